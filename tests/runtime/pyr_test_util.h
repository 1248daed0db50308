// Byte-level editing of .pyr files for tests that forge fields: little-endian access and resealing
// the superblock's checksums (the layout is restated from docs/format.md on purpose).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "codec/crc32c.h"

namespace pyrtest {

inline uint64_t get_le(const std::vector<uint8_t>& b, size_t at, int bytes) {
  uint64_t v = 0;
  for (int i = bytes - 1; i >= 0; --i) v = v << 8 | b[at + size_t(i)];
  return v;
}
inline void put_le(std::vector<uint8_t>& b, size_t at, uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) b[at + size_t(i)] = uint8_t(v >> (8 * i));
}
inline void put_f64(std::vector<uint8_t>& b, size_t at, double v) {
  uint64_t u;
  std::memcpy(&u, &v, 8);
  put_le(b, at, u, 8);
}

// Superblock field offsets from docs/format.md.
constexpr size_t kSbMajor = 8, kSbMinor = 10, kSbFileSize = 16, kSbIndexOffset = 24, kSbIndexSize = 32,
                 kSbIndexCrc = 40, kSbCrc = 60;

// Makes the index and superblock checksums match the (edited) bytes again, where the superblock
// still locates the index inside the file.
inline void reseal(std::vector<uint8_t>& b) {
  const uint64_t offset = get_le(b, kSbIndexOffset, 8), size = get_le(b, kSbIndexSize, 8);
  if (offset <= b.size() && size <= b.size() - offset)
    put_le(b, kSbIndexCrc, codec::crc32c(b.data() + offset, size_t(size)), 4);
  put_le(b, kSbCrc, codec::crc32c(b.data(), kSbCrc), 4);
}

}  // namespace pyrtest
