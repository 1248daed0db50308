// Terrain synthesis beyond the stored resolution (Losasso & Hoppe 2004 §8, Asirvatham & Hoppe 2005
// §2.4.2): levels finer than a height source's finest are made on the fly as U(coarser level) plus
// uncorrelated Gaussian "residuals" read from a small precomputed table indexed by the sample's
// integer coordinates, with the noise variance of each synthesised level extrapolated from the
// residual variances measured on the stored levels. The same mechanism amplifies any coarse base
// (a pure generator: base + seed -> terrain). docs/synthesis.md explains the choices.
//
// Determinism: every synthesised sample is a pure function of (seed, options, base heights, level,
// x, y). fill() reconstructs the coarser window it needs recursively down to the base's finest
// level and upsamples it with libpyramid's integer U (upsample_region), exactly as the region
// decoder does for stored levels, so heights never depend on the order or the boundaries of fills.
//
// Threads: the free functions are pure (any thread); a SynthesisSource is not thread-safe, like
// every HeightSource.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "pyramid/pyramid.h"
#include "runtime/height_source.h"

namespace terrain::container {
class PyramidFile;
}

namespace terrain::runtime {

// ---------------------------------------------------------------------------------------------
// Noise variance model

// How the per-level residual variance was extrapolated: log2(variance) = intercept + slope * level
// fitted by least squares on `levels_used` (stored levels, coarsest = 0).
struct ResidualFit {
  std::vector<int> levels_used;
  double intercept = 0;     // log2(m^2)
  double slope = 0;         // per level (finer = +1), after clamping
  double slope_fitted = 0;  // before clamping (equal to slope when no fit was possible)
  bool clamped = false;     // slope was outside [kMinSlope, kMaxSlope]
  std::string note;         // one line for logs ("fit on levels 3..6", "fallback: ...")
  // Variance ratio per finer level is 2^slope. For fractional Brownian terrain with Hurst exponent
  // H it is 2^(-2H); the clamp keeps H in [0.25, 1.5] so that one odd level cannot make the
  // extrapolated detail explode (slope > -0.5) or vanish at once (slope < -3).
  static constexpr double kMinSlope = -3.0, kMaxSlope = -0.5;
  static constexpr double kDefaultSlope = -1.6;  // H = 0.8: used when fewer than 2 levels can be fitted
  static constexpr int kMaxFitLevels = 4;        // the finest levels are the best predictors of finer ones
};

// The residual standard deviations (metres) of `count` levels finer than the stored ones, from the
// stored levels' residual variances (m^2; index = level, 0 coarsest). Level 0 is skipped (its
// "residual" is the terrain itself), as are levels with zero variance; the fit uses up to the
// kMaxFitLevels finest remaining levels. No usable level: all zero (flat terrain gets no detail).
std::vector<double> extrapolate_residual_std(const std::vector<double>& stored_variance_m2, int count,
                                             ResidualFit* fit = nullptr);

// The per-level residual variances (m^2) a pyramid file stores (container ResidualStats, in level
// units, times metres_per_unit^2), index = level. Reads the file's index only (no decoding).
std::vector<double> stored_residual_variance_m2(const container::PyramidFile& file);

// ---------------------------------------------------------------------------------------------
// The synthesising height source

struct SynthesisOptions {
  int levels = 0;                 // K: levels added beyond the base's finest, 1..kMaxLevels
  std::vector<double> std_m;      // noise standard deviation of each added level (K values, metres, >= 0)
  uint64_t seed = 1;              // the noise table and its per-level index transforms
  double quantum_m = 1.0 / 1024;  // heights are integers of this step while upsampling (U is exact
                                  // integer arithmetic); also the rounding of the noise
  int table_log2 = 8;             // noise table side 2^table_log2 (5..10)
  static constexpr int kMaxLevels = 16;
};

// A HeightSource with the base's P levels (passed through unchanged) and K synthesised levels
// P .. P+K-1 finer than the base's finest. Synthesised level sizes double (2w - 1, so coarse sample
// i sits on fine sample 2i and coarse_extent gives the base's size back); spacing_m() is the
// base's divided by 2^K. Outside a level, fill() repeats its edge samples like every source
// (synthesised levels are bounded by their level_size even over an unbounded base).
// Throws std::invalid_argument for unusable options (K, std_m size or values, quantum, table size).
// The base must outlive this object. Not thread-safe (one scratch), like every HeightSource.
class SynthesisSource final : public HeightSource {
 public:
  SynthesisSource(HeightSource& base, const SynthesisOptions& options);
  int level_count() const override { return base_levels_ + int(options_.levels); }
  GridSize level_size(int level) const override;
  double spacing_m() const override { return spacing_m_; }
  void fill(int level, const Rect& rect, float* out, int64_t out_stride) override;

