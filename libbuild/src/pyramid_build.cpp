// build_pyramid_file: chooses the quantiser step for the user's error target on a calibration
// window, then streams the whole input once through the pyramid builder into the container.
#include "build/pyramid_build.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <mutex>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "build/ptc_coder.h"
#include "codec/codec.h"
#include "container/pyramid_file.h"
#include "core/cores.h"
#include "core/file.h"
#include "core/text.h"

namespace terrain::build {

using namespace terrain::container;  // the stage below

const char* downsample_choice_name(DownsampleChoice choice) {
  switch (choice) {
    case DownsampleChoice::Auto:
      return "auto";
    case DownsampleChoice::Wavelet:
      return "wavelet";
    case DownsampleChoice::Optimal:
      return "optimal";
    case DownsampleChoice::Point:
      return "point";
  }
  return "unknown";
}

std::optional<DownsampleChoice> downsample_choice_from_name(const std::string& name) {
  for (const DownsampleChoice c : {DownsampleChoice::Auto, DownsampleChoice::Wavelet,
                                   DownsampleChoice::Optimal, DownsampleChoice::Point})
    if (name == downsample_choice_name(c)) return c;
  return std::nullopt;
}

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Forwards a BandReader and reports the fraction of rows read.
class ProgressReader final : public BandReader {
 public:
  ProgressReader(BandReader& inner, const BuildProgress& progress) : inner_(inner), progress_(progress) {}
  const GridInfo& info() const override { return inner_.info(); }
  int64_t read_rows(int64_t rows, double* values, uint8_t* valid) override {
    return advanced(inner_.read_rows(rows, values, valid));
  }
  bool reads_int32() const override { return inner_.reads_int32(); }
  int64_t read_rows_int32(int64_t rows, int32_t* values, uint8_t* valid) override {
    return advanced(inner_.read_rows_int32(rows, values, valid));
  }
  // The inner reader's own skip (a seek on raw and .hgt), not the base class's read and discard.
  int64_t skip_rows(int64_t rows) override { return advanced(inner_.skip_rows(rows)); }

 private:
  int64_t advanced(int64_t n) {
    rows_read_ += n;
    if (progress_)
      progress_("reading input", double(rows_read_) / double(std::max<int64_t>(1, info().height)));
    return n;
  }

  BandReader& inner_;
  const BuildProgress& progress_;
};

// Forwards the builder's output to the file and reports the fraction of level rows coded.
class ProgressSink final : public PyramidSink {
 public:
  ProgressSink(PyramidFileWriter& inner, const BuildProgress& progress)
      : inner_(inner), progress_(progress) {}
  void begin(const PyramidHeader& h) override {
    total_ = 0;
    for (const GridSize& s : h.levels) total_ += s.height;
    inner_.begin(h);
  }
  void band(int level, int64_t y0, int64_t rows, std::vector<uint8_t>&& bytes) override {
    inner_.band(level, y0, rows, std::move(bytes));
    done_ += rows;
    if (progress_) progress_("coding levels", double(done_) / double(std::max<int64_t>(1, total_)));
  }
  void mask_rows(int64_t y0, int64_t rows, const uint8_t* valid) override {
    inner_.mask_rows(y0, rows, valid);
  }

