// RLGR1: mode follows k = kp >> 3 (k > 0: runs of zeros, k == 0: Golomb-Rice of each value); kp and
// the Rice parameter krp adapt after every codeword with the constants of MS-RDPRFX (see
// shared/research/codecs.md section 3). The unary part of every Rice code is capped at kUnaryCap ones;
// reaching the cap announces a fixed-width escape, so no input can produce an unbounded code.
#include "codec/internal/rlgr.h"

#include <algorithm>
#include <cmath>

namespace codec::detail {
namespace {

using namespace rlgr;

inline void put_rice(BitWriter& out, uint32_t u, RlgrState& s) {
  const int kr = s.krp >> 3;
  const uint32_t quotient = u >> kr;
  if (quotient < uint32_t(kUnaryCap)) {
    // quotient ones, a zero, kr remainder bits: at most 19 + 1 + 10 = 30 bits, one put.
    out.put((((1u << quotient) - 1) << (kr + 1)) | (u & ((1u << kr) - 1)), int(quotient) + 1 + kr);
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

namespace {

// The encoder loop, with the value of each position supplied by `level(i, k)`, called once per
// position in coding order; k is the run-length parameter there (0: Golomb-Rice mode).
template <class Level> void encode_levels(BitWriter& out, size_t count, RlgrState& s, Level&& level) {
  size_t i = 0;
  while (i < count) {
    const int k = s.kp >> 3;
    if (k == 0) {
      const int32_t v = level(i++, 0);
      const uint32_t mapped = v >= 0 ? uint32_t(v) * 2 : uint32_t(-int64_t(v)) * 2 - 1;
      put_rice(out, mapped, s);
      s.kp = clamp_kp(mapped == 0 ? s.kp + kUpZero : s.kp - kDownZero);
      continue;
    }
    const size_t window = std::min(size_t(1) << k, count - i);
    size_t run = 0;
    int32_t v = 0;
    while (run < window && (v = level(i + run, k)) == 0) ++run;
    if (run == window) {  // a full run, or the zeros that end the sequence
      out.put_bit(0);
      i += window;
      s.kp = clamp_kp(s.kp + kUpRun);
      continue;
    }
    out.put((1u << (k + 1)) | uint32_t(run) << 1 | uint32_t(v < 0), k + 2);  // flag, run, sign
    i += run + 1;
    put_rice(out, uint32_t(v < 0 ? -int64_t(v) : v) - 1, s);
    s.kp = clamp_kp(s.kp - kDownRun);
  }
}

constexpr int kMaxRunK = kKpMax >> 3;

}  // namespace

void rlgr_encode(BitWriter& out, const int32_t* values, size_t count, RlgrState& s) {
  encode_levels(out, count, s, [values](size_t i, int) { return values[i]; });
}

void rlgr_encode_quantizing(BitWriter& out, int32_t* values, size_t count, size_t group_size,
                            const double* group_inverse_step, const DeadZone& dead_zone, RlgrState& s) {
  double offset[kMaxRunK + 1];
  offset[0] = dead_zone.rice_offset;
  for (int k = 1; k <= kMaxRunK; ++k)
    offset[k] =
        std::max(dead_zone.min_run_offset, dead_zone.run_offset - dead_zone.run_offset_per_k * (k - 1));
  // Magnitudes below zero_below[k] quantise to 0 in the current group: most values take this
  // integer test only. encode_levels visits the positions in increasing order, so the group advances
  // without a division.
  int64_t zero_below[kMaxRunK + 1];
  const auto enter_group = [&](const double* inverse) {
    for (int k = 0; k <= kMaxRunK; ++k) zero_below[k] = int64_t(std::ceil((1.0 - offset[k]) / *inverse));
  };
  size_t group_end = group_size;
  const double* inverse_step = group_inverse_step;
  enter_group(inverse_step);
  encode_levels(out, count, s, [&](size_t i, int k) {
    while (i >= group_end) {
      group_end += group_size;
      enter_group(++inverse_step);
    }
    const int32_t c = values[i];
    const int64_t magnitude = c < 0 ? -int64_t(c) : int64_t(c);
    if (magnitude < zero_below[std::min(k, kMaxRunK)]) {
      values[i] = 0;
      return 0;
    }
    const double scaled = double(magnitude) * *inverse_step;
    const int32_t q = int32_t(scaled + offset[std::min(k, kMaxRunK)]);
    values[i] = c < 0 ? -q : q;
    return values[i];
  });
}

bool rlgr_decode(BitReader& in, int32_t* values, size_t count, RlgrState& state) {
  std::fill(values, values + count, 0);
  return rlgr_decode_dense(in, count, state, [values](size_t i, uint32_t magnitude, bool negative) {
    values[i] = negative ? -int32_t(magnitude) : int32_t(magnitude);
    return true;
  });
}

}  // namespace codec::detail
