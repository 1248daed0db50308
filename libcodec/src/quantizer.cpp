// Band norms are measured rather than derived by hand: the norm of a band is the root energy of the
// tile the integer inverse transform produces from one large coefficient, divided by its amplitude.
// The impulse sits in an interior macroblock of a 64x64 tile so that the overlap filters act on all
// sides. The norms are those of the lossy transform (the only one quantised with steps above 1). Integer
// lifting is linear up to rounding, which a 2^14 amplitude makes negligible.
#include "codec/internal/quantizer.h"

#include <array>
#include <cmath>
#include <vector>

#include "codec/internal/lapped_transform.h"
#include "codec/internal/lifting_transform.h"

namespace codec::detail {
namespace {

constexpr int kProbeSide = 64;
constexpr int32_t kImpulse = 1 << 14;

double impulse_norm(int x, int y) {
  std::vector<int32_t> tile(size_t(kProbeSide) * kProbeSide, 0);
  tile[size_t(y) * kProbeSide + x] = kImpulse;
  inverse_lapped(tile.data(), kProbeSide, kProbeSide, true);
  double energy = 0;
  for (int32_t v : tile) energy += double(v) * double(v);
  return std::sqrt(energy) / kImpulse;
}

std::array<double, kBandCount> measure_norms() {
  std::array<double, kBandCount> norms{};
  const int mb = 16;  // macroblock (1,1)
  norms[0] = impulse_norm(mb, mb);
  for (int p = 1; p < 16; ++p) {
    const int u = p % 4, v = p / 4;
    norms[size_t(lp_band(p))] = impulse_norm(mb + 4 * u, mb + 4 * v);
    norms[size_t(hp_band(p))] = impulse_norm(mb + 4 + u, mb + 4 + v);  // block (1,1) of that macroblock
  }
  return norms;
}

}  // namespace

const double* band_synthesis_norms() {
  static const std::array<double, kBandCount> norms = measure_norms();
  return norms.data();
}

BandSteps band_steps_for(uint32_t step_q8, int fraction_bits) {
  const double* norms = band_synthesis_norms();
  BandSteps steps{};
  for (int b = 0; b < kBandCount; ++b) {
    const double s = std::round(std::ldexp(double(step_q8), fraction_bits) / norms[b]);
    steps.q8[b] = s < kStepOne ? kStepOne : s > kMaxBandStep ? kMaxBandStep : uint32_t(s);
  }
  return steps;
}

BandSteps lifting_band_steps_for(uint32_t step_q8, int fraction_bits) {
  const double* norms = lifting_synthesis_norms();
  BandSteps steps = unit_band_steps();
  for (int b = 0; b < kLiftingBandCount; ++b) {
    const double s = std::round(std::ldexp(double(step_q8), fraction_bits) / norms[b]);
    steps.q8[b] = s < kStepOne ? kStepOne : s > kMaxBandStep ? kMaxBandStep : uint32_t(s);
  }
  return steps;
}

BandSteps unit_band_steps() {
  BandSteps steps{};
  for (auto& s : steps.q8) s = kStepOne;
  return steps;
}

}  // namespace codec::detail
