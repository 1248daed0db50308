// The filtered residual pyramid of Losasso & Hoppe 2004 (sections 5 and 7): the upsampling filter U
// (tensor-product four-point interpolatory subdivision), the per-terrain optimal 11x11 downsampling
// filter D (least squares), and the closed-loop residual pyramid, built streamed out of core.
//
// Levels are numbered coarse to fine: level 0 is the coarsest, level m (= level_count-1) the input.
// Every level is an int32 grid in the input's native units (times BuildOptions::value_scale), so
// that a quantiser step of 1 makes the whole pipeline exactly lossless.
//
// Extent rule (any size, rectangular, tiny): coarse extent = ceil(fine/2) per axis, and coarse
// sample i sits on fine sample 2i (grid-registered: 1201->601->301->151, 1025->513->257,
// 7->4->2->1, 1->1). See docs/pyramid.md for the boundary rules of U and D.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/rect.h"
#include "readers/heightmap.h"

namespace terrain {

// ---------------------------------------------------------------------------------------------
// Level geometry

struct GridSize {
  int64_t width = 0;
  int64_t height = 0;
  bool operator==(const GridSize&) const = default;
};

// ceil(fine/2): the extent of the next coarser level along one axis (1 stays 1).
inline int64_t coarse_extent(int64_t fine) { return (fine + 1) / 2; }

// Level sizes, coarsest first, finest (= finest) last. level_count > 0 asks for exactly that many
// levels (capped at the count that reaches 1x1); level_count == 0 halves while the next level's
// longer side would still be >= min_coarsest_side.
std::vector<GridSize> pyramid_level_sizes(GridSize finest, int level_count, int64_t min_coarsest_side = 128);

// Rectangles of samples on one level: terrain::Rect (core/rect.h).

// ---------------------------------------------------------------------------------------------
// U: four-point interpolatory subdivision, exact integer arithmetic.
//
// Even fine samples copy the coarse sample; odd ones use (-1, 9, 9, -1)/16 along one axis, and
// odd-odd ones the 16-tap tensor product /256, all accumulated in int64 and rounded once, half up
// (floor((s + d/2) / d)). Beyond the level's edges the coarse grid is extended by point reflection
// about the edge sample, c[-k] = 2c[0] - c[k] and c[n-1+k] = 2c[n-1] - c[n-1-k] (a 1-sample axis
// extends as a constant), which keeps linear ramps exact up to and across the edge. For an even
// fine extent the last fine sample (2n-1) is odd and lies half a coarse step beyond the last coarse
// sample: it is interpolated from that extension like any odd sample.

// A window of a coarse level held by the caller: `data` points at sample (x0, y0) of a level of
// size level.
struct CoarseWindow {
  const int32_t* data = nullptr;
  int64_t stride = 0;  // samples between rows
  Rect rect;           // which samples of the coarse level `data` holds
  GridSize level;      // full size of the coarse level
};

// The coarse samples upsample_region needs to produce `fine` on a fine level of size `fine_level`
// (the coarse level is coarse_extent() of it). Always within the coarse level.
Rect upsample_required_window(const Rect& fine, GridSize fine_level);

// Reusable scratch of upsample_region (no allocation once warmed up).
struct UpsampleScratch {
  std::vector<int64_t> rows;    // horizontal pass, int64 path
  std::vector<int32_t> rows32;  // horizontal pass, int32 path (values bounded, see upsample_region)
};

// Writes U(coarse) restricted to the fine rectangle `fine` into out (row stride out_stride).
// `coarse.rect` must contain upsample_required_window(fine, fine_level); fine_level must be the
// level whose coarse_extent is coarse.level. Throws std::invalid_argument otherwise.
// This is the one implementation of U: the encoder and the runtime decoder both call it.
void upsample_region(const CoarseWindow& coarse, GridSize fine_level, const Rect& fine, int32_t* out,
                     int64_t out_stride, UpsampleScratch& scratch);

// Whole-level convenience: fine (fine.width*fine.height) = U(coarse).
void upsample(const int32_t* coarse, GridSize fine_level, int32_t* fine);

// Real-valued U with the same boundary rule and no rounding (filter design and tests).
void upsample_real(const double* coarse, GridSize fine_level, double* fine);

// ---------------------------------------------------------------------------------------------
// D: 11x11 linear downsampling filter, centred on fine sample (2i, 2j) of coarse sample (i, j).
// Beyond the edges the fine level is extended by mirror reflection without repeating the edge
// sample (f[-k] = f[k], f[n-1+k] = f[n-1-k]; folded repeatedly for levels narrower than 6).

struct DownsampleFilter {
  static constexpr int kRadius = 5;
  static constexpr int kSize = 2 * kRadius + 1;
  enum class Kind { Optimal, Default, Impulse, Box2x2, Custom };
  Kind kind = Kind::Default;
  // taps[(dy + 5) * 11 + (dx + 5)] weighs fine sample (2i + dx, 2j + dy). Sums to 1.
  std::array<double, kSize * kSize> taps{};

