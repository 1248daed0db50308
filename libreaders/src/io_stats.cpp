// Min/max/mean over valid samples, in metres, either from a whole grid or streamed band by band.
#include <algorithm>
#include <limits>
#include <vector>

#include "readers/internal/io_internal.h"

namespace terrain {
namespace {

// Accumulates native values; converting only the extremes to metres keeps the per-sample work minimal.
struct StatsAccumulator {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  double sum = 0;
  int64_t valid = 0, voids = 0;

  void add(const double* values, const uint8_t* valid_flags, int64_t count) {
    for (int64_t i = 0; i < count; ++i) {
      if (valid_flags && !valid_flags[i]) {
        ++voids;
        continue;
      }
      double v = values[i];
      lo = std::min(lo, v);
      hi = std::max(hi, v);
      sum += v;
      ++valid;
    }
  }

  GridStats finish(const GridInfo& g) const {
    GridStats s;
    s.valid_count = valid;
    s.nodata_count = voids;
    if (valid == 0) return s;
    double a = lo * g.vertical_scale + g.vertical_offset;
    double b = hi * g.vertical_scale + g.vertical_offset;
    s.min_m = std::min(a, b);  // a negative scale swaps the extremes
    s.max_m = std::max(a, b);
    s.mean_m = (sum / double(valid)) * g.vertical_scale + g.vertical_offset;
    return s;
  }
};

}  // namespace

GridStats compute_stats(const Heightmap& map) {
  StatsAccumulator acc;
  acc.add(map.values.data(), map.valid.empty() ? nullptr : map.valid.data(), int64_t(map.values.size()));
  return acc.finish(map.info);
}

GridStats stream_stats(BandReader& reader, int64_t band_rows) {
  const GridInfo& g = reader.info();
  band_rows = std::max<int64_t>(1, band_rows);
  std::vector<double> values(size_t(band_rows * g.width));
  std::vector<uint8_t> valid(values.size());
  StatsAccumulator acc;
  while (int64_t n = reader.read_rows(band_rows, values.data(), valid.data()))
    acc.add(values.data(), valid.data(), n * g.width);
  return acc.finish(g);
}

}  // namespace terrain
