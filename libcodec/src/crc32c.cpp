// CRC-32C (Castagnoli): table-driven "slicing by 8" in portable C++, plus the SSE4.2 crc32
// instruction when the CPU has it. Both give identical results; the table path is the reference.
// The one implementation for the project: libcodec checks tiles with it, the container its regions.
#include "codec/crc32c.h"

#include <array>
#include <cstring>

#include "codec/codec.h"
#include "core/bytes.h"

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <nmmintrin.h>
#define TERRAIN_CRC32C_HW 1
#endif

namespace codec {
namespace {

constexpr uint32_t kPolynomial = 0x82F63B78u;  // 0x1EDC6F41 bit-reversed (LSB-first processing)

using Tables = std::array<std::array<uint32_t, 256>, 8>;

// tables[0] advances the CRC over one byte; tables[k] advances a byte that is followed by k more
// bytes, so eight lookups fold eight bytes at once.
constexpr Tables make_tables() {
  Tables t{};
  for (uint32_t i = 0; i < 256; ++i) {
    uint32_t c = i;
    for (int bit = 0; bit < 8; ++bit) c = (c & 1) ? (c >> 1) ^ kPolynomial : c >> 1;
    t[0][i] = c;
  }
  for (size_t k = 1; k < 8; ++k)
    for (uint32_t i = 0; i < 256; ++i) t[k][i] = (t[k - 1][i] >> 8) ^ t[0][t[k - 1][i] & 0xFF];
  return t;
}
constexpr Tables kTables = make_tables();

using terrain::bytes::get_u32;

// `state` is the inverted CRC register.
uint32_t update_portable(uint32_t state, const uint8_t* p, size_t n) {
  while (n >= 8) {
    const uint32_t lo = state ^ get_u32(p);
    const uint32_t hi = get_u32(p + 4);
    state = kTables[7][lo & 0xFF] ^ kTables[6][(lo >> 8) & 0xFF] ^ kTables[5][(lo >> 16) & 0xFF] ^
            kTables[4][lo >> 24] ^ kTables[3][hi & 0xFF] ^ kTables[2][(hi >> 8) & 0xFF] ^
            kTables[1][(hi >> 16) & 0xFF] ^ kTables[0][hi >> 24];
    p += 8;
    n -= 8;
  }
  while (n--) state = (state >> 8) ^ kTables[0][(state ^ *p++) & 0xFF];
  return state;
}

#ifdef TERRAIN_CRC32C_HW
__attribute__((target("sse4.2"))) uint32_t update_sse42(uint32_t state, const uint8_t* p, size_t n) {
  while (n > 0 && (reinterpret_cast<uintptr_t>(p) & 7) != 0) {
    state = _mm_crc32_u8(state, *p++);
    --n;
  }
  uint64_t wide = state;
  while (n >= 8) {
    uint64_t word;
    std::memcpy(&word, p, 8);  // x86 is little endian, which is the order the CRC consumes bytes
    wide = _mm_crc32_u64(wide, word);
    p += 8;
    n -= 8;
  }
  state = uint32_t(wide);
  while (n--) state = _mm_crc32_u8(state, *p++);
  return state;
}

bool cpu_has_sse42() {
  static const bool has = __builtin_cpu_supports("sse4.2");
  return has;
}
#endif

// Polynomials over GF(2) modulo the CRC polynomial, in the CRC's reflected order (bit 31 holds x^0):
// the product a b mod P, shifting b up one power of x for each bit of a.
uint32_t multiply_mod(uint32_t a, uint32_t b) {
  uint32_t product = 0;
  for (uint32_t bit = 1u << 31; bit != 0 && a != 0; bit >>= 1) {
    if (a & bit) {
      product ^= b;
      a ^= bit;
    }
    b = (b & 1) ? (b >> 1) ^ kPolynomial : b >> 1;
  }
  return product;
}

}  // namespace

// Appending B to A multiplies A's register by x^(8 |B|) and adds B's; the pre- and post-inversion
// cancel because both CRCs start from the same inverted register.
uint32_t crc32c_combine(uint32_t crc_a, uint32_t crc_b, uint64_t size_b) {
  uint32_t shift = 1u << 31;        // x^0
  uint32_t power = 1u << (31 - 8);  // x^8: one byte
  for (; size_b != 0; size_b >>= 1) {
    if (size_b & 1) shift = multiply_mod(shift, power);
    power = multiply_mod(power, power);
  }
  return multiply_mod(shift, crc_a) ^ crc_b;
}

uint32_t crc32c_portable(const void* data, size_t size, uint32_t crc) {
  return ~update_portable(~crc, static_cast<const uint8_t*>(data), size);
}

uint32_t crc32c(const void* data, size_t size, uint32_t crc) {
#ifdef TERRAIN_CRC32C_HW
  if (cpu_has_sse42()) return ~update_sse42(~crc, static_cast<const uint8_t*>(data), size);
#endif
  return crc32c_portable(data, size, crc);
}

}  // namespace codec
