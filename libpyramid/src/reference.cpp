// The D cascade of the builder, run on a whole in-memory grid.
#include "pyramid/reference.h"

#include <algorithm>

namespace terrain {

ReferenceLevels reference_levels(const Heightmap& map, const BuildOptions& options) {
  ReferenceLevels r;
  std::vector<int32_t> finest = to_level_grid(map, options);
  r.sizes = pyramid_level_sizes({map.width(), map.height()}, options.level_count, options.min_coarsest_side);
  const size_t m = r.sizes.size() - 1;
  if (options.use_fixed_filter) {
    r.filter = options.fixed_filter;
  } else {
    // The builder fits D before it has seen more than the top fit_rows rows; rows are contiguous, so
    // those rows are a grid of their own.
    FilterFitReport report;
    r.filter = fit_optimal_filter(finest.data(), {map.width(), std::min(map.height(), options.fit_rows)},
                                  options.fit, &report);
  }
  r.levels.resize(r.sizes.size());
  r.levels[m] = std::move(finest);
  for (size_t l = m; l > 0; --l) {
    r.levels[l - 1].resize(size_t(r.sizes[l - 1].width * r.sizes[l - 1].height));
    downsample(r.filter, r.levels[l].data(), r.sizes[l], r.levels[l - 1].data(), options.threads);
  }
  return r;
}

}  // namespace terrain
