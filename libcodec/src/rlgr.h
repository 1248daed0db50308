// Adaptive run-length / Golomb-Rice coding (RLGR1 after Malvar, DCC 2006) with a bounded escape.
//
// One RlgrState per band and tile, reset at each tile start, so tiles decode independently and no
// side tables are stored. Values must satisfy |v| < kRlgrMaxMagnitude; every codeword is at most
// kRlgrMaxCodeBits long whatever the input.
#pragma once

#include <cstddef>
#include <cstdint>

#include "bitio.h"

namespace codec::detail {

inline constexpr int32_t kRlgrMaxMagnitude = 1 << 30;
inline constexpr int kRlgrMaxCodeBits = 64;

struct RlgrState {
  int kp = 8;   // run-length parameter, 3 fractional bits (k = kp >> 3)
  int krp = 8;  // Golomb-Rice parameter, 3 fractional bits
};

void rlgr_encode(BitWriter& out, const int32_t* values, size_t count, RlgrState& state);
// Decodes exactly `count` values. Returns false when the bits describe an impossible sequence (a run
// longer than the values left, an escape out of range); the caller also checks out.overrun().
bool rlgr_decode(BitReader& in, int32_t* values, size_t count, RlgrState& state);

}  // namespace codec::detail