 private:
  PyramidFileWriter& inner_;
  const BuildProgress& progress_;
  int64_t total_ = 0, done_ = 0;
};

// The calibration sample: up to calibration_cols columns (centred) of the input's rows. An input of
// at most calibration_rows rows is taken whole; a taller one gives kCalibrationBands bands of
// calibration_rows / kCalibrationBands rows spread evenly from its top to its bottom, so that the
// step represents the whole input (the first rows alone can be all sea on a coastal tile).
constexpr int64_t kCalibrationBands = 4;

std::vector<Heightmap> read_calibration_windows(const std::string& input, const ReadOptions& ro,
                                                const BuildFileOptions& o) {
  auto reader = open_band_reader(input, ro);
  const GridInfo& g = reader->info();
  const int64_t cw = std::min(g.width, o.calibration_cols);
  const int64_t bands = g.height <= o.calibration_rows ? 1 : kCalibrationBands;
  const int64_t bh = bands == 1 ? g.height : std::max<int64_t>(1, o.calibration_rows / bands);
  const int64_t x0 = (g.width - cw) / 2;
  std::vector<Heightmap> windows(static_cast<size_t>(bands));
  std::vector<double> row(size_t(g.width));
  std::vector<uint8_t> valid(size_t(g.width));
  int64_t y = 0;  // rows read so far
  for (int64_t k = 0; k < bands; ++k) {
    const int64_t top = bands == 1 ? 0 : k * (g.height - bh) / (bands - 1);
    // Seeks where the format allows: reading the rows between the windows was a serial pass down
    // the whole input before the build.
    if (y < top && reader->skip_rows(top - y) != top - y)
      throw Error(ErrorCode::Truncated, input + ": ended while reading the calibration windows");
    y = top;
    Heightmap& map = windows[size_t(k)];
    map.info = g;
    map.info.width = cw;
    map.info.height = bh;
    map.values.resize(size_t(cw * bh));
    map.valid.resize(size_t(cw * bh));
    for (int64_t r = 0; r < bh; ++r, ++y) {
      if (reader->read_rows(1, row.data(), valid.data()) != 1)
        throw Error(ErrorCode::Truncated, input + ": ended while reading the calibration windows");
      std::copy_n(row.begin() + x0, cw, map.values.begin() + r * cw);
      std::copy_n(valid.begin() + x0, cw, map.valid.begin() + r * cw);
    }
  }
  return windows;
}

// The D a build uses. Point sampling pays where every sample is bounded (the phase tiles skip the
// even phase); at an rms target the wavelet D's smooth coarse levels cost less (docs/pyramid.md).
DownsampleChoice resolved_downsample(const BuildFileOptions& o) {
  const bool bounded = o.mode == container::ErrorMode::MaxError || o.mode == container::ErrorMode::Lossless;
  return o.downsample != DownsampleChoice::Auto ? o.downsample
         : bounded                              ? DownsampleChoice::Point
                                                : DownsampleChoice::Wavelet;
}

// A fixed D (wavelet or point sampling) into bo; the others are fitted or the default.
void use_fixed_filter(BuildOptions& bo, DownsampleChoice d) {
  if (d != DownsampleChoice::Wavelet && d != DownsampleChoice::Point) return;
  bo.use_fixed_filter = true;
  bo.fixed_filter = d == DownsampleChoice::Point ? DownsampleFilter::impulse() : DownsampleFilter::wavelet();
}

// Whether the step is calibrated by trial builds: at an rms target, and at a max-error target unless
// D is point sampling. There the phase tiles code nearly every tile and the transform step they leave
// to the rest changed the 13 shared DEMs' files by -0.03..+0.03 % (max error 1, 2, 5 m; the codec's
// default 2E against the best of 1E..4E) while the five trial builds took 2-3x the build's time.
bool calibrates_step(const BuildFileOptions& o) {
  return o.mode == container::ErrorMode::Rms ||
         (o.mode == container::ErrorMode::MaxError && resolved_downsample(o) != DownsampleChoice::Point);
}

// Whether build_pyramid_file reads the calibration sample: to calibrate the step, or for an input
// whose values may reach beyond half of libcodec's range (16-bit integers times a unit scale up to 8
// cannot: their centring offset is 0).
bool needs_calibration_sample(const GridInfo& g, double value_scale, const BuildFileOptions& o) {
  const bool calibrating = calibrates_step(o);
  const bool narrow_range = (g.sample_type == SampleType::Int16 || g.sample_type == SampleType::UInt16) &&
                            65535.0 * value_scale <= double(codec::kMaxAbsSample / 2);
  return calibrating || !narrow_range;
}

// The file writer's levels held back in memory before they spill (PyramidFileWriter): 4 MiB each,
// less under a small budget.
size_t level_memory_limit(const BuildFileOptions& o) {
  constexpr int64_t kLimit = int64_t(4) << 20;
  return size_t(o.memory_bytes > 0 ? std::clamp<int64_t>(o.memory_bytes / 256, 64 << 10, kLimit) : kLimit);
}

// What the process holds besides the builder (plan_build_memory): the program and its heap's
// overhead, the file writer's held levels, the calibration sample (freed before the build, but
// the peak) and a striped build's part buffer and one band on assembly.
int64_t ptc_band_rows(uint32_t tile_size) {
  PtcCoderOptions co;
  co.tile_size = tile_size;
  return PtcResidualCoder(co).band_rows();
}

int64_t memory_outside_builder(const GridInfo& g, const BuildOptions& bo, const BuildFileOptions& o,
                               bool striped) {
  constexpr int64_t kProcess = int64_t(12) << 20;  // pyramid-build --help peaks at 5 MiB
  const int levels =
      int(pyramid_level_sizes({g.width, g.height}, bo.level_count, bo.min_coarsest_side).size());
  int64_t bytes = kProcess + int64_t(levels) * int64_t(level_memory_limit(o));
  // The calibration sample (read_calibration_windows: values and validity, one input row) and, for
  // an rms or max-error target, the trial builds of its windows, side by side.
  const int64_t cw = std::min(g.width, o.calibration_cols), ch = std::min(g.height, o.calibration_rows);
  if (needs_calibration_sample(g, bo.value_scale, o)) bytes += cw * ch * 9 + g.width * 9;
  if (o.mode == container::ErrorMode::Rms || o.mode == container::ErrorMode::MaxError) {
    GridInfo w = g;
    w.width = cw;
    w.height = g.height <= o.calibration_rows ? ch : std::max<int64_t>(1, ch / kCalibrationBands);
    BuildOptions wo = bo;
    wo.memory_budget = 0;
    const int64_t windows = g.height <= o.calibration_rows ? 1 : kCalibrationBands;
    const int64_t parallel = std::clamp<int64_t>(bo.threads, 1, windows);
    wo.threads = std::max<int64_t>(1, bo.threads / parallel);
    bytes += parallel * plan_build_memory(w, wo, ptc_band_rows(o.tile_size)).estimated_bytes;
  }
  if (striped) bytes += int64_t(2) << 20;  // the part buffer, one band and its mask on assembly
  return bytes;
}

// Lowest and highest valid value of the calibration sample in level units (lo > hi when it has none).
std::pair<double, double> value_span(const std::vector<Heightmap>& windows, double value_scale) {
  double lo = INFINITY, hi = -INFINITY;
  for (const Heightmap& window : windows)
    for (size_t i = 0; i < window.values.size(); ++i)
      if (window.valid.empty() || window.valid[i]) {
        const double v = std::nearbyint(window.values[i] * value_scale);
        lo = std::min(lo, v), hi = std::max(hi, v);
      }
  return {lo, hi};
}

// Integer level-unit offset that centres the sample's valid values [lo, hi] (value_span) when they
// reach beyond half of libcodec's range; 0 otherwise.
double centring_offset(double lo, double hi) {
  if (!(hi >= lo) || std::max(std::abs(lo), std::abs(hi)) <= double(codec::kMaxAbsSample / 2)) return 0;
  return std::nearbyint(0.5 * (lo + hi));
}

// The coarsest level is coded as values, centred by `offset`: values beyond +-2^20 units of it do not
// fit libcodec. Refused here when the calibration sample shows it (a clear error naming the file
// rather than the coder's failure in the middle of the build; PtcResidualCoder reports what the
// sample missed the same way).
void check_value_span(const std::string& input, double lo, double hi, const LevelUnits& units,
                      double offset) {
  const double limit = double(codec::kMaxAbsSample);
  const auto metres = [&](double v) {
    char text[32];
    std::snprintf(text, sizeof text, "%.10g", v * units.metres_per_unit);
    return std::string(text);
  };
  if (!(hi >= lo) || (hi - offset <= limit && offset - lo <= limit)) return;
  throw Error(ErrorCode::InvalidOption,
              input + ": values from " + metres(lo) + " to " + metres(hi) + " m span " + shortest(hi - lo) +
                  " units of " + shortest(units.metres_per_unit) + " m, more than the " +
                  std::to_string(2 * codec::kMaxAbsSample) + " (2^21) a pyramid codes; " + kValueSpanAdvice);
}

struct Trial {
  double step = 1;
  double coarse_step_ratio = 1;
  double rms = 0;
  int64_t max_abs = 0;
  uint64_t bytes = 0;
};

// Only the figures of a trial matter: it keeps no output and writes no file. Over several windows:
// the rms of all their samples, the largest error, the bytes of all. Each window's D is fitted by its
// first trial and then given to the later ones as a fixed filter (the same taps, so the same trial
// results): the fit does not depend on the step, and refitting it was a third of the calibration's
// CPU time. filters: one per window, empty until fitted.
Trial trial_build(const std::vector<Heightmap>& windows, BuildOptions bo, const PtcCoderOptions& co,
                  std::vector<std::optional<DownsampleFilter>>& filters) {
  PtcResidualCoder coder(co);  // thread-safe: each thread has its own libcodec scratch
  const size_t n = windows.size();
  filters.resize(n);
  // The windows are small pyramids that use few threads well: build them side by side, the threads
  // shared out, and add their figures in window order (the same sums for any thread count).
  std::vector<BuildResult> results(n);
  std::vector<uint64_t> bytes(n, 0);
  std::vector<std::exception_ptr> errors(n);
  const int parallel = int(std::clamp<size_t>(size_t(bo.threads), 1, std::max<size_t>(n, 1)));
  const auto build_window = [&](size_t k) {
    try {
      CountingSink sink;
      BuildOptions wo = bo;
      wo.threads = std::max(1, bo.threads / parallel);
      wo.memory_budget = 0;  // a calibration window is small beside the build it calibrates
      if (filters[k]) {
        wo.use_fixed_filter = true;
        wo.fixed_filter = *filters[k];
      }
      results[k] = build_pyramid(windows[k], wo, coder, sink);
      bytes[k] = sink.band_bytes;
    } catch (...) {
      errors[k] = std::current_exception();
    }
  };
  for (size_t first = 0; first < n; first += size_t(parallel)) {
    const size_t last = std::min(n, first + size_t(parallel));
    std::vector<std::thread> pool;
    for (size_t k = first + 1; k < last; ++k) pool.emplace_back(build_window, k);
    build_window(first);
    for (std::thread& th : pool) th.join();
  }
  for (const std::exception_ptr& e : errors)
    if (e) std::rethrow_exception(e);
  Trial t{co.step, co.coarse_step_ratio, 0, 0, 0};
  double squares = 0, samples = 0;
  for (size_t k = 0; k < n; ++k) {
    const BuildResult& r = results[k];
    if (!filters[k]) filters[k] = r.header.filter;
    const double count = double(windows[k].width() * windows[k].height());
    squares += r.levels.back().error_rms * r.levels.back().error_rms * count;
    samples += count;
    t.max_abs = std::max(t.max_abs, r.levels.back().error_max_abs);
    t.bytes += bytes[k];
  }
  t.rms = samples > 0 ? std::sqrt(squares / samples) : 0;
  return t;
}

}  // namespace

