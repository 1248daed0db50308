// Byte coding shared by every on-disk format of the project (libcodec streams, .pyr containers, band
// tables, mask runs): fixed-width little-endian integers and LEB128 varints. All functions are pure
// and thread-safe; the readers never read outside the range they are given.
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace terrain::bytes {

inline void put_u16(uint8_t* p, uint16_t v) {
  p[0] = uint8_t(v);
  p[1] = uint8_t(v >> 8);
}
inline void put_u32(uint8_t* p, uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = uint8_t(v >> (8 * i));
}
inline void put_u64(uint8_t* p, uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = uint8_t(v >> (8 * i));
}
inline void put_f64(uint8_t* p, double v) { put_u64(p, std::bit_cast<uint64_t>(v)); }

inline uint16_t get_u16(const uint8_t* p) { return uint16_t(p[0] | p[1] << 8); }
inline uint32_t get_u32(const uint8_t* p) {
  return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}
inline uint64_t get_u64(const uint8_t* p) { return uint64_t(get_u32(p)) | uint64_t(get_u32(p + 4)) << 32; }
inline double get_f64(const uint8_t* p) { return std::bit_cast<double>(get_u64(p)); }

// LEB128: 7 bits per byte, low groups first, the high bit set on every byte but the last.
inline constexpr size_t kMaxVarintBytes = 10;  // a uint64_t

// Writes v at p (at most kMaxVarintBytes) and returns the end of what it wrote.
inline uint8_t* put_varint(uint8_t* p, uint64_t v) {
  while (v >= 0x80) {
    *p++ = uint8_t(v | 0x80);
    v >>= 7;
  }
  *p++ = uint8_t(v);
  return p;
}
inline void put_varint(std::vector<uint8_t>& out, uint64_t v) {
  uint8_t buf[kMaxVarintBytes];
  out.insert(out.end(), buf, put_varint(buf, v));
}

// Reads one varint from [p, end) into *v and advances p past it. False, with p somewhere inside the
// range, when the varint runs past end or its value exceeds max (at most 64 bits): untrusted bytes
// are safe.
inline bool get_varint(const uint8_t*& p, const uint8_t* end, uint64_t* v, uint64_t max = UINT64_MAX) {
  uint64_t value = 0;
  for (int shift = 0; shift < 70; shift += 7) {
    if (p == end) return false;
    const uint8_t b = *p++;
    const uint64_t bits = b & 0x7F;
    if (shift == 63 && bits > 1) return false;  // beyond 64 bits
    value |= bits << shift;
    if (!(b & 0x80)) {
      if (value > max) return false;
      *v = value;
      return true;
    }
  }
  return false;
}

}  // namespace terrain::bytes
