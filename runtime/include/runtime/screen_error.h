// Screen-space geometric error of the clipmap's levels (L&H 2004 §9, Table 2) and the clipmap size
// it calls for: e_l = PL(T^_l) - T_m at every finest-level sample (PL: the renderer's
// triangulation), projected as e_l * s / g_l pixels, s = the screen-space size of a grid cell.
//
// Threads: each call uses the given sources (not thread-safe, see height_source.h) and nothing
// else; calls on different sources may run concurrently.
#pragma once

#include <cstdint>
#include <vector>

#include "runtime/height_source.h"

namespace terrain::runtime {

struct LevelScreenError {
  int level = 0;                               // source level (0 coarsest)
  double spacing_m = 0;                        // g_l
  double rms_m = 0, max_m = 0;                 // |e_l| in metres
  double rms_px = 0, p999_px = 0, max_px = 0;  // |e_l| in pixels: rms, 99.9th percentile, max
};
// s (pixels per grid cell at the average ring depth 0.4 n g_l, L&H 2004 §4):
// 1.25 W / (n tan(phi/2)), W the frame width (pixels) and phi the horizontal field of view, from
// the vertical one fov_y_deg (degrees) and the aspect width / height.
double triangle_size_px(int width, int height, double fov_y_deg, int n);
// Levels first_level..finest of `rendered` (the heights the clipmap draws) against `original`'s
// finest level; only samples valid in original.finest_valid count. Reads every level whole (time
// and memory of the finest level). Throws std::invalid_argument when the two differ in level count
// or finest size, and what rendered.fill throws.
std::vector<LevelScreenError> screen_space_error(HeightSource& rendered, const GridHeightSource& original,
                                                 int first_level, double s_px);
// The same analysis without the original: `source`'s own finest level stands in for the truth, so
// the figures leave out the finest level's compression error (level l's error against the data is at
// most this plus that). Over the whole finest level when it has at most max_samples samples,
// otherwise over a grid of 256x256 windows spread evenly over it, max_samples in all (bounded time
// and memory on any pyramid). Throws what source.fill throws.
std::vector<LevelScreenError> estimate_screen_space_error(HeightSource& source, int first_level, double s_px,
                                                          int64_t max_samples = int64_t(1) << 22);
// Makes such an estimate an upper bound of the figures against the data, given how far the finest
// level is from the data (rms and max |T^_m - T_m| in metres, >= 0, e.g. the builder's figures the
// .pyr records): the true error is the estimate's plus that difference, so on the same samples rms
// grows by at most finest_rms_m (triangle inequality), p99.9 and max by at most finest_max_m; in
// pixels each times s_px / g_l (s_px > 0).
void add_finest_error_bound(std::vector<LevelScreenError>& errors, double finest_rms_m, double finest_max_m,
                            double s_px);

// The smallest clipmap size n = 2^k - 1 (15..1023) whose worst level's p99.9 screen-space error is at
// most tolerance_px, from `errors` computed at triangle size s_px (> 0; errors scale with s, s with
// 1/n; L&H 2004 §9 suggest sizing the clipmap by the terrain's error) for a width x height frame
// with vertical field of view fov_y_deg degrees.
struct ClipmapSizeChoice {
  int n = 0;           // the size chosen; 1023 when none meets the tolerance
  double p999_px = 0;  // the worst level's p99.9 at that n, pixels
  bool met = false;    // false: even n = 1023 exceeds the tolerance
};
ClipmapSizeChoice clipmap_size_for_screen_error(const std::vector<LevelScreenError>& errors, double s_px,
                                                int width, int height, double fov_y_deg, double tolerance_px);

}  // namespace terrain::runtime
