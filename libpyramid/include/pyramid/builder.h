// The closed-loop residual pyramid of Losasso & Hoppe 2004 (section 5), built streamed out of core:
// T_{l-1} = round(D(T_l)), R_l = T_l - U(T^_{l-1}), T^_l = U(T^_{l-1}) + decoded R_l.
//
// Levels are numbered coarse to fine: level 0 is the coarsest, level m (= level_count-1) the input.
// Every level is an int32 grid in the input's native units (times BuildOptions::value_scale), so
// that a quantiser step of 1 makes the whole pipeline exactly lossless.
//
// Extent rule (any size, rectangular, tiny): coarse extent = ceil(fine/2) per axis, and coarse
// sample i sits on fine sample 2i (grid-registered: 1201->601->301->151, 1025->513->257,
// 7->4->2->1, 1->1). See docs/pyramid.md for the boundary rules of U and D.
#pragma once

#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "pyramid/downsample.h"
#include "pyramid/filter_fit.h"
#include "pyramid/levels.h"
#include "pyramid/residual_coder.h"
#include "readers/heightmap.h"

namespace terrain {

// Builder

struct BuildOptions {
  int level_count = 0;              // 0: automatic (see pyramid_level_sizes)
  int64_t min_coarsest_side = 128;  // automatic level count stops before the longer side drops below
  double value_scale = 1.0;         // level value = round(native * value_scale); integer inputs must
                                    // give integers (else the build fails); float inputs are rounded
  double value_offset = 0.0;        // an integer subtracted after scaling: level value =
                                    // round(native * value_scale) - value_offset; keeps inputs far
                                    // from zero (1e6 m, int32 millimetres) inside the coder's range
  bool use_fixed_filter = false;    // true: use `fixed_filter` instead of fitting D
  DownsampleFilter fixed_filter = DownsampleFilter::default_filter();
  FilterFitOptions fit;
  int threads = 2;              // results are bit-identical for every thread count; the calling thread
                                // keeps up to threads - 1 idle workers for later builds (D's batches)
  int64_t fill_band_rows = 64;  // nodata push-pull works on bands of this many input rows
  int64_t fit_rows = 512;       // D is fitted on windows within the top fit_rows input rows
  // Bytes the builder may hold (its estimate, plan_build_memory): bands of every level are coded at
  // most bands_in_flight at a time, fewer than `threads` when the budget is tight (the bytes are the
  // same: only the schedule changes). 0: no budget (threads bands in flight). The estimate allows
  // 256 KiB of heap slack per thread, which holds where the allocator's arenas are few: glibc's
  // default (8 per core) let a 64-thread build exceed its budget by 7 % on 16 cores; pyramid-build
  // sets M_ARENA_MAX to 8, and an embedding process with many cores should do the same.
  int64_t memory_budget = 0;
};

// What the builder will hold, estimated from the sizes alone (docs/scale.md "Memory model"): the
// rows each level lags behind the input, the bands being coded with their coder buffers (a coded
// stream is counted at 2 bytes a sample: incompressible input coded losslessly holds more), the D
// engines and the input bands. Not counted: the sink (a file writer holds a few MiB per level),
// the reader's own buffers and the process itself.
struct BuildMemoryPlan {
  int bands_in_flight = 1;      // bands of each level coded at once (1 .. threads)
  int64_t minimum_bytes = 0;    // the estimate with one band of each level in flight
  int64_t estimated_bytes = 0;  // the estimate at bands_in_flight
  int64_t finest_rows = 0;      // finest rows held at most (reading waits for the coders beyond)
};
// bands_in_flight is the largest count <= options.threads whose estimate fits options.memory_budget
// (threads when the budget is 0). Throws std::invalid_argument naming the minimum when even one band
// in flight does not fit, and as build_pyramid for unusable options. `band_rows`: the coder's
// (ResidualCoder::band_rows); `striped`: a stripe of a striped build (it also holds a fill band of
// samples read above its rows). `first_level`: a stripe's fine-level build
// (build_pyramid_stripe_fine_levels at k = first_level - 1), which holds no coarse level. Thread-safe.
BuildMemoryPlan plan_build_memory(const GridInfo& input, const BuildOptions& options, int64_t band_rows,
                                  bool striped = false, int first_level = 0);

// Everything a decoder needs besides the per-band bytes.
struct PyramidHeader {
  std::vector<GridSize> levels;  // coarsest first
  DownsampleFilter filter;       // the D used (informative: decoding needs only U)
  int64_t band_rows = 0;         // coder band height at the finest level (halved per coarser level)
  double value_scale = 1.0;
  GridInfo input;  // the input's description
};

// What the builder measured on one level while coding it.
struct LevelBuildStats {
  GridSize size;
  double residual_rms = 0;  // of R_l = T_l - U(T^_{l-1}) (T_0 - 0 for the coarsest)
  int64_t residual_max_abs = 0;
  double error_rms = 0;  // of T_l - T^_l (valid samples at the finest level)
  int64_t error_max_abs = 0;
  uint64_t bytes = 0;  // coded residual bytes
};

// What one coded band contributes to its level's figures (LevelBuildStats); a level's figures are
// these added in band order, top to bottom (LevelFigures), so that they do not depend on how the
// bands were shared out among threads or processes.
struct BandFigures {
  double res_sq = 0, err_sq = 0;  // sums of squared residuals / errors over the counted samples
  int64_t res_max = 0, err_max = 0, counted = 0;
};

// Adds a level's band figures in band order and gives its LevelBuildStats.
class LevelFigures {
 public:
  void add(const BandFigures& band, uint64_t bytes);
  // The level's stats: rms from the sums, the largest values, the bytes.
  LevelBuildStats stats(GridSize size) const;

