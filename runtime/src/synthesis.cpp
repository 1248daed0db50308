// Synthesised levels: U(coarser level) + table-driven Gaussian noise, recursively from the base's
// finest level; plus the extrapolation of the stored levels' residual variance that sets the noise.
#include "runtime/synthesis.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "container/pyramid_file.h"

namespace terrain::runtime {

using namespace terrain::container;  // the stage below
namespace {

uint64_t splitmix64(uint64_t& state) {
  uint64_t z = (state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

int32_t saturate_round(double v) {
  constexpr double lo = std::numeric_limits<int32_t>::min(), hi = std::numeric_limits<int32_t>::max();
  return int32_t(std::llround(std::clamp(v, lo, hi)));
}

// Magnification of level k's table index along one axis, 16.16 fixed point: 1.03 .. 1.125, drawn
// from the seed. Above 1, so that consecutive samples never read the same entry (the noise stays
// uncorrelated), and different per level and axis, so that the levels' periods do not line up.
constexpr int kMulShift = 16;
constexpr int64_t kMulOne = int64_t(1) << kMulShift;

}  // namespace

// ---------------------------------------------------------------------------------------------
// Noise variance model

std::vector<double> extrapolate_residual_std(const std::vector<double>& stored_variance_m2, int count,
                                             ResidualFit* fit) {
  ResidualFit f;
  const int stored = int(stored_variance_m2.size());
  for (int l = stored - 1; l >= 1 && int(f.levels_used.size()) < ResidualFit::kMaxFitLevels; --l) {
    const double v = stored_variance_m2[size_t(l)];
    if (v > 0 && std::isfinite(v)) f.levels_used.push_back(l);
  }
  std::reverse(f.levels_used.begin(), f.levels_used.end());
  std::vector<double> out(size_t(std::max(count, 0)), 0.0);
  const size_t m = f.levels_used.size();
  if (m == 0) {
    f.note = "no stored level with a positive residual variance (beyond level 0): zero detail";
    if (fit) *fit = f;
    return out;
  }
  double mx = 0, my = 0;
  for (int l : f.levels_used) mx += l, my += std::log2(stored_variance_m2[size_t(l)]);
  mx /= double(m), my /= double(m);
  if (m >= 2) {
    double sxx = 0, sxy = 0;
    for (int l : f.levels_used) {
      const double dx = l - mx;
      sxx += dx * dx;
      sxy += dx * (std::log2(stored_variance_m2[size_t(l)]) - my);
    }
    f.slope_fitted = sxy / sxx;
    f.slope = std::clamp(f.slope_fitted, ResidualFit::kMinSlope, ResidualFit::kMaxSlope);
    f.clamped = f.slope != f.slope_fitted;
    f.note = "log2 variance fit on levels " + std::to_string(f.levels_used.front()) + ".." +
             std::to_string(f.levels_used.back()) + (f.clamped ? " (slope clamped)" : "");
  } else {
    f.slope = f.slope_fitted = ResidualFit::kDefaultSlope;
    f.note = "fallback: one usable level (" + std::to_string(f.levels_used.front()) + "), default slope";
  }
  // The line passes through the centroid of the fitted points (also with a clamped slope).
  f.intercept = my - f.slope * mx;
  for (int k = 0; k < count; ++k)
    out[size_t(k)] = std::sqrt(std::exp2(f.intercept + f.slope * double(stored + k)));
  if (fit) *fit = f;
  return out;
}

std::vector<double> stored_residual_variance_m2(const PyramidFile& file) {
  const ContainerInfo& info = file.info();
  const double s2 = info.vertical_scale * info.vertical_scale;
  std::vector<double> v;
  for (const LevelInfo& l : info.levels) v.push_back(l.stats.variance * s2);
  return v;
}

SynthesisOptions synthesis_options_for(const PyramidFile& file, int levels, uint64_t seed,
                                       double detail_scale, ResidualFit* fit) {
  if (!(detail_scale >= 0) || !std::isfinite(detail_scale))
    throw std::invalid_argument("synthesis: detail scale must be a finite number >= 0");
  SynthesisOptions o;
  o.levels = levels;
  o.seed = seed;
  o.std_m = extrapolate_residual_std(stored_residual_variance_m2(file), levels, fit);
  for (double& s : o.std_m) s *= detail_scale;
  return o;
}

std::vector<double> fractal_std(double std0_m, double hurst, int count) {
  std::vector<double> s(size_t(std::max(count, 0)));
  for (int k = 0; k < count; ++k) s[size_t(k)] = std0_m * std::exp2(-hurst * k);
  return s;
}

std::vector<double> gaussian_noise_table(uint64_t seed, int table_log2) {
  if (table_log2 < 5 || table_log2 > 10)
    throw std::invalid_argument("synthesis: table side must be 2^5..2^10");
  const size_t count = size_t(1) << (2 * table_log2);
  std::vector<double> t(count);
  uint64_t state = seed ^ 0x5DEECE66Dull;
  constexpr double kTwoPi = 6.283185307179586476925286766559;
  for (size_t i = 0; i < count; i += 2) {
    // Uniforms in (0, 1]: the log never sees 0.
    const double u1 = double((splitmix64(state) >> 11) + 1) * 0x1.0p-53;
    const double u2 = double(splitmix64(state) >> 11) * 0x1.0p-53;
    const double r = std::sqrt(-2.0 * std::log(u1));
    t[i] = r * std::cos(kTwoPi * u2);
    t[i + 1] = r * std::sin(kTwoPi * u2);
  }
  // Exactly zero mean and unit variance over the table, so that any window covering whole table
  // periods has the target variance, not the sample variance of one draw.
  double mean = 0;
  for (double v : t) mean += v;
  mean /= double(count);
  double var = 0;
  for (double v : t) var += (v - mean) * (v - mean);
  const double inv_sd = 1.0 / std::sqrt(var / double(count));
  for (double& v : t) v = (v - mean) * inv_sd;
  return t;
}

// ---------------------------------------------------------------------------------------------
// SynthesisSource

SynthesisSource::SynthesisSource(HeightSource& base, const SynthesisOptions& options)
    : base_(base), options_(options), base_levels_(base.level_count()) {
  const int K = options_.levels;
  if (base_levels_ < 1) throw std::invalid_argument("synthesis: the base source has no levels");
  if (K < 1 || K > SynthesisOptions::kMaxLevels)
    throw std::invalid_argument("synthesis: level count must be 1.." +
                                std::to_string(SynthesisOptions::kMaxLevels) + ", got " + std::to_string(K));
  if (int(options_.std_m.size()) != K)
    throw std::invalid_argument("synthesis: need one noise std per synthesised level (" + std::to_string(K) +
                                "), got " + std::to_string(options_.std_m.size()));
  for (double s : options_.std_m)
    if (!(s >= 0) || !std::isfinite(s))
      throw std::invalid_argument("synthesis: noise std must be finite and >= 0");
  if (!(options_.quantum_m > 0) || !std::isfinite(options_.quantum_m))
    throw std::invalid_argument("synthesis: quantum must be a positive number of metres");
  if (!(base.spacing_m() > 0)) throw std::invalid_argument("synthesis: the base's spacing must be positive");
  spacing_m_ = std::ldexp(base.spacing_m(), -K);

  GridSize s = base.level_size(base_levels_ - 1);
  for (int k = 0; k < K; ++k) {
    s = GridSize{std::max<int64_t>(2 * s.width - 1, 1), std::max<int64_t>(2 * s.height - 1, 1)};
    if (s.width > (int64_t(1) << 40) || s.height > (int64_t(1) << 40))
      throw std::invalid_argument("synthesis: synthesised level too large (more than 2^40 samples a side)");
    sizes_.push_back(s);
  }

  const std::vector<double> table = gaussian_noise_table(options_.seed, options_.table_log2);
  table_mask_ = (1 << options_.table_log2) - 1;
  uint64_t state = options_.seed * 0xD1B54A32D192ED03ull + 0x2545F4914F6CDD1Dull;
  for (int k = 0; k < K; ++k) {
    const double std_units = options_.std_m[size_t(k)] / options_.quantum_m;
    std::vector<int32_t> scaled(table.size());
    for (size_t i = 0; i < table.size(); ++i) scaled[i] = saturate_round(table[i] * std_units);
    noise_.push_back(std::move(scaled));
    // Magnification in [1 + 2^-5, 1 + 2^-3) and an offset in [0, table side).
    mul_x_.push_back(kMulOne + 2048 + int64_t(splitmix64(state) % 6144));
    mul_y_.push_back(kMulOne + 2048 + int64_t(splitmix64(state) % 6144));
    off_x_.push_back(int64_t(splitmix64(state) & uint64_t(table_mask_)));
    off_y_.push_back(int64_t(splitmix64(state) & uint64_t(table_mask_)));
  }
  // One buffer per recursion depth, allocated once: a deeper call never reallocates a shallower one.
  scratch_.resize(size_t(K) + 1);
}

GridSize SynthesisSource::level_size(int level) const {
  if (level < 0 || level >= level_count())
    throw std::out_of_range("synthesis: no level " + std::to_string(level));
  return level < base_levels_ ? base_.level_size(level) : sizes_[size_t(level - base_levels_)];
}

double SynthesisSource::noise_std_m(int level) const {
  return level < base_levels_ ? 0.0 : options_.std_m.at(size_t(level - base_levels_));
}

int32_t SynthesisSource::noise_units(int level, int64_t x, int64_t y) const {
  assert(level >= base_levels_ && level < level_count());
  const size_t k = size_t(level - base_levels_);
  // Floor of x * magnification (arithmetic shift), wrapped onto the table (two's complement & mask).
  const int64_t ix = (((x * mul_x_[k]) >> kMulShift) + off_x_[k]) & table_mask_;
  const int64_t iy = (((y * mul_y_[k]) >> kMulShift) + off_y_[k]) & table_mask_;
  return noise_[k][size_t((iy << options_.table_log2) | ix)];
}

void SynthesisSource::compute(int level, const Rect& rect, int32_t* out, int64_t out_stride, size_t depth) {
  if (level == base_levels_ - 1) {
    base_scratch_.resize(size_t(rect.width * rect.height));
    base_.fill(level, rect, base_scratch_.data(), rect.width);
    const double inv_q = 1.0 / options_.quantum_m;
    for (int64_t y = 0; y < rect.height; ++y)
      for (int64_t x = 0; x < rect.width; ++x) {
        const float v = base_scratch_[size_t(y * rect.width + x)];
        out[y * out_stride + x] = std::isfinite(v) ? saturate_round(double(v) * inv_q) : 0;
      }
    return;
  }
  const GridSize fine = level_size(level);
  const Rect need = upsample_required_window(rect, fine);
  std::vector<int32_t>& coarse = scratch_[depth];
  coarse.resize(size_t(need.width * need.height));
  compute(level - 1, need, coarse.data(), need.width, depth + 1);
  const CoarseWindow window{coarse.data(), need.width, need, level_size(level - 1)};
  upsample_region(window, fine, rect, out, out_stride, upsample_scratch_);
  const size_t k = size_t(level - base_levels_);
  if (options_.std_m[k] == 0) return;
  for (int64_t y = 0; y < rect.height; ++y) {
    int32_t* row = out + y * out_stride;
    for (int64_t x = 0; x < rect.width; ++x)
      row[x] = saturate_round(double(row[x]) + double(noise_units(level, rect.x0 + x, rect.y0 + y)));
  }
}

void SynthesisSource::fill_quanta(int level, const Rect& rect, int32_t* out, int64_t out_stride) {
  if (level < base_levels_ - 1 || level >= level_count())
    throw std::out_of_range("synthesis: fill_quanta needs a level in " + std::to_string(base_levels_ - 1) +
                            ".." + std::to_string(level_count() - 1) + ", got " + std::to_string(level));
  const GridSize size = level_size(level);
  if (rect.x0 < 0 || rect.y0 < 0 || rect.width < 0 || rect.height < 0 || rect.x0 + rect.width > size.width ||
      rect.y0 + rect.height > size.height)
    throw std::out_of_range("synthesis: rectangle outside level " + std::to_string(level));
  if (rect.width == 0 || rect.height == 0) return;
  // Recursion depth 0 is the caller's buffer; scratch_[depth] holds level - 1 - depth.
  compute(level, rect, out, out_stride, 0);
}

void SynthesisSource::fill(int level, const Rect& rect, float* out, int64_t out_stride) {
  if (level < base_levels_) return base_.fill(level, rect, out, out_stride);
  if (rect.width <= 0 || rect.height <= 0) return;
  const GridSize size = level_size(level);
  // Synthesise the part of the level nearest to rect (at least one sample), then repeat its edges.
  const int64_t cx0 = std::clamp<int64_t>(rect.x0, 0, size.width - 1);
  const int64_t cx1 = std::clamp<int64_t>(rect.x0 + rect.width - 1, 0, size.width - 1);
  const int64_t cy0 = std::clamp<int64_t>(rect.y0, 0, size.height - 1);
  const int64_t cy1 = std::clamp<int64_t>(rect.y0 + rect.height - 1, 0, size.height - 1);
  const Rect inside{cx0, cy0, cx1 - cx0 + 1, cy1 - cy0 + 1};
  std::vector<int32_t>& units = scratch_.back();  // never a recursion buffer of `level` (depth <= K - 1)
  units.resize(size_t(inside.width * inside.height));
  fill_quanta(level, inside, units.data(), inside.width);
  const double q = options_.quantum_m;
  for (int64_t y = 0; y < rect.height; ++y) {
    const int64_t sy = std::clamp(rect.y0 + y, cy0, cy1) - cy0;
    for (int64_t x = 0; x < rect.width; ++x) {
      const int64_t sx = std::clamp(rect.x0 + x, cx0, cx1) - cx0;
      out[y * out_stride + x] = float(double(units[size_t(sy * inside.width + sx)]) * q);
    }
  }
}

void synthesize_level(SynthesisSource& source, int level, std::vector<float>& out) {
  const GridSize s = source.level_size(level);
  out.resize(size_t(s.width * s.height));
  source.fill(level, Rect{0, 0, s.width, s.height}, out.data(), s.width);
}

}  // namespace terrain::runtime