  // Synthesised levels in integer quanta (metres = units * quantum_m()); `rect` must lie inside
  // level `level` >= base_levels() - 1 (the base's finest comes out rounded to the quantum).
  // Throws std::out_of_range otherwise, and what the base's fill throws.
  void fill_quanta(int level, const Rect& rect, int32_t* out, int64_t out_stride);
  // The noise added at sample (x, y) of synthesised level `level` (base_levels() ..
  // level_count() - 1, asserted; any x, y), in quanta.
  int32_t noise_units(int level, int64_t x, int64_t y) const;
  // Target noise standard deviation of `level` (metres; 0 for the base's levels; std::out_of_range
  // beyond level_count() - 1).
  double noise_std_m(int level) const;
  int base_levels() const { return base_levels_; }
  double quantum_m() const { return options_.quantum_m; }
  const SynthesisOptions& options() const { return options_; }

 private:
  void compute(int level, const Rect& rect, int32_t* out, int64_t out_stride, size_t depth);

  HeightSource& base_;
  SynthesisOptions options_;
  int base_levels_;
  double spacing_m_;
  std::vector<GridSize> sizes_;  // synthesised levels, k = level - P
  int table_mask_;
  // Per synthesised level: the table scaled to quanta, and per axis the magnification (16.16 fixed
  // point, a few per cent above 1: breaks the table's periodicity between levels) and offset.
  std::vector<std::vector<int32_t>> noise_;
  std::vector<int64_t> mul_x_, mul_y_, off_x_, off_y_;
  std::vector<std::vector<int32_t>> scratch_;  // per recursion depth
  std::vector<float> base_scratch_;
  UpsampleScratch upsample_scratch_;
};

// The unit-variance Gaussian table (side 2^table_log2, row-major) the source draws from: Box-Muller
// on a splitmix64 stream of `seed`, then shifted and scaled to mean 0 and variance 1 exactly.
// Throws std::invalid_argument for table_log2 outside 5..10.
std::vector<double> gaussian_noise_table(uint64_t seed, int table_log2);

// SynthesisOptions for K levels below a pyramid file: std_m extrapolated from the file's stored
// residual variances, times detail_scale (0: zero detail, U alone). Throws std::invalid_argument
// for a detail_scale that is negative or not finite; `levels` is checked by the SynthesisSource
// constructor, not here.
SynthesisOptions synthesis_options_for(const container::PyramidFile& file, int levels, uint64_t seed,
                                       double detail_scale = 1.0, ResidualFit* fit = nullptr);

// Noise standard deviations for a pure generator: std0_m at the first added level, then a factor
// 2^-hurst per finer level (fractional Brownian detail with Hurst exponent `hurst`).
std::vector<double> fractal_std(double std0_m, double hurst, int count);

// Pure generator: a terrain from a coarse base and a seed. Fills the whole of level `level` of
// `source` (metres, row-major) into out, resized to its size (std::out_of_range for a level outside
// the source). Memory: the whole level.
void synthesize_level(SynthesisSource& source, int level, std::vector<float>& out);

}  // namespace terrain::runtime
