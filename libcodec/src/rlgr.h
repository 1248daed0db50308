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

// Elias-gamma code of one value (|v| < kRlgrMaxMagnitude), at most 63 bits: for a first value that
// has no context, such as a tile's first DC, where RLGR's fresh state would need an escape.
void gamma_encode(BitWriter& out, int32_t v);
// False for a code longer than any gamma_encode output or a value out of range.
bool gamma_decode(BitReader& in, int32_t* v);

void rlgr_encode(BitWriter& out, const int32_t* values, size_t count, RlgrState& state);
// Decodes exactly `count` values. Returns false when the bits describe an impossible sequence (a run
// longer than the values left, an escape out of range); the caller also checks out.overrun().
bool rlgr_decode(BitReader& in, int32_t* values, size_t count, RlgrState& state);

}  // namespace codec::detail
