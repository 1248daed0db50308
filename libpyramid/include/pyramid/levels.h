// Pyramid level geometry (Losasso & Hoppe 2004, section 5).
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
#include <vector>

namespace terrain {

struct GridSize {
  int64_t width = 0;
  int64_t height = 0;
  bool operator==(const GridSize&) const = default;
};

// ceil(fine/2): the extent of the next coarser level along one axis (1 stays 1).
inline int64_t coarse_extent(int64_t fine) { return (fine + 1) / 2; }

// Level sizes, coarsest first, the finest (the input's size) last. level_count > 0 asks for exactly that many
// levels (capped at the count that reaches 1x1); level_count == 0 halves while the next level's
// longer side would still be >= min_coarsest_side.
std::vector<GridSize> pyramid_level_sizes(GridSize finest, int level_count, int64_t min_coarsest_side = 128);

}  // namespace terrain
