// CRC32C (Castagnoli, reflected polynomial 0x82F63B78), the checksum of stream headers and tiles.
#pragma once

#include <cstddef>
#include <cstdint>

#include "codec/codec.h"

namespace codec::detail {

// CRC32C of data[0 .. size); chain calls by passing the previous result as `crc`.
inline uint32_t crc32c(const uint8_t* data, size_t size, uint32_t crc = 0) {
  return codec::crc32c(data, size, crc);
}

}  // namespace codec::detail
