// LEB128 varints and zigzag mapping for the uniform quantiser's bytes.
#pragma once

#include <cstddef>
#include <cstdint>

namespace terrain::detail {

inline uint32_t zigzag(int32_t v) { return (uint32_t(v) << 1) ^ uint32_t(v >> 31); }
inline int32_t unzigzag(uint32_t u) { return int32_t(u >> 1) ^ -int32_t(u & 1); }

// Writes v at p (at most 10 bytes) and returns the end.
inline uint8_t* put_varint(uint8_t* p, uint64_t v) {
  while (v >= 0x80) {
    *p++ = uint8_t(v | 0x80);
    v >>= 7;
  }
  *p++ = uint8_t(v);
  return p;
}

// Reads a varint from [*p, end); false when truncated or longer than 10 bytes.
inline bool get_varint(const uint8_t** p, const uint8_t* end, uint64_t* v) {
  uint64_t out = 0;
  for (int shift = 0; shift < 70; shift += 7) {
    if (*p == end) return false;
    const uint8_t b = *(*p)++;
    out |= uint64_t(b & 0x7f) << shift;
    if (!(b & 0x80)) {
      *v = out;
      return true;
    }
  }
  return false;
}

}  // namespace terrain::detail