  double tap(int dx, int dy) const { return taps[size_t((dy + kRadius) * kSize + (dx + kRadius))]; }
  // True when symmetric in x, in y and about the diagonal (enables the folded fast path).
  bool symmetric8() const;
  double sum() const;

  // The default used when the least-squares fit is degenerate: the separable tent
  // (1/4, 1/2, 1/4) x (1/4, 1/2, 1/4).
  static DownsampleFilter default_filter();
  // Plain subsampling: coarse (i, j) = fine (2i, 2j).
  static DownsampleFilter impulse();
  // The 2x2 box of fine (2i..2i+1, 2j..2j+1) (a half-sample shift: the mipmap baseline).
  static DownsampleFilter box2x2();
  // An 8-fold symmetric filter from its 21 orbit weights (see symmetric_orbits()).
  static DownsampleFilter from_orbit_weights(const std::array<double, 21>& w, Kind kind);
};

// The 21 orbits of offsets under the 8-fold symmetry: orbit k holds all (dx, dy) with
// (max(|dx|,|dy|), min(|dx|,|dy|)) == orbit_key(k). Returns, for each k, {a, b, member count}.
struct FilterOrbit {
  int a, b, count;
};
const std::array<FilterOrbit, 21>& symmetric_orbits();

// coarse = round(D(fine)) (half away from zero, saturated to int32); coarse is
// coarse_extent(w) x coarse_extent(h). Same row engine as the streaming builder.
void downsample(const DownsampleFilter& filter, const int32_t* fine, GridSize fine_level, int32_t* coarse,
                int threads = 1);

// How the optimal filter was chosen; also printed to the build log.
struct FilterFitReport {
  bool fallback = false;         // true: the default filter was used
  std::string reason;            // why (fallback) or "least squares fit"
  int windows = 0;               // sample windows used
  int64_t equations = 0;         // rows of the design matrix
  int64_t active_equations = 0;  // rows that see non-flat terrain
  int rank = 0;                  // numerical rank of the 20-column reduced design matrix
  double condition = 0;          // sigma_max / sigma_min of that matrix (inf when rank deficient)
  double rms_optimal = 0;        // rms of T - U(D(T)) on the sample (real-valued U and D)
  double rms_default = 0;        // same for the default filter
  double rms_impulse = 0;        // same for plain subsampling
  std::string summary() const;   // one line for logs
};

struct FilterFitOptions {
  int64_t window = 128;                 // side of the square sample windows
  int max_windows = 16;                 // spread evenly over the grid (4 x 4 for large grids)
  double max_condition = 1e8;           // above: fall back
  double max_abs_tap = 4.0;             // any orbit weight larger in magnitude: fall back
  int64_t min_active_equations = 2000;  // fewer equations that see non-flat terrain: fall back
};

// The sample windows (fine-level rectangles) used to fit D on a grid of this size: up to
// max_windows squares of side min(window, w, h), evenly spread. Empty when the grid is smaller
// than 24 samples on a side (too little data: the fit falls back).
std::vector<Rect> filter_fit_windows(GridSize level, const FilterFitOptions& options = {});

// Least-squares optimal 8-fold symmetric D with DC gain 1 such that U(D(T)) best approximates T on
// the given windows; window_data[k] holds rect k's samples row-major. Degenerate data (flat, a
// spike, constant rows, too small) yields the default filter and report->fallback = true.
DownsampleFilter fit_optimal_filter(const std::vector<Rect>& windows,
                                    const std::vector<std::vector<int32_t>>& window_data,
                                    const FilterFitOptions& options, FilterFitReport* report);
// Convenience: fit on filter_fit_windows() of an in-memory grid.
DownsampleFilter fit_optimal_filter(const int32_t* grid, GridSize level, const FilterFitOptions& options,
                                    FilterFitReport* report);

// Root-mean-square of T - U(round(D(T))) over the whole grid, with the integer pipeline (the
// figure the acceptance test compares for optimal / box / impulse).
double prediction_rms(const DownsampleFilter& filter, const int32_t* grid, GridSize level, int threads = 1);

// ---------------------------------------------------------------------------------------------
// Residual coding interface (the real coder lives in libcodec and implements this).

class ResidualCoder {
 public:
  virtual ~ResidualCoder() = default;
  // Rows per band the coder wants at the finest level: the builder codes each level as consecutive,
  // independent bands (the last one shorter), level l of m+1 with max(1, band_rows >> (m - l)) rows
  // so that coarse bands do not hold back the finer levels. Each band is a whole image to the coder.
  virtual int64_t band_rows() const = 0;
  // encode/decode may be called concurrently from several threads (one band each).
  // Codes one band of integer residuals (w x h, row-major) and writes into `reconstructed` the exact
  // values decode() will produce from the returned bytes. A coder may return no bytes for a band
  // that reconstructs to all zeros (decode then gets n = 0); the pyramid file stores no stream for it.
  virtual std::vector<uint8_t> encode(const int32_t* residual, int64_t w, int64_t h,
                                      int32_t* reconstructed) = 0;
  // Decodes one band; false on malformed or truncated data (never crashes, never reads past n).
  virtual bool decode(const uint8_t* data, size_t n, int64_t w, int64_t h, int32_t* out) = 0;
};

// Uniform scalar quantiser, one absolute step for every level: q = sign(r) * floor((|r| + S/2) / S),
// reconstruction q*S, so |r - r^| <= S/2 (step 1 is lossless). Bytes: zigzag LEB128 varints of q.
class UniformQuantizerCoder final : public ResidualCoder {
 public:
  explicit UniformQuantizerCoder(int32_t step, int64_t band_rows = 64);
  int64_t band_rows() const override { return band_rows_; }
  std::vector<uint8_t> encode(const int32_t* residual, int64_t w, int64_t h, int32_t* reconstructed) override;
  bool decode(const uint8_t* data, size_t n, int64_t w, int64_t h, int32_t* out) override;
  int32_t step() const { return step_; }