 private:
  double res_sq_ = 0, err_sq_ = 0;
  int64_t counted_ = 0, res_max_ = 0, err_max_ = 0;
  uint64_t bytes_ = 0;
};

struct BuildResult {
  PyramidHeader header;
  FilterFitReport filter_report;
  std::vector<LevelBuildStats> levels;  // coarsest first
  int64_t void_count = 0;
  // Wall time: seconds_pass_input = fitting D; seconds_pass_residual = the rest of the streaming build
  // (read, D cascade, closed loop).
  double seconds_pass_input = 0, seconds_pass_residual = 0;
  BuildMemoryPlan memory;        // the schedule the budget allowed and its estimate
  std::vector<std::string> log;  // human-readable build log (filter choice, fallbacks)
};

// Receives the output as it is produced: begin() once the filter is known, then the coded bands,
// levels interleaved, each level top to bottom. Before each finest-level band, mask_rows() gives
// the validity of its rows; whether the input has voids at all is known only at the end, so a
// sink that stores a mask decides what to keep once every row has arrived. reconstructed_rows()
// calls may come at any time (even before begin()), each level top to bottom. Ordering levels for
// a file is the sink's business (PyramidFileWriter does it). The calls come one at a time, but not
// always from the thread that called build_pyramid (the builder's coding rounds deliver their
// bands from a thread of their own, each level's as soon as they are coded): a sink needs no lock,
// only no thread affinity.
class PyramidSink {
 public:
  virtual ~PyramidSink() = default;
  virtual void begin(const PyramidHeader& header) { (void)header; }
  virtual void band(int level, int64_t y0, int64_t rows, std::vector<uint8_t>&& bytes) = 0;
  // The figures of the band band() receives next (called just before it).
  virtual void band_figures(int level, int64_t y0, const BandFigures& figures) {
    (void)level, (void)y0, (void)figures;
  }
  // Validity of finest-level rows y0..y0+rows-1, rows x width bytes (1 = data, 0 = void).
  virtual void mask_rows(int64_t y0, int64_t rows, const uint8_t* valid) {
    (void)y0, (void)rows, (void)valid;
  }
  // The decoder-exact reconstruction T^_level of rows y0.. (only called when wants_reconstruction()).
  virtual bool wants_reconstruction(int level) const {
    (void)level;
    return false;
  }
  virtual void reconstructed_rows(int level, int64_t y0, int64_t rows, int64_t width, const int32_t* data) {
    (void)level, (void)y0, (void)rows, (void)width, (void)data;
  }
};

// Keeps nothing but the number of coded bytes: for trial builds and benchmarks, which need the
// figures of a build and not its output. Not thread-safe (the builder calls its sink once at a time).
class CountingSink final : public PyramidSink {
 public:
  void band(int, int64_t, int64_t, std::vector<uint8_t>&& bytes) override { band_bytes += bytes.size(); }
  uint64_t band_bytes = 0;  // coded residual bytes of every level
};

// Builds the pyramid from the input streamed through `input`: one pass, nothing written but what
// the sink writes. Level l lags the input by about 8 * 2^l of its rows, so memory is
// O(width * 2^levels), independent of the input height. Throws Error for I/O problems
// (naming the file) and std::invalid_argument for unusable input or options.
BuildResult build_pyramid(BandReader& input, const BuildOptions& options, ResidualCoder& coder,
                          PyramidSink& sink);

// A build spread over processes (libbuild's stripe build) gives each part a stripe of finest rows
// [y0, y1). A band of level l belongs to the stripe that holds its first row times 2^(m-l), so the
// stripes of a partition of the rows share out every level's bands. The stripe's part reads the
// input from row 0 (the rows above it only for D's fit and the void fill's carry), runs the D
// cascade on its rows plus a halo (D's 11-row support grows to ~11 * 2^m finest rows at the
// coarsest level), codes the bands it owns plus the coarser bands their U windows need, and hands
// only its own bands to the sink (band_figures, mask_rows and band as the whole build does). Every
// band's bytes and figures equal the whole build's. An empty stripe (y0 == y1) codes nothing and
// only fits D (the result's header and filter_report). Throws as build_pyramid, and
// std::invalid_argument for a stripe outside 0..height.
struct BuildStripe {
  int64_t y0 = 0, y1 = 0;
  // Skip the rows above the stripe's cascade (BandReader::skip_rows, a seek for raw, .hgt and .bil)
  // instead of reading them for the void fill's carry; where a fill then needs the carry, the build
  // throws StripeRowsAboveNeeded and the caller runs the stripe again without seek_above (its sink
  // may have received bands by then).
  bool seek_above = false;
};
class StripeRowsAboveNeeded : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
BuildResult build_pyramid_stripe(BandReader& input, const BuildOptions& options, const BuildStripe& stripe,
                                 ResidualCoder& coder, PyramidSink& sink);

// Experimental: the shared coarse levels of libbuild's striped build (docs/scale.md "Cost of the
// decomposition"). A stripe's needed bands grow by about a band per level up the pyramid, so a
// stripe that codes every level runs D over some 30 x 2^m input rows beyond each of its edges; these
// three split the work at a level k (0 <= k < m) instead, with the same bytes as build_pyramid:
//  1. build_stripe_level_rows: the stripe's share of T_k (the level-k rows whose first row times
//     2^(m-k) lies in the stripe, as build_pyramid_stripe shares out bands), made by the D cascade
//     exactly as the whole build makes them; nothing is coded and the sink sees nothing;
//  2. build_pyramid_coarse_levels: levels 0..k coded from the whole T_k (the stripes' shares put
//     together) with options.use_fixed_filter set to the stripes' D; the sink gets them as the whole
//     build gives them, and wants_reconstruction(k) yields T^_k;
//  3. build_pyramid_stripe_fine_levels: the stripe's bands of levels k+1..m, with the whole T^_k given
//     and, optionally, the stripe's T_{m-1} rows that (1) kept (the same stripe, options and seek_above
//     need not match; std::invalid_argument when the rows are another stripe's).
// Each throws as build_pyramid_stripe, and std::invalid_argument for k outside 0..m-1, a given grid
// of the wrong size, or (2) no fixed filter. Thread-safe as build_pyramid (options.threads inside).
struct StripeLevelRows {
  int64_t first_row = 0;      // the first of the stripe's rows of level k
  int64_t width = 0;          // level k's width
  std::vector<int32_t> rows;  // (rows.size() / width) rows from first_row on, row-major
  // With keep_fine (and k < m - 1): the rows of T_{m-1} the stripe's fine-level build runs D on, so
  // that it need not run D's finest level again (a quarter of the stripe's samples, as int32).
  int64_t fine_first_row = 0;
  std::vector<std::vector<int32_t>> fine_rows;  // one vector per row
};
BuildResult build_stripe_level_rows(BandReader& input, const BuildOptions& options, const BuildStripe& stripe,
                                    int level, ResidualCoder& coder, StripeLevelRows& out,
                                    bool keep_fine = false);
BuildResult build_pyramid_coarse_levels(const GridInfo& input, const BuildOptions& options, int level,
                                        const std::vector<int32_t>& level_grid, ResidualCoder& coder,
                                        PyramidSink& sink);
BuildResult build_pyramid_stripe_fine_levels(BandReader& input, const BuildOptions& options,
                                             const BuildStripe& stripe, int level,
                                             const std::vector<int32_t>& coarse_reconstruction,
                                             ResidualCoder& coder, PyramidSink& sink,
                                             const StripeLevelRows* fine = nullptr);

// The same builder fed from memory (the grid is streamed from `map` through a BandReader).
BuildResult build_pyramid(const Heightmap& map, const BuildOptions& options, ResidualCoder& coder,
                          PyramidSink& sink);

// The integer grid the builder codes as its finest level: native value * value_scale, rounded, with
// the voids filled by push-pull exactly as the builder fills them; `valid` receives the mask.
std::vector<int32_t> to_level_grid(const Heightmap& map, const BuildOptions& options,
                                   std::vector<uint8_t>* valid = nullptr);

// A BandReader over an in-memory grid, handing out at most max_rows_per_call rows per call.
std::unique_ptr<BandReader> make_memory_band_reader(const Heightmap& map,
                                                    int64_t max_rows_per_call = 1 << 30);

}  // namespace terrain
