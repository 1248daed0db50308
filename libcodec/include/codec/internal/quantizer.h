// Dead-zone uniform quantiser with per-band steps that equalise the sample-domain error of one unit
// step across bands (the lapped transform is not orthonormal; see codec.h for what "step" means).
//
// Bands: 0 = macroblock DC, 1..15 = LP (stage-2 AC, position v*4+u), 16..30 = HP (stage-1 AC, 15+p).
// Steps are fixed point with 8 fractional bits; 256 means step 1 (exact for integer coefficients).
#pragma once

#include <algorithm>
#include <cstdint>

namespace codec::detail {

inline constexpr int kBandCount = 31;
inline constexpr uint32_t kStepOne = 256;
inline constexpr uint32_t kMaxBandStep = 1u << 30;
inline constexpr int64_t kMaxCoefficient = int64_t(1) << 29;  // decoder rejects larger coefficients
// Lossy tiles carry extra bits of sample precision through the transform, so the rounding inside the
// integer lifting steps adds little error at small steps (lossless tiles: 0). Images whose samples all
// lie within +-kFineRange get kFineFractionBits (rms 0.47 instead of 0.60 at step 1.25 on SRTM data,
// and about 2% fewer bits at equal rms), others kWideFractionBits; either way the scaled samples stay
// within +-2^22, the range the transform is designed for.
inline constexpr int kFineFractionBits = 4;
inline constexpr int kWideFractionBits = 2;
inline constexpr int32_t kFineRange = 1 << 18;

constexpr int lp_band(int position) { return position; }
constexpr int hp_band(int position) { return 15 + position; }

struct BandSteps {
  uint32_t q8[kBandCount];
};

// Synthesis norm of each band's basis function (measured once on the integer inverse transform).
const double* band_synthesis_norms();
// Per-band steps for global step step_q8 (step * 256) in the transform's units (samples scaled by
// 2^fraction_bits): max(1, step * 2^fraction_bits / norm) in 1/256 units.
BandSteps band_steps_for(uint32_t step_q8, int fraction_bits);
// All bands at step 1 (lossless).
BandSteps unit_band_steps();
// The residual transform's four band steps (lifting_transform.h) in q8[0..3], the same rule with the
// lifting bands' norms; the other entries are unused.
BandSteps lifting_band_steps_for(uint32_t step_q8, int fraction_bits);
// A stream's steps: unit steps when lossless (fraction_bits 0), else the lapped or the lifting rule.
inline BandSteps stream_band_steps(uint32_t step_q8, int fraction_bits, bool lifting) {
  if (fraction_bits == 0) return unit_band_steps();
  return lifting ? lifting_band_steps_for(step_q8, fraction_bits) : band_steps_for(step_q8, fraction_bits);
}

// Encoder side: q = sign(c) * floor(|c| / step + 3/8).
inline int32_t quantize(int32_t c, double inverse_step) {
  const double magnitude = double(c < 0 ? -int64_t(c) : int64_t(c)) * inverse_step + 0.375;
  const int32_t q = int32_t(magnitude);
  return c < 0 ? -q : q;
}
// Decoder side: |c| = (|q| + 1/16) * step, rounded: ((16 |q| + 1) * step_q8 + 2048) >> 12. The
// reconstruction sits 1/16 step above q * step (measured on SRTM tiles: about 0.5% fewer bits at equal
// rms than q * step). Exact at step 1 (256): the result is |q|. Products stay far from 2^63: a |q|
// large enough to matter is clamped to a value every caller rejects (> kMaxCoefficient).
inline int64_t dequantize(int64_t q, uint32_t step_q8) {
  const int64_t m = q < 0 ? -q : q;
  const int64_t product =
      std::min(std::min<int64_t>(m, int64_t(1) << 30) * int64_t(step_q8), int64_t(1) << 40);
  const int64_t magnitude = ((product * 16 + step_q8 + 2048) >> 12) & -int64_t(m != 0);  // branch-free
  return q < 0 ? -magnitude : magnitude;
}

}  // namespace codec::detail
