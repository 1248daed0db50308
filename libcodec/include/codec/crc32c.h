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
// The CRC-32C of A followed by B from crc_a = crc32c(A), crc_b = crc32c(B) and B's size, without
// B's bytes (O(log size_b)): pieces checked by different writers, e.g. the bands that MPI ranks
// write into one container level, give the level's CRC. Pure; any thread.
uint32_t crc32c_combine(uint32_t crc_a, uint32_t crc_b, uint64_t size_b);

}  // namespace codec