namespace {

BuildFileResult build_file(const std::string& input, const ReadOptions& read_options,
                           const std::string& output, const BuildFileOptions& o,
                           const std::string& metadata_json_extra, const BuildProgress& progress) {
  // The output must not replace the input or one of its side files (sidecar, ESRI header, .prj).
  check_output_path(output, {input, input + ".json", input + ".hdr", input + ".prj"});
  BuildFileResult out;
  auto reader = open_band_reader(input, read_options);
  const GridInfo g = reader->info();
  const LevelUnits units = level_units(g, o.quantum_metres);
  out.metres_per_unit = units.metres_per_unit;
  out.finest_samples = g.width * g.height;
  const double mpu = units.metres_per_unit;

  BuildOptions bo;
  bo.level_count = o.levels;
  bo.value_scale = units.value_scale;
  bo.threads = o.threads > 0 ? o.threads : usable_cores();
  out.threads = bo.threads;
  DownsampleChoice d = resolved_downsample(o);  // at an rms target, Auto is settled by the calibration
  use_fixed_filter(bo, d);

  // Inputs far from zero (1e6 m, int32 millimetres, bathymetry in centimetres) would put the coarsest
  // level, which is coded as values rather than residuals, outside libcodec's +-2^20: centre them on
  // the calibration sample's mid-range. Ordinary DEMs keep their native units (offset 0).
  // The memory budget: what the builder may hold is the budget less what the process holds besides
  // (a plan that does not fit fails here, before anything is read).
  const bool striped_plan = o.journal || o.stripes > 0 || (o.group && o.group->size() > 1);
  const int64_t band_rows = ptc_band_rows(o.tile_size);
  out.memory_outside_builder = memory_outside_builder(g, bo, o, striped_plan);
  if (o.memory_bytes > 0) {
    const int64_t minimum =
        plan_build_memory(g, bo, band_rows, striped_plan).minimum_bytes + out.memory_outside_builder;
    const auto mib = [](int64_t b) { return std::to_string((b + (1 << 20) - 1) >> 20); };
    if (minimum > o.memory_bytes)
      throw std::invalid_argument(
          input + ": a memory budget of " + mib(o.memory_bytes) + " MiB is below the " + mib(minimum) +
          " MiB this " + std::to_string(g.width) + " x " + std::to_string(g.height) +
          " input needs (the rows each level lags behind the input, one band of each level being coded, "
          "docs/scale.md): give at least " +
          mib(minimum) + "M, or fewer levels");
    bo.memory_budget = o.memory_bytes - out.memory_outside_builder;
  }
  out.memory = plan_build_memory(g, bo, band_rows, striped_plan);

  // The sample is read only when something needs it (needs_calibration_sample): the windows are
  // spread to the input's bottom, which the raw, .hgt, .bil and .flt readers seek to, and which
  // costs the other formats (compressed or images) a serial pass down the whole input.
  std::vector<Heightmap> window;
  if (needs_calibration_sample(g, bo.value_scale, o))
    window = read_calibration_windows(input, read_options, o);
  const auto [lo, hi] = value_span(window, units.value_scale);
  bo.value_offset = centring_offset(lo, hi);
  check_value_span(input, lo, hi, units, bo.value_offset);
  std::vector<std::optional<DownsampleFilter>> window_filters;  // each calibration window's D
  const LevelUnits stored =
      LevelUnits{units.metres_per_unit, units.value_scale, units.offset_metres + bo.value_offset * mpu};

  PtcCoderOptions co;
  co.tile_size = o.tile_size;
  co.screen_level_error = o.screen_level_error;
  // Point sampling: every level's residual is coded by phase tiles (the even phase is the coarse
  // level's error), bounded or with the step as a real-valued bin; the calibration trials too.
  co.phase_tiles = d == DownsampleChoice::Point;
  const auto t_cal = std::chrono::steady_clock::now();
  if (!(o.coarse_step_ratio >= 0 && o.coarse_step_ratio <= 1))
    throw Error(ErrorCode::InvalidOption,
                "coarse step ratio " + std::to_string(o.coarse_step_ratio) + " is outside (0, 1]");
  if (o.coarse_step_ratio > 0 && (o.mode == ErrorMode::Lossless || o.mode == ErrorMode::MaxError))
    throw Error(ErrorCode::InvalidOption,
                "a coarse step ratio applies to --step and --rms targets, not lossless or max error");
  switch (o.mode) {
    case ErrorMode::Lossless:
      if (!g.integer_valued() && o.quantum_metres <= 0)
        throw std::invalid_argument(
            "lossless needs integer input; float input is quantised to --quantum (give one)");
      co.step = 1;
      break;
    case ErrorMode::Step:
      co.step = o.target_metres / mpu;
      if (co.step > kLargestStep)
        throw Error(ErrorCode::InvalidOption, "step " + std::to_string(o.target_metres) +
                                                  " m is above the coder's largest, " +
                                                  std::to_string(kLargestStep * mpu) + " m (2^20 units)");
      if (!(co.step >= 1))
        throw std::invalid_argument("step " + std::to_string(o.target_metres) +
                                    " m is below the input's unit of " + std::to_string(mpu) + " m");
      co.coarse_step_ratio = o.coarse_step_ratio > 0 ? o.coarse_step_ratio : 1.0;
      break;
    case ErrorMode::Rms: {
      if (!(o.target_metres > 0)) throw std::invalid_argument("rms target must be positive");
      const double target = o.target_metres / mpu;
      if (progress) progress("calibrating step", 0);
      // rms grows with the step as a power law, about linearly at high rates and much more slowly
      // on smooth terrain at low rates (where much of the finest error is the coarse levels'): each
      // move follows the slope of log rms against log step measured by the last two trials (`slope`,
      // carried from call to call; 1 before any), a secant step that takes 3-4 trials where plain
      // proportional moves took 6-10. Once a step above and one below the target are known, the
      // moves stay between them (bisecting, in log step, when the secant would leave). The result is
      // the largest step whose rms is at most the target (a search ends within 2 % below it): the
      // target is a bound, as a user reads it, and smooth or flat terrain, whose rms stays 0 up to a
      // large step and then jumps, must not be given a step that overshoots it. (Accepting 2 % above
      // put Berlin's --rms 0.5 at 0.507 m.) Returns the chosen trial and whether it meets the target.
      const auto calibrate = [&](const BuildOptions& cbo, PtcCoderOptions cco,
                                 std::vector<std::optional<DownsampleFilter>>& filters, const char* label,
                                 double progress_from, double first_step, double& slope) {
        Trial below{}, above{};  // largest step meeting the target; smallest step missing it
        bool have_below = false, have_above = false;
        Trial previous_trial{};
        double step = std::clamp(first_step, 1.0, kLargestStep);
        for (int i = 0; i < 10; ++i) {
          cco.step = step;
          const Trial t = trial_build(window, cbo, cco, filters);
          out.calibration_log.push_back(std::string(label) + "step " + std::to_string(t.step) +
                                        " units: rms " + std::to_string(t.rms * mpu) + " m, " +
                                        std::to_string(t.bytes) + " bytes");
          if (progress) progress("calibrating step", progress_from + (i + 1) / 20.0);
          if (t.rms <= target) {
            if (!have_below || t.step > below.step) below = t, have_below = true;
          } else if (!have_above || t.step < above.step) {
            above = t, have_above = true;
          }
          if (t.rms <= target && (t.rms >= 0.98 * target || step <= 1)) break;
          if (i > 0 && t.rms > 0 && previous_trial.rms > 0 && t.step != previous_trial.step) {
            const double s = std::log(t.rms / previous_trial.rms) / std::log(t.step / previous_trial.step);
            if (std::isfinite(s)) slope = std::clamp(s, 0.25, 2.0);
          }
          previous_trial = t;
          const double previous = step;
          step =
              t.rms > 0 ? step * std::clamp(std::pow(0.99 * target / t.rms, 1 / slope), 0.5, 4.0) : 4 * step;
          if (have_below && have_above) {
            if (above.step / below.step < 1.03) break;
            if (!(step > below.step && step < above.step)) step = std::sqrt(below.step * above.step);
          }
          step = std::clamp(step, 1.0, kLargestStep);
          if (step == previous) break;
        }
        return std::pair<Trial, bool>(have_below ? below : above, have_below);
      };
      // The coarse levels' step ratio: the given one, or the first of 1, 0.7, 0.5, 0.35 after which a
      // smaller one no longer codes the windows in 1 % fewer bytes at the target, each calibrated from
      // the previous one's step and slope (on flat terrain a smaller ratio lowers the finest level's
      // rms a lot: Berlin at 2 m took step 9.4 at ratio 1, 19.3 at 0.35). No search beyond ratio 1
      // when its bytes exceed search_limit (0: none): a family that needs twice the other's bytes
      // at ratio 1 does not win by the ratio, which saved at most 43 % (docs/pyramid.md).
      const auto calibrate_ratio = [&](const BuildOptions& cbo, PtcCoderOptions cco,
                                       std::vector<std::optional<DownsampleFilter>>& filters,
                                       const std::string& label, double progress_from, double first_step,
                                       uint64_t search_limit) {
        double slope = 1;
        if (o.coarse_step_ratio > 0) {
          cco.coarse_step_ratio = o.coarse_step_ratio;
          return calibrate(cbo, cco, filters, label.c_str(), progress_from, first_step, slope);
        }
        cco.coarse_step_ratio = 1;
        auto best = calibrate(cbo, cco, filters, label.c_str(), progress_from, first_step, slope);
        if (search_limit > 0 && best.first.bytes > search_limit) return best;
        for (const double r : {0.7, 0.5, 0.35}) {
          cco.coarse_step_ratio = r;
          const std::string l = label + "ratio " + std::to_string(r).substr(0, 4) + ": ";
          const auto t = calibrate(cbo, cco, filters, l.c_str(), progress_from, best.first.step, slope);
          if (!t.second || (best.second && double(t.first.bytes) >= 0.99 * double(best.first.bytes))) break;
          best = t;
        }
        return best;
      };
      if (o.downsample != DownsampleChoice::Auto) {
        const Trial t =
            calibrate_ratio(bo, co, window_filters, "", 0.5, codec::step_for_target_rms(target), 0).first;
        co.step = t.step;
        co.coarse_step_ratio = t.coarse_step_ratio;
        break;
      }
      // The default D at an rms target: whichever of the wavelet D (its residuals coded by the
      // transforms) and point sampling (phase tiles with the step as a real-valued bin) the calibration
      // windows code in fewer bytes at the target. Neither wins everywhere: point sampling is 4-14 %
      // smaller on rough terrain at 1-2 m and 2-3x larger on flat plains (docs/pyramid.md).
      const auto [wavelet, wavelet_met] =
          calibrate_ratio(bo, co, window_filters, "D wavelet: ", 0.0, codec::step_for_target_rms(target), 0);
      BuildOptions point_bo = bo;
      use_fixed_filter(point_bo, DownsampleChoice::Point);
      PtcCoderOptions point_co = co;
      point_co.phase_tiles = true;
      std::vector<std::optional<DownsampleFilter>> point_filters;
      // A uniform bin B gives rms B / sqrt(12) where the transform's step S gives 0.315 S
      // (codec::predicted_rms): start the point sampling's search from the wavelet's step scaled so.
      const double bin_per_step = codec::predicted_rms(1.0) * std::sqrt(12.0);
      const Trial point = calibrate_ratio(point_bo, point_co, point_filters, "D point: ", 0.5,
                                          wavelet.step * bin_per_step, wavelet_met ? 2 * wavelet.bytes : 0)
                              .first;
      // On integer heights a real-valued bin's rms moves in jumps (bins of 3.2 and 3.5 samples round
      // the same residuals differently): point sampling must come within 10 % below the target (the
      // --rms contract), or the wavelet D's smooth step-rms curve is kept (Provence at 1 m: 0.875 m,
      // -12.5 %). Within 10 %, fewer bytes at a lower rms is better on both counts.
      const bool point_close = point.rms <= target && point.rms >= 0.9 * target;
      if (point_close && (point.bytes < wavelet.bytes || !wavelet_met)) {
        bo = point_bo;
        co = point_co;
        co.step = point.step;
        co.coarse_step_ratio = point.coarse_step_ratio;
        d = DownsampleChoice::Point;
      } else {
        co.step = wavelet.step;
        co.coarse_step_ratio = wavelet.coarse_step_ratio;
      }
      // A target that only step 1 meets (every level exact) is met by the lossless build, which codes
      // integer heights in fewer bytes than the transforms at step 1 (Berlin --rms 0.25: 609312 ->
      // 500824 bytes, the --lossless file's size).
      if (co.step <= 1 && (g.integer_valued() || o.quantum_metres > 0)) {
        use_fixed_filter(bo, DownsampleChoice::Point);
        co.phase_tiles = true;
        co.step = 1;
        co.coarse_step_ratio = 1;
        co.bound_max_error = true;
        co.max_error = 0;
        d = DownsampleChoice::Point;
      }
      break;
    }
    case ErrorMode::MaxError: {
      // Float input loses up to half a quantum when it is rounded to level units.
      const double budget =
          g.integer_valued() && o.quantum_metres <= 0 ? o.target_metres : o.target_metres - 0.5 * mpu;
      const double e_units = std::floor(budget / mpu + 1e-9);
      if (!(e_units >= 0))
        throw std::invalid_argument("max error " + std::to_string(o.target_metres) +
                                    " m is below the input's unit");
      out.max_error_units = uint32_t(std::min<double>(e_units, codec::kMaxAbsSample));
      co.bound_max_error = true;
      co.max_error = out.max_error_units;
      co.step = std::clamp(2.0 * out.max_error_units, 1.0, kLargestStep);
      if (out.max_error_units > 0 && calibrates_step(o)) {
        // The transform step that gives the fewest bytes under the bound depends on the terrain.
        if (progress) progress("calibrating step", 0);
        Trial best{};
        for (double f : {1.0, 1.5, 2.0, 3.0, 4.0}) {
          co.step = std::clamp(f * out.max_error_units, 1.0, kLargestStep);
          const Trial t = trial_build(window, bo, co, window_filters);
          out.calibration_log.push_back("step " + std::to_string(t.step) + " units: max " +
                                        std::to_string(t.max_abs) + " units, " + std::to_string(t.bytes) +
                                        " bytes");
          if (best.bytes == 0 || t.bytes < best.bytes) best = t;
        }
        co.step = best.step;
      }
      break;
    }
  }
  out.seconds_calibrate = seconds_since(t_cal);
  out.step_units = co.step;
  out.coarse_step_ratio = co.coarse_step_ratio;
  std::vector<Heightmap>().swap(window);  // calibrated: the build does not need the sample

  const auto t_build = std::chrono::steady_clock::now();
  // Lossless point-sampled streams become max-error streams with E = 0 (their phase tiles beside the
  // other modes: the coarsest level keeps the transform).
  if (d == DownsampleChoice::Point && o.mode == ErrorMode::Lossless)
    co.bound_max_error = true, co.max_error = 0;
  PtcResidualCoder coder(co);
  const int rank = o.group ? o.group->rank() : 0;
  std::optional<PyramidFileWriter> writer;
  const auto open_output = [&]() -> PyramidFileWriter& {
    writer.emplace(output);
    writer->set_level_memory_limit(level_memory_limit(o));
    return *writer;
  };
  StripeBuildOptions so;
  so.directory = stripe_directory(output);
  // Everything the output depends on: parts of another input or other options are never reused.
  std::ostringstream fp;
  fp.precision(17);
  std::error_code ec;
  const auto input_bytes = std::filesystem::file_size(input, ec);
  const auto input_time = std::filesystem::last_write_time(input, ec).time_since_epoch().count();
  fp << "pyramid-build stripe journal 3\ninput " << input << " " << input_bytes << " " << input_time << " "
     << g.width << "x" << g.height << " " << sample_type_name(g.sample_type) << " " << g.nodata.value_or(0)
     << "\noptions " << metadata_json_extra << " step " << co.step << " max " << co.max_error << " "
     << co.bound_max_error << " tile " << co.tile_size << " band " << coder.band_rows() << " screen "
     << co.screen_level_error << " ratio " << co.coarse_step_ratio << " levels " << bo.level_count
     << " scale " << bo.value_scale << " offset " << bo.value_offset << "\n";
  const int journal_stripes = read_journal_stripes(so.directory, fp.str());
  const int processes = o.group ? o.group->size() : 1;
  if (o.journal || o.stripes > 0 || processes > 1 || journal_stripes > 0) {
    so.stripes = o.stripes > 0         ? o.stripes
                 : journal_stripes > 0 ? journal_stripes
                 : processes > 1       ? processes
                                       : 4;
    so.fingerprint = fp.str() + "stripes " + std::to_string(so.stripes) + "\n";
    so.group = o.group;
    if (progress && rank == 0) so.progress = [&](double f) { progress("coding stripes", f); };
    out.build = build_stripes([&] { return open_band_reader(input, read_options); }, bo, coder, so,
                              open_output, &out.stripes_resumed);
    out.stripes = so.stripes;
  } else {
    // The reader reports from the builder's input thread, the sink from its coding thread; reading
    // and coding overlap, so they are one phase, "building", at the mean of the two fractions (two
    // phases took turns and restarted the bar each time).
    std::mutex progress_lock;
    double read_fraction = 0, coded_fraction = 0;
    const BuildProgress locked = [&](const std::string& phase, double f) {
      const std::lock_guard<std::mutex> hold(progress_lock);
      (phase == "reading input" ? read_fraction : coded_fraction) = f;
      progress("building", 0.5 * (read_fraction + coded_fraction));
    };
    ProgressReader preader(*reader, progress ? locked : progress);
    ProgressSink psink(open_output(), progress ? locked : progress);
    out.build = build_pyramid(preader, bo, coder, psink);
  }
  out.seconds_build = seconds_since(t_build);
  const int levels = int(out.build.levels.size());
  for (int l = 0; l < levels; ++l) out.level_step_units.push_back(coder.level_options(levels - 1 - l).step);

  ContainerInfo info;
  info.spacing_x = g.spacing_x;
  info.spacing_y = g.spacing_y;
  info.horizontal_units = g.horizontal_units;
  info.vertical_units = "m";
  info.vertical_scale = mpu;
  info.vertical_offset = stored.offset_metres;
  if (const auto gt = geotransform(g)) {
    Georeference geo;
    geo.geotransform = *gt;
    geo.units = g.horizontal_units == "arc-second" ? "degree" : g.horizontal_units;
    geo.crs_epsg = g.crs_epsg ? uint32_t(*g.crs_epsg) : 0;
    geo.crs_text = g.crs_text;
    info.georeference = std::move(geo);
  }
  info.quantisation.step_units = co.step;
  info.quantisation.step_metres = co.step * mpu;
  info.quantisation.mode = o.mode;
  info.quantisation.target = o.mode == ErrorMode::Lossless ? 0 : o.target_metres;

  // No timings or other run-dependent values in the file: the same input and options must give a
  // byte-identical file whatever the thread count or machine load (build times go to --json).
  std::ostringstream meta;
  meta.precision(10);
  meta << "{\"tool\":\"pyramid-build\",\"version\":\"0.1.0\",\"source\":" << json_quote(input)
       << ",\"source_format\":\"" << file_format_name(g.format) << "\",\"source_type\":\""
       << sample_type_name(g.sample_type) << "\",\"step_units\":" << co.step
       << ",\"max_error_units\":" << out.max_error_units << ",\"tile_size\":" << co.tile_size
       << ",\"band_rows\":" << coder.band_rows() << ",\"level_error\":\""
       << (co.screen_level_error ? "screen" : "absolute")
       << "\",\"coarse_step_ratio\":" << co.coarse_step_ratio
       << ",\"filter\":" << json_quote(out.build.filter_report.summary())
       << ",\"options\":" << (metadata_json_extra.empty() ? "{}" : metadata_json_extra) << "}";
  if (!writer) {
    out.wrote_output = false;
    return out;
  }
  writer->finish(out.build, info, meta.str());
  if (out.stripes) remove_stripe_directory(so.directory);
  out.file_bytes = uint64_t(std::filesystem::file_size(output));
  return out;
}

}  // namespace

BuildFileResult build_pyramid_file(const std::string& input, const ReadOptions& read_options,
                                   const std::string& output, const BuildFileOptions& o,
                                   const std::string& metadata_json_extra, const BuildProgress& progress) {
  try {
    return build_file(input, read_options, output, o, metadata_json_extra, progress);
  } catch (const ValueRangeError& e) {  // the coder does not know the file
    throw Error(e.code(), input + ": " + e.what());
  }
}

}  // namespace terrain::build
