// CRC-32C, the one checksum of the project: libcodec's streams and the .pyr container both use it.
#pragma once

#include <cstddef>
#include <cstdint>

namespace codec {

// CRC-32C (Castagnoli) of data[0 .. size), the checksum used by the stream and by the pyramid
// container; chain calls by passing the previous result as `crc`. Uses the SSE4.2 instruction when
// the CPU has it; crc32c_portable is the table-driven path alone (identical results). Pure functions:
// any thread, any bytes; data may be null when size is 0.
uint32_t crc32c(const void* data, size_t size, uint32_t crc = 0);
uint32_t crc32c_portable(const void* data, size_t size, uint32_t crc = 0);

}  // namespace codec
