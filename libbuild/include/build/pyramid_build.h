// From a heightmap file to a compressed pyramid file: error target -> quantiser step, the streamed
// build through libcodec into the container. The library form of `pyramid-build`, so benchmarks
// and tests run exactly what the tool runs.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "build/stripe_build.h"
#include "container/container.h"
#include "pyramid/level_units.h"
#include "pyramid/pyramid.h"
#include "readers/heightmap.h"

namespace terrain::build {

// D, the downsampling filter of the coarse levels (the decoder never needs it; the file records its taps).
enum class DownsampleChoice {
  Auto,     // the default: Point for --max-error and --lossless, Wavelet for --rms and --step
  Wavelet,  // DownsampleFilter::wavelet(), the dual of U: smaller files at an rms target, nothing to fit
  Optimal,  // the paper's per-terrain least-squares 11x11 D (L&H 2004 §7), fitted on the top rows
  // DownsampleFilter::impulse(): every level's samples are input samples; with a max-error bound (0 =
  // lossless) the residuals are coded by libcodec's phase tiles, which skip the even phase (21-26 %
  // smaller at max error 2 m, 9 % lossless on Rainier; docs/pyramid.md "D: point sampling").
  Point,
};
// "auto", "wavelet", "optimal" or "point" (pyramid-build --downsample, Python's downsample=, the
// file's metadata).
const char* downsample_choice_name(DownsampleChoice choice);
// The choice of that name; nullopt for any other string.
std::optional<DownsampleChoice> downsample_choice_from_name(const std::string& name);

struct BuildFileOptions {
  container::ErrorMode mode =
      container::ErrorMode::Lossless;  // what target_metres is (stored in the file as given)
  double target_metres = 0;            // the step, rms or max error asked for, in metres
  double quantum_metres = 0;  // level unit for float input (0: 0.01 m); integer input uses its own unit
  int levels = 0;             // 0: automatic
  uint32_t tile_size = 32;    // libcodec tile side: 32 keeps a 255x255 window under 1.3x its area
  int threads = 0;            // 0: the cores this process may run on (usable_cores(), core/cores.h)
  // Bytes the whole build may hold (pyramid-build --memory): the builder gets this less what the
  // process holds besides it, and codes fewer bands at once when that is tight (the same bytes).
  // 0: no budget. A budget below the input's minimum fails at the start (std::invalid_argument).
  int64_t memory_bytes = 0;
  int64_t calibration_rows = 1024;  // rms/max-error calibration sample: this many rows (taller inputs: in
                                    // 4 bands spread from top to bottom) x up to calibration_cols columns
  int64_t calibration_cols = 2048;
  // Level error schedule (PtcCoderOptions::screen_level_error): false, the paper's one absolute step
  // (and max error) at every level; true, level l's step and max error grow with its spacing, 2^(m-l)
  // times the finest level's, for the same screen-space error at every level. The rms / max-error
  // target and its calibration always refer to the finest level.
  bool screen_level_error = false;
  // The coarse levels' step over the finest level's, per level (PtcCoderOptions::coarse_step_ratio):
  // level l's step is the finest's times ratio^min(m - l, 2). In (0, 1], or 0 (default): 1 (the paper's one
  // absolute step) for a step target, and for an rms target the first of 1, 0.7, 0.5 and 0.35 after
  // which a smaller ratio no longer codes the calibration sample in fewer bytes. Step and rms targets
  // only (a max-error or lossless build with a ratio is an InvalidOption error).
  double coarse_step_ratio = 0;
  DownsampleChoice downsample = DownsampleChoice::Auto;
  // The striped build (build/stripe_build.h): the finest rows cut into stripes, each coded into a part
  // file in OUTPUT.build/ and shared out among the processes of `group`; rank 0 writes the output from
  // the parts. Used when journal is set, stripes > 0, the group has more than one process, or a
  // journal of the same input and options is there (a killed build: its complete stripes are kept).
  // The output is byte-identical to the plain build's.
  bool journal = false;
  int stripes = 0;                // 0: the journal's, else one per process (4 for one process)
  ProcessGroup* group = nullptr;  // null: this process alone
};

struct BuildFileResult {
  BuildResult build;
  double step_units = 1;                 // quantiser step chosen, in level units (the finest level's)
  double coarse_step_ratio = 1;          // the coarse levels' step ratio used (given or calibrated)
  std::vector<double> level_step_units;  // each level's step, coarsest first
  double metres_per_unit = 1;
  uint32_t max_error_units = 0;  // max-error mode: the bound in level units
  std::vector<std::string> calibration_log;
  uint64_t file_bytes = 0;
  double seconds_calibrate = 0, seconds_build = 0;
  int64_t finest_samples = 0;
  BuildMemoryPlan memory;              // the builder's schedule and estimate under the budget
  int64_t memory_outside_builder = 0;  // the estimate of what the process holds besides the builder
  int threads = 0;                     // the threads the build ran on (options' threads, or its default)
  int stripes = 0;                     // striped build: stripes (0: the plain build)
  int stripes_resumed = 0;             // parts an earlier, killed build had completed
  bool wrote_output = true;            // false on the ranks other than 0 of a group
};

// Progress: phase name and fraction done in [0, 1]; called once at a time, from the building thread
// or, while the levels are coded, from the builder's coding thread.
using BuildProgress = std::function<void(const std::string& phase, double fraction)>;

// Builds `output` from `input`. Throws Error for input problems (naming the file), Error for
// output problems, std::invalid_argument for options the input cannot honour (e.g. a step below the
// input's quantum, lossless on float input without a quantum), Error(InvalidOption) naming the file
// for values the coder cannot hold in the input's units (a span over 2^21 units, or a residual over
// 2^20: docs/pyramid.md "Value range"). Nothing is left at `output` on failure
// (a striped build keeps its complete parts in OUTPUT.build/ for a resumed run). With a group: every
// process calls it with the same arguments (collective); only rank 0 writes `output`.
BuildFileResult build_pyramid_file(const std::string& input, const ReadOptions& read_options,
                                   const std::string& output, const BuildFileOptions& options,
                                   const std::string& metadata_json_extra = "{}",
                                   const BuildProgress& progress = nullptr);

}  // namespace terrain::build
