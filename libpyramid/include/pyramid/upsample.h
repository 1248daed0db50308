// The upsampling filter U: tensor-product four-point interpolatory subdivision (L&H 2004 §7).
// Pure functions; any thread.
#pragma once

#include <cstdint>
#include <vector>

#include "core/rect.h"
#include "pyramid/levels.h"

namespace terrain {

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

}  // namespace terrain
