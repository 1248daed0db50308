// RLGR1: mode follows k = kp >> 3 (k > 0: runs of zeros, k == 0: Golomb-Rice of each value); kp and
// the Rice parameter krp adapt after every codeword with the constants of MS-RDPRFX (see
// shared/research/codecs.md section 3). The unary part of every Rice code is capped at kUnaryCap ones;
// reaching the cap announces a fixed-width escape, so no input can produce an unbounded code.
#include "rlgr.h"

#include <algorithm>

namespace codec::detail {
namespace {

using namespace rlgr;

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

}  // namespace

void gamma_encode(BitWriter& out, int32_t v) {
  const uint32_t u = (v >= 0 ? uint32_t(v) * 2 : uint32_t(-int64_t(v)) * 2 - 1) + 1;
  const int length = 32 - __builtin_clz(u);
  out.put(0, length - 1);
  out.put(u, length);
}

bool gamma_decode(BitReader& in, int32_t* v) {
  in.refill();
  const int zeros = in.leading_zeros();
  if (zeros > 30) return false;
  in.skip(zeros);
  in.refill();
  const uint32_t u = in.take(zeros + 1) - 1;
  if (u >= uint32_t(2) * kRlgrMaxMagnitude) return false;
  const int32_t half = int32_t((u + 1) >> 1);
  *v = (u & 1) ? -half : half;
  return true;
}

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

bool rlgr_decode(BitReader& in, int32_t* values, size_t count, RlgrState& state) {
  std::fill(values, values + count, 0);
  return rlgr_decode_nonzero(in, count, state, [values](size_t i, uint32_t magnitude, bool negative) {
    values[i] = negative ? -int32_t(magnitude) : int32_t(magnitude);
    return true;
  });
}

}  // namespace codec::detail