 private:
  int32_t step_;
  int64_t band_rows_;
};

// ---------------------------------------------------------------------------------------------
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
  int threads = 2;              // results are bit-identical for every thread count
  int64_t fill_band_rows = 64;  // nodata push-pull works on bands of this many input rows
  int64_t fit_rows = 512;       // D is fitted on windows within the top fit_rows input rows
};

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

struct BuildResult {
  PyramidHeader header;
  FilterFitReport filter_report;
  std::vector<LevelBuildStats> levels;  // coarsest first
  int64_t void_count = 0;
  // Wall time: seconds_pass_input = fitting D; seconds_pass_residual = the rest of the streaming build
  // (read, D cascade, closed loop).
  double seconds_pass_input = 0, seconds_pass_residual = 0;
  std::vector<std::string> log;  // human-readable build log (filter choice, fallbacks)
};

// Receives the output as it is produced: begin() once the filter is known, then the coded bands,
// levels interleaved, each level top to bottom. Before each finest-level band, mask_rows() gives
// the validity of its rows; whether the input has voids at all is known only at the end, so a
// sink that stores a mask decides what to keep once every row has arrived. reconstructed_rows()
// calls may come at any time (even before begin()), each level top to bottom. Ordering levels for
// a file is the sink's business (PyramidFileWriter does it).
class PyramidSink {
 public:
  virtual ~PyramidSink() = default;
  virtual void begin(const PyramidHeader& header) { (void)header; }
  virtual void band(int level, int64_t y0, int64_t rows, std::vector<uint8_t>&& bytes) = 0;
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
// figures of a build and not its output. Not thread-safe (the builder calls its sink from one thread).
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

// An in-memory sink (tests, small inputs) and a decoder over it.
class MemoryPyramid final : public PyramidSink {
 public:
  struct Band {
    int64_t y0, rows;
    std::vector<uint8_t> bytes;
  };
  PyramidHeader header;
  std::vector<std::vector<Band>> bands;     // [level][band]
  std::vector<uint8_t> mask;                // finest level, row-major (1 = data); empty: no voids
  std::vector<std::vector<int32_t>> recon;  // [level] when keep_reconstruction
  bool keep_reconstruction = true;

  void begin(const PyramidHeader& h) override;
  void band(int level, int64_t y0, int64_t rows, std::vector<uint8_t>&& bytes) override;
  void mask_rows(int64_t y0, int64_t rows, const uint8_t* valid) override;
  bool wants_reconstruction(int) const override { return keep_reconstruction; }
  void reconstructed_rows(int level, int64_t y0, int64_t rows, int64_t width, const int32_t* data) override;
  uint64_t total_bytes() const;  // coded residual bytes
};

// Decodes levels 0..up_to_level coarse to fine (U + decoded residual) and returns level
// up_to_level; valid (when non-null) receives the finest level's mask when up_to_level is finest.
// Throws Error(CorruptData) on bad bytes.
std::vector<int32_t> decode_pyramid(const MemoryPyramid& pyramid, ResidualCoder& coder, int up_to_level,
                                    std::vector<uint8_t>* valid = nullptr);

}  // namespace terrain
