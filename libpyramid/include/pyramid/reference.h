// The levels the builder approximates, without coding anything: the "levels only" pyramid (the D
// cascade alone). Verification tools compare a compressed pyramid's T^_l with these T_l; running the
// whole closed-loop builder with a lossless coder gives the same levels at several times the cost.
#pragma once

#include <cstdint>
#include <vector>

#include "pyramid/pyramid.h"

namespace terrain {

struct ReferenceLevels {
  std::vector<GridSize> sizes;               // coarsest first, as pyramid_level_sizes gives them
  DownsampleFilter filter;                   // the D used: options.fixed_filter or the fitted one
  std::vector<std::vector<int32_t>> levels;  // [level] row-major, in level units
};

// Returns the builder's own T_l for every level of build_pyramid(map, options, ...): the finest level
// is to_level_grid(map, options) (value scale and offset, voids filled by push-pull), and each
// coarser level is round(D(T_l)) with the builder's D (options.fixed_filter, or fitted on the top
// options.fit_rows rows exactly as the builder fits it) and its row engine, so every level equals
// bit for bit what the builder codes. A lossless build (UniformQuantizerCoder(1)) reconstructs the
// same values everywhere except at voids, where it gives its prediction and these levels hold the
// fill. Uses options.level_count, min_coarsest_side, value_scale, value_offset, use_fixed_filter,
// fixed_filter, fit, fit_rows, fill_band_rows and threads (results do not depend on threads).
// Holds the whole pyramid in memory (about 4/3 x 4 bytes per finest sample, plus 9 bytes per sample
// while converting). Throws std::invalid_argument for unusable input or options, as build_pyramid.
// Thread-safe (no shared state).
ReferenceLevels reference_levels(const Heightmap& map, const BuildOptions& options);

}  // namespace terrain
