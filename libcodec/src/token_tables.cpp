// The phase tiles' static token distributions (token_tables.h): integer-only construction, lazily
// built slot tables, and the encoder's choice of member for a histogram.
#include "codec/internal/token_tables.h"

#include <cmath>
#include <memory>
#include <mutex>

namespace codec::detail {
namespace {

using u128 = unsigned __int128;
constexpr uint32_t kOne = 1u << kTokenProbBits;

// P(level 0) in 1/4096: logits -5.25 .. 6.0 in steps of 0.75, so that neighbouring members differ by
// a small fraction of a bit on the zero token whatever its probability.
constexpr uint16_t kZeroFreq[kZeroLevels] = {21,   45,   94,   194,  391,  747,  1314, 2048,
                                             2782, 3349, 3705, 3902, 4002, 4051, 4075, 4086};

// theta^k in Q32 (theta < 2^32 in Q32), by squaring: exact integer arithmetic.
uint64_t power_q32(uint64_t theta, uint64_t k) {
  uint64_t result = uint64_t(1) << 32, base = theta;
  while (k > 0 && result > 0) {
    if (k & 1) result = uint64_t((u128(result) * base) >> 32);
    base = uint64_t((u128(base) * base) >> 32);
    k >>= 1;
  }
  return result;
}

// Ratio theta (Q32) of the geometric law of |q| - 1 with mean mu = 2^(g/2 - 5).
uint64_t theta_q32(int g) {
  // mu in Q32: 2^(32 + g/2 - 5), times sqrt(2) (6074001000 / 2^32) for odd g.
  const int shift = 32 + g / 2 - 5;
  u128 mu = u128(1) << shift;
  if (g & 1) mu = (mu * 6074001000u) >> 32;
  return uint64_t((mu << 32) / ((u128(1) << 32) + mu));
}

void fill(TokenTable& t, int member) {
  const int z = member / kMeanLevels, g = member % kMeanLevels;
  const uint64_t theta = theta_q32(g);
  // Q32 mass of each non-zero token: P(lo <= m < hi) = theta^(lo - 1) - theta^(hi - 1).
  uint64_t mass[kTokens] = {};
  for (int k = 1; k < kTokens; ++k) {
    uint64_t lo = uint64_t(k), hi = uint64_t(k) + 1;
    if (k >= 16) {
      int raw = 0;
      lo = token_base(k, &raw);
      hi = lo + (uint64_t(1) << raw);
    }
    mass[k] = power_q32(theta, lo - 1) - power_q32(theta, hi - 1);
  }
  // Level 0 gets its frequency, the escape one slot, every other token its share of the rest
  // (rounded down: possibly none), split between its signs (the odd slot to the positive one); the
  // rounding remainder goes to the heaviest token's positive symbol.
  t.freq[0] = kZeroFreq[z];
  t.freq[kTokenEscape] = 1;
  const uint64_t rest = kOne - kZeroFreq[z] - 1;
  uint64_t used = 0;
  int heaviest = 1;
  for (int k = 1; k < kTokens; ++k) {
    const uint64_t share = uint64_t((u128(mass[k]) * rest) >> 32);
    t.freq[2 * k - 1] = uint16_t((share + 1) / 2);
    t.freq[2 * k] = uint16_t(share / 2);
    used += share;
    if (mass[k] > mass[heaviest]) heaviest = k;
  }
  t.freq[2 * heaviest - 1] = uint16_t(t.freq[2 * heaviest - 1] + (rest - used));
  t.cum[0] = 0;
  for (int k = 0; k < kSymbols; ++k) {
    t.cum[k + 1] = uint16_t(t.cum[k] + t.freq[k]);
    t.freq_cum[k] = t.freq[k] | uint32_t(t.cum[k]) << 16;
  }
  // A token's cost: its two symbols' mean (a fair sign), an escape where a symbol has no slot.
  const double escape_bits = kTokenProbBits + kTokenEscapeBits;
  const auto bits = [&](int s) {
    return t.freq[s] ? kTokenProbBits - std::log2(double(t.freq[s])) : escape_bits;
  };
  t.cost[0] = float(bits(0));
  for (int k = 1; k < kTokens; ++k) t.cost[k] = float(0.5 * (bits(2 * k - 1) + bits(2 * k)));
}

struct Family {
  TokenTable tables[kFamilySize];
  std::once_flag built[kFamilySize];
  std::unique_ptr<uint8_t[]> slots[kFamilySize];
  Family() {
    for (int i = 0; i < kFamilySize; ++i) fill(tables[i], i);
  }
};

Family& family() {
  static Family f;
  return f;
}

}  // namespace

const TokenTable& token_costs(int member) { return family().tables[member]; }

const TokenTable& token_table(int member) {
  Family& f = family();
  std::call_once(f.built[member], [&] {
    TokenTable& t = f.tables[member];
    f.slots[member] = std::make_unique<uint8_t[]>(kOne);
    for (int k = 0; k < kSymbols; ++k)
      for (uint32_t s = t.cum[k]; s < t.cum[k + 1]; ++s) f.slots[member][s] = uint8_t(k);
    t.slots = f.slots[member].get();
  });
  return f.tables[member];
}

int best_member(const uint32_t* counts) {
  int used[kTokens], n = 0;
  for (int k = 0; k < kTokens; ++k)
    if (counts[k]) used[n++] = k;
  int best = 0;
  double best_bits = INFINITY;
  for (int i = 0; i < kFamilySize; ++i) {
    const TokenTable& t = token_costs(i);
    double bits = 0;
    for (int j = 0; j < n; ++j) bits += double(counts[used[j]]) * t.cost[used[j]];
    if (bits < best_bits) best_bits = bits, best = i;
  }
  return best;
}

}  // namespace codec::detail
