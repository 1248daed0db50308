// Static token distributions of the phase tiles (format 7): a fixed two-parameter family, so that a
// stream names one member per context in a few bits instead of storing histograms, and a decoder
// builds no table of its own. docs/codec.md "Phase tiles (format 7)".
//
// A quantised level q is coded as the token of |q| (kTokens symbols: magnitudes below 16 directly,
// larger ones by their bit length and the bit below the leading one, the n - 1 bits that follow raw)
// and, when q != 0, a raw sign bit. Member (z, g) of the family gives the token 0 the probability
// kZeroFreq[z] / 4096 and |q| >= 1 a geometric law of mean 1 + mu_g, mu_g = 2^(g/2 - 5), spread
// over the tokens by their magnitude ranges. A token too unlikely for a slot of its own is coded as
// the escape symbol (one slot in every member) and its number in 7 raw bits, so any level is codable
// with any member. The frequencies are computed with integer arithmetic only: encoder and decoder on
// any machine get the same tables.
#pragma once

#include <cstddef>
#include <cstdint>

namespace codec::detail {

inline constexpr int kTokens = 70;            // |q| < 2^31
inline constexpr int kTokenEscape = kTokens;       // symbol kTokens: a token follows in kTokenEscapeBits raw bits
inline constexpr int kTokenEscapeBits = 7;
inline constexpr int kSymbols = kTokens + 1;
inline constexpr int kTokenProbBits = 12;     // frequencies in 1/4096
inline constexpr int kZeroLevels = 16;        // z: probability of a zero level
inline constexpr int kMeanLevels = 42;        // g: mean of the non-zero magnitudes
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

// One member: symbol frequencies (sum 4096; 0 = escaped token), cumulative frequencies, the encoder's
// cost of each token in bits (escape included), and (built on first use by token_table) the symbol of
// each of the 4096 slots.
struct TokenTable {
  uint16_t freq[kSymbols];
  uint16_t cum[kSymbols + 1];
  float cost[kTokens];
  const uint8_t* slots = nullptr;
};

// Member i (0 .. kFamilySize - 1) with its slot table built. Thread-safe; the tables live for the
// process (about 4.4 KiB per member used).
const TokenTable& token_table(int member);
// The same without building the slot table (the encoder's cost estimates need none).
const TokenTable& token_costs(int member);

// The member that codes a histogram of tokens (counts[kTokens]) in the fewest bits.
int best_member(const uint32_t* counts);

}  // namespace codec::detail
