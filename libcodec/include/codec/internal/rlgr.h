// Adaptive run-length / Golomb-Rice coding (RLGR1 after Malvar, DCC 2006) with a bounded escape.
//
// One RlgrState per band and tile, reset at each tile start, so tiles decode independently and no
// side tables are stored. Values must satisfy |v| < kRlgrMaxMagnitude; every codeword is at most
// kRlgrMaxCodeBits long whatever the input.
#pragma once

#include <algorithm>
#include <cassert>
#include <cstddef>
#include <cstdint>

#include "codec/internal/bitio.h"

namespace codec::detail {

inline constexpr int32_t kRlgrMaxMagnitude = 1 << 30;
inline constexpr int kRlgrMaxCodeBits = 64;

struct RlgrState {
  int kp = 8;   // run-length parameter, 3 fractional bits (k = kp >> 3)
  int krp = 8;  // Golomb-Rice parameter, 3 fractional bits
};

// Elias-gamma code of one value (|v| < kRlgrMaxMagnitude), at most 63 bits: for a first value that
// has no context, such as a tile's first DC, where RLGR's fresh state would need an escape.
void gamma_encode(BitWriter& out, int32_t v);
// False for a code longer than any gamma_encode output or a value out of range.
bool gamma_decode(BitReader& in, int32_t* v);

void rlgr_encode(BitWriter& out, const int32_t* values, size_t count, RlgrState& state);
// Rounding offsets of a dead-zone quantiser that depend on the coder's state at each position: in
// run-length mode (k > 0) a non-zero value costs a run code, a sign and a Rice code and ends the run,
// so small values are worth zeroing; the longer the runs (larger k), the more so.
struct DeadZone {
  double rice_offset;       // Golomb-Rice mode
  double run_offset;        // run mode, k = 1
  double run_offset_per_k;  // decrease per unit of k above 1
  double min_run_offset;
};
// Quantises and codes in one pass (encoder only; the decoder is rlgr_decode): values[i], a
// coefficient of group i / group_size, becomes sign(c) * floor(|c| * group_inverse_step[group] +
// offset) with the DeadZone offset for the coder's state there, and values then hold the levels coded.
// Offsets below 1 keep step-1 groups exact.
void rlgr_encode_quantizing(BitWriter& out, int32_t* values, size_t count, size_t group_size,
                            const double* group_inverse_step, const DeadZone& dead_zone, RlgrState& state);
// Decodes exactly `count` values. Returns false when the bits describe an impossible sequence (a run
// longer than the values left, an escape out of range); the caller also checks out.overrun().
bool rlgr_decode(BitReader& in, int32_t* values, size_t count, RlgrState& state);

// Adaptation constants shared by the coder and the decoder (see rlgr.cpp).
namespace rlgr {
inline constexpr int kKpMax = 80;
inline constexpr int kUpRun = 4;     // after a complete run of 2^k zeros
inline constexpr int kDownRun = 6;   // after a run ended by a non-zero value
inline constexpr int kUpZero = 3;    // Golomb-Rice mode: after a zero
inline constexpr int kDownZero = 3;  // Golomb-Rice mode: after a non-zero
inline constexpr int kUnaryCap = 20;
inline constexpr int kEscapeBits = 31;

// Branch-free (GCC compiles std::clamp to branches here, and near 0 they mispredict): kp is at most
// kKpMax + kUpRun and at least -kDownRun before the clamp.
inline int clamp_kp(int kp) {
  kp &= ~(kp >> 31);
  const int over = kp - kKpMax;
  return kKpMax + (over & (over >> 31));
}
// After a Rice code with quotient q (at most kUnaryCap, the escape): q = 0: krp -= 2; q = 1:
// unchanged; q > 1: krp += q; clamped to [0, kKpMax]. Looked up in a table of the next krp for every
// (krp, q), 1.7 KB: one L1 load in place of about ten compare and select instructions on each
// codeword's path (decode +5-7%, Rainier step 6).
struct RiceTable {
  uint8_t next[kKpMax + 1][kUnaryCap + 1];
};
constexpr RiceTable make_rice_table() {
  RiceTable t{};
  for (int krp = 0; krp <= kKpMax; ++krp)
    for (int q = 0; q <= kUnaryCap; ++q) {
      const int v = krp + q - 2 * int(q == 0) - int(q == 1);
      t.next[krp][q] = uint8_t(v < 0 ? 0 : v > kKpMax ? kKpMax : v);
    }
  return t;
}
inline constexpr RiceTable kRiceNext = make_rice_table();
inline void adapt_rice(RlgrState& s, int quotient) {
  assert(s.krp >= 0 && s.krp <= kKpMax && quotient >= 0 && quotient <= kUnaryCap);
  s.krp = kRiceNext.next[s.krp][quotient];
}
}  // namespace rlgr

// One codeword, branching on its shape: advances i past the values it codes, calling sink for a
// non-zero one. Returns false for an impossible sequence or a value the sink rejects. in must hold
// at least 56 bits (a codeword without escape needs at most 1 + 10 + 1 + 20 + 10 = 42). The slow
// path of rlgr_decode_codeword_dense (escapes and corrupt streams).
template <class Sink>
[[gnu::always_inline]] inline bool rlgr_decode_codeword(BitReader& in, size_t count, RlgrState& s, size_t& i,
                                                        Sink& sink) {
  using namespace rlgr;
  // A Rice code with parameter kr. Without escape the value is below 2^(5 + 10) (quotient < 20, kr <=
  // 10), so only an escape's 31-bit value needs the range check: in_range = false when it is not
  // below `limit`.
  const auto rice = [&](int kr, uint32_t limit, bool& in_range) -> uint32_t {
    const int ones = in.leading_ones();
    if (ones < kUnaryCap) [[likely]] {
      // The remainder from the cache shifted to the terminating zero, whose bit on top keeps kr = 0
      // defined; then one skip of the whole codeword.
      const uint32_t remainder = uint32_t((in.cache() << ones) >> (63 - kr));
      in.skip(ones + 1 + kr);
      adapt_rice(s, ones);
      return (uint32_t(ones) << kr) | remainder;
    }
    in.skip(kUnaryCap);
    in.refill();
    adapt_rice(s, kUnaryCap);
    const uint32_t escaped = in.take(kEscapeBits);
    in_range = escaped < limit;
    return escaped;
  };
  bool in_range = true;
  const int k = s.kp >> 3;
  if (k == 0) {
    // |v| < kRlgrMaxMagnitude maps to at most 2 kRlgrMaxMagnitude - 2.
    const uint32_t mapped = rice(s.krp >> 3, uint32_t(2) * kRlgrMaxMagnitude - 1, in_range);
    if (!in_range) [[unlikely]]
      return false;
    if (mapped != 0 && !sink(i, (mapped + 1) >> 1, (mapped & 1) != 0)) [[unlikely]]
      return false;
    ++i;
    s.kp = clamp_kp(s.kp + kUpZero - (kUpZero + kDownZero) * int(mapped != 0));
    return true;
  }
  if (in.take(1) == 0) {
    i += std::min(size_t(1) << k, count - i);
    s.kp = clamp_kp(s.kp + kUpRun);
    return true;
  }
  // Run length (k bits) and sign in one read.
  const uint32_t run_sign = in.take(k + 1);
  const size_t run = run_sign >> 1;
  if (run >= count - i) [[unlikely]]
    return false;
  i += run;
  const uint32_t negative = run_sign & 1;
  const uint32_t magnitude_minus_1 = rice(s.krp >> 3, uint32_t(kRlgrMaxMagnitude) - 1, in_range);
  if (!in_range) [[unlikely]]
    return false;
  if (!sink(i, magnitude_minus_1 + 1, negative != 0)) [[unlikely]]
    return false;
  ++i;
  s.kp = clamp_kp(s.kp - kDownRun);
  return true;
}

// rlgr_decode_codeword for a sink that accepts zeros (see rlgr_decode_dense): the run-mode codeword's
// two shapes (a complete run, or a run ended by a value) are parsed together and selected by masks,
// without a branch. Which shape comes next is data (about as likely either way near 2 bits/sample),
// so that branch of rlgr_decode_codeword mispredicts often; here only the mode (k = 0 or not),
// escapes and corrupt streams branch. Parsing the Golomb-Rice mode's codeword alongside as well
// removed the mode's branch but lengthened the dependency chain: 15-25 % slower (Rainier, rms 1 m).
template <class Sink>
[[gnu::always_inline]] inline bool rlgr_decode_codeword_dense(BitReader& in, size_t count, RlgrState& s,
                                                              size_t& i, Sink& sink) {
  using namespace rlgr;
  const int k = s.kp >> 3;
  const int kr = s.krp >> 3;
  const uint64_t c = in.cache();
  if (k == 0) {
    const int ones = __builtin_clzll(~c | 1);
    if (ones >= kUnaryCap) [[unlikely]]
      return rlgr_decode_codeword(in, count, s, i, sink);
    const uint32_t mapped = (uint32_t(ones) << kr) | uint32_t((c << ones) >> (63 - kr));
    in.skip(ones + 1 + kr);
    s.krp = kRiceNext.next[s.krp][ones];
    if (!sink(i, (mapped + 1) >> 1, (mapped & 1) != 0)) [[unlikely]]
      return false;
    ++i;
    s.kp = clamp_kp(s.kp + kUpZero - (kUpZero + kDownZero) * int(mapped != 0));
    return true;
  }
  // The ended run's fields, parsed whether or not the codeword has them: after the flag, k run bits
  // and the sign, then the Rice code of magnitude - 1.
  const uint32_t run_sign = uint32_t((c << 1) >> (63 - k));
  const uint64_t rest = c << (k + 2);
  const int ones = __builtin_clzll(~rest | 1);
  const size_t run = run_sign >> 1;
  const size_t left = count - i;
  const bool full = (c >> 63) == 0;  // a complete run
  if (int(!full) & (int(ones >= kUnaryCap) | int(run >= left))) [[unlikely]]
    return rlgr_decode_codeword(in, count, s, i, sink);  // an escape, or the error it reports
  const int q = std::min(ones, kUnaryCap);
  const uint32_t magnitude = ((uint32_t(q) << kr) | uint32_t((rest << q) >> (63 - kr))) + 1;
  // Masks, not conditionals: GCC turns the equivalent conditionals into branches.
  const size_t ended = size_t(0) - size_t(!full);  // all ones for a run ended by a value
  const size_t at = i + (run & ended);
  if (!sink(at, magnitude & uint32_t(ended), (run_sign & 1 & uint32_t(ended)) != 0)) [[unlikely]]
    return false;
  const size_t full_run = std::min(size_t(1) << k, left);
  in.skip(int(1 + (size_t(k + 2 + q + kr) & ended)));
  i = ((at + 1) & ended) | ((i + full_run) & ~ended);
  s.kp = clamp_kp(s.kp + kUpRun - int((kUpRun + kDownRun) & ended));
  s.krp += int((kRiceNext.next[s.krp][q] - s.krp) & int(ended));
  return true;
}

// Decodes exactly count values (rlgr_decode without the output array), calling sink(index, magnitude,
// negative) in index order for each non-zero value (0 < magnitude < kRlgrMaxMagnitude) and also
// for some zero values (magnitude 0, negative false; the sink may store the zero or skip it), so
// that the decoder need not branch on whether a codeword ends with a value. A sink that returns
// false rejects the stream. Returns false for an impossible sequence (a run longer than the values
// left, an escape out of range) or a rejected value; the caller also checks the reader's overrun.
template <class Sink> bool rlgr_decode_dense(BitReader& reader, size_t count, RlgrState& state, Sink&& sink) {
  BitReader in = reader;
  RlgrState s = state;
  size_t i = 0;
  bool ok = true;
  while (i < count) {
    if (!in.refill_fast()) in.refill();
    if (!rlgr_decode_codeword_dense(in, count, s, i, sink)) [[unlikely]] {
      ok = false;
      break;
    }
  }
  reader = in;
  state = s;
  return ok;
}

}  // namespace codec::detail
