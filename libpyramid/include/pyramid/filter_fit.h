// The per-terrain optimal D: a least-squares fit of U(D(T)) to T on sample windows (L&H 2004 §7).
// Pure functions; any thread.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/rect.h"
#include "pyramid/downsample.h"

namespace terrain {

// How the optimal filter was chosen; also printed to the build log.
struct FilterFitReport {
  bool fitted = false;           // false: no fit ran (a fixed filter; reason names it)
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

}  // namespace terrain
