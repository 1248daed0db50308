// Static token distributions of the phase tiles (format 7): a fixed two-parameter family, so that a
// stream names one member per context in a few bits instead of storing histograms, and a decoder
// builds no table of its own. docs/codec.md "Phase tiles (formats 7 and 8)".
//
// A quantised level q is coded as one symbol: 0, or the token t of |q| (kTokens tokens: magnitudes
// below 16 directly, larger ones by their bit length and the bit below the leading one, the n - 1
// bits that follow raw) with q's sign, symbol 2t - 1 for q > 0 and 2t for q < 0 (one rANS step for
// what would otherwise be two: the sign is a fair coin). Member (z, g) of the family gives level 0
// the probability kZeroFreq[z] / 4096 and |q| >= 1 a geometric law of mean 1 + mu_g,
// mu_g = 2^(g/2 - 5), spread over the tokens by their magnitude ranges and split evenly between the
// signs. A symbol too unlikely for a slot of its own is coded as the escape symbol (one slot in every
// member) and its number in 8 raw bits, so any level is codable with any member. The frequencies
// are computed with integer arithmetic only: encoder and decoder on any machine get the same tables.
#pragma once

#include <cstddef>
#include <cstdint>

namespace codec::detail {

inline constexpr int kTokens = 70;                    // |q| < 2^31
inline constexpr int kTokenEscape = 2 * kTokens - 1;  // a symbol follows in kTokenEscapeBits raw bits
inline constexpr int kTokenEscapeBits = 8;
inline constexpr int kSymbols = kTokenEscape + 1;
inline constexpr int kSmallSymbols = 31;  // symbols 0 .. 30: |q| < 16, no raw bits

// Symbol of level q whose magnitude has token t.
inline int symbol_of(int t, int64_t q) { return t == 0 ? 0 : 2 * t - (q > 0 ? 1 : 0); }
inline constexpr int kTokenProbBits = 12;                      // frequencies in 1/4096
inline constexpr int kZeroLevels = 16;                         // z: probability of a zero level
inline constexpr int kMeanLevels = 42;                         // g: mean of the non-zero magnitudes
inline constexpr int kFamilySize = kZeroLevels * kMeanLevels;  // members 0 .. 671: z * kMeanLevels + g

// Token of magnitude m and the number of raw bits below it (their value: m's low `*raw_bits` bits).
inline int token_of(uint32_t m, int* raw_bits) {
  if (m < 16) {
    *raw_bits = 0;
    return int(m);
  }
  const int n = 31 - __builtin_clz(m);
  *raw_bits = n - 1;
  return 16 + (n - 4) * 2 + int((m >> (n - 1)) & 1);
}
// Smallest magnitude of token t (t >= 16) and its raw bit count.
inline uint32_t token_base(int t, int* raw_bits) {
  const int n = (t - 16) / 2 + 4;
  *raw_bits = n - 1;
  return (uint32_t(2 | ((t - 16) & 1))) << (n - 1);
}

// One member: symbol frequencies (sum 4096; 0 = escaped symbol), cumulative frequencies, the
// encoder's cost of each token in bits (sign and escape included: the fit counts tokens), the
// decoder's freq | cum << 16 of each symbol, and
// (built on first use by token_table) the symbol of each of the 4096 slots.
struct TokenTable {
  uint16_t freq[kSymbols];
  uint16_t cum[kSymbols + 1];
  float cost[kTokens];
  uint32_t freq_cum[kSymbols];
  const uint8_t* slots = nullptr;
};

// Member i (0 .. kFamilySize - 1) with its slot entries built. Thread-safe; the tables live for the
// process (4 KiB per member used, 2.7 MiB if a process met all of them).
const TokenTable& token_table(int member);
// The same without building the slot table (the encoder's cost estimates need none).
const TokenTable& token_costs(int member);

// The member that codes a histogram of tokens (counts[kTokens]) in the fewest bits.
int best_member(const uint32_t* counts);

}  // namespace codec::detail
