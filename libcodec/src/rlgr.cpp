// RLGR1: mode follows k = kp >> 3 (k > 0: runs of zeros, k == 0: Golomb-Rice of each value); kp and
// the Rice parameter krp adapt after every codeword with the constants of MS-RDPRFX (see
// shared/research/codecs.md section 3). The unary part of every Rice code is capped at kUnaryCap ones;
// reaching the cap announces a fixed-width escape, so no input can produce an unbounded code.
#include "rlgr.h"

#include <algorithm>

namespace codec::detail {
namespace {

constexpr int kKpMax = 80;
constexpr int kUpRun = 4;     // after a complete run of 2^k zeros
constexpr int kDownRun = 6;   // after a run ended by a non-zero value
constexpr int kUpZero = 3;    // Golomb-Rice mode: after a zero
constexpr int kDownZero = 3;  // Golomb-Rice mode: after a non-zero
constexpr int kUnaryCap = 20;
constexpr int kEscapeBits = 31;

inline int clamp_kp(int kp) { return std::clamp(kp, 0, kKpMax); }

inline void adapt_rice(RlgrState& s, int quotient) {
  if (quotient == 0) s.krp = clamp_kp(s.krp - 2);
  else if (quotient > 1) s.krp = clamp_kp(s.krp + quotient);
}

inline void put_rice(BitWriter& out, uint32_t u, RlgrState& s) {
  const int kr = s.krp >> 3;
  const uint32_t quotient = u >> kr;
  if (quotient < uint32_t(kUnaryCap)) {
    out.put_ones(int(quotient));
    out.put_bit(0);
    if (kr) out.put(u & ((1u << kr) - 1), kr);
    adapt_rice(s, int(quotient));
  } else {
    out.put_ones(kUnaryCap);
    out.put(u, kEscapeBits);
    adapt_rice(s, kUnaryCap);
  }
}

inline uint32_t get_rice(BitReader& in, RlgrState& s) {
  const int kr = s.krp >> 3;
  const int quotient = in.get_ones_capped(kUnaryCap);
  uint32_t u;
  if (quotient < kUnaryCap) u = (uint32_t(quotient) << kr) | in.get(kr);
  else u = in.get(kEscapeBits);
  adapt_rice(s, quotient);
  return u;
}

}  // namespace

void rlgr_encode(BitWriter& out, const int32_t* values, size_t count, RlgrState& s) {
  size_t i = 0;
  while (i < count) {
    const int k = s.kp >> 3;
    if (k == 0) {
      const int32_t v = values[i++];
      const uint32_t mapped = v >= 0 ? uint32_t(v) * 2 : uint32_t(-int64_t(v)) * 2 - 1;
      put_rice(out, mapped, s);
      s.kp = clamp_kp(mapped == 0 ? s.kp + kUpZero : s.kp - kDownZero);
      continue;
    }
    const size_t window = std::min(size_t(1) << k, count - i);
    size_t run = 0;
    while (run < window && values[i + run] == 0) ++run;
    if (run == window) {  // a full run, or the zeros that end the sequence
      out.put_bit(0);
      i += window;
      s.kp = clamp_kp(s.kp + kUpRun);
      continue;
    }
    out.put_bit(1);
    out.put(uint32_t(run), k);
    i += run;
    const int32_t v = values[i++];
    out.put_bit(v < 0);
    put_rice(out, uint32_t(v < 0 ? -int64_t(v) : v) - 1, s);
    s.kp = clamp_kp(s.kp - kDownRun);
  }
}

bool rlgr_decode(BitReader& in, int32_t* values, size_t count, RlgrState& s) {
  size_t i = 0;
  while (i < count) {
    const int k = s.kp >> 3;
    if (k == 0) {
      const uint32_t mapped = get_rice(in, s);
      if (mapped >= uint32_t(2) * kRlgrMaxMagnitude) return false;
      values[i++] = (mapped & 1) ? -int32_t((mapped + 1) >> 1) : int32_t(mapped >> 1);
      s.kp = clamp_kp(mapped == 0 ? s.kp + kUpZero : s.kp - kDownZero);
      continue;
    }
    if (in.get_bit() == 0) {
      const size_t zeros = std::min(size_t(1) << k, count - i);
      std::fill(values + i, values + i + zeros, 0);
      i += zeros;
      s.kp = clamp_kp(s.kp + kUpRun);
      continue;
    }
    const size_t run = in.get(k);
    if (run >= count - i) return false;
    std::fill(values + i, values + i + run, 0);
    i += run;
    const uint32_t negative = in.get_bit();
    const uint32_t magnitude_minus_1 = get_rice(in, s);
    if (magnitude_minus_1 >= uint32_t(kRlgrMaxMagnitude)) return false;
    const int32_t magnitude = int32_t(magnitude_minus_1) + 1;
    values[i++] = negative ? -magnitude : magnitude;
    s.kp = clamp_kp(s.kp - kDownRun);
  }
  return true;
}

}  // namespace codec::detail
