// Helpers of the numerical stress suite: write a synthetic grid as a raw file + sidecar, build it
// through the public runtime API (build_pyramid_file, what pyramid-build runs), decode every level
// with RegionDecoder, and measure the finest level against the input in metres.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "build/pyramid_build.h"
#include "io/io_test_util.h"
#include "readers/heightmap.h"
#include "runtime/region_decoder.h"

namespace stress {

using namespace terrain;
using namespace terrain::runtime;
using namespace terrain::container;
using namespace terrain::build;

inline Heightmap make_grid(int64_t w, int64_t h, SampleType type, double fill = 0) {
  Heightmap m;
  m.info.width = w;
  m.info.height = h;
  m.info.sample_type = type;
  m.info.format = FileFormat::Raw;
  m.values.assign(size_t(w * h), fill);
  return m;
}

struct Outcome {
  double rms = 0, max_err = 0;      // finest level against the input, metres, valid samples
  int64_t non_finite_valid = 0;     // valid samples that decoded to NaN/Inf (must be 0)
  int64_t finite_void = 0;          // void samples that did not decode to NaN (must be 0)
  int64_t coarse_out_of_range = 0;  // coarse-level samples outside [zmin - 4R - s, zmax + 4R + s]
                                    // (R = the input's range, s = the quantiser step in metres)
  int levels = 0;
  double bits_per_sample = 0;
  std::vector<double> finest;  // decoded finest level in metres (NaN at voids)
};

inline BuildFileOptions target(ErrorMode t, double metres = 0) {
  BuildFileOptions o;
  o.mode = t;
  o.target_metres = metres;
  return o;
}

// Builds `pyr` from `input` and decodes every level whole. The input is read back with the same
// reader the builder uses, so the comparison is against exactly what the builder saw.
inline Outcome build_and_measure(const std::string& input, const std::string& pyr,
                                 const BuildFileOptions& options, const ReadOptions& read_options = {}) {
  const Heightmap map = read_heightmap(input, read_options);
  const BuildFileResult built = build_pyramid_file(input, read_options, pyr, options);
  auto file = PyramidFile::open(pyr);
  RegionDecoder decoder(file);
  Outcome out;
  out.levels = file->level_count();
  out.bits_per_sample = 8.0 * double(built.file_bytes) / double(map.width() * map.height());
  double zmin = std::numeric_limits<double>::infinity(), zmax = -zmin;
  for (int64_t y = 0; y < map.height(); ++y)
    for (int64_t x = 0; x < map.width(); ++x)
      if (map.is_valid(x, y))
        zmin = std::min(zmin, map.metres(x, y)), zmax = std::max(zmax, map.metres(x, y));
  const double range = zmax - zmin;
  const double slack = 4 * range + built.step_units * built.metres_per_unit;
  for (int level = 0; level + 1 < out.levels; ++level) {
    const GridSize g = file->level_size(level);
    std::vector<int32_t> units(size_t(g.width * g.height));
    decoder.decode_units(level, Rect{0, 0, g.width, g.height}, units.data(), g.width);
    for (int32_t u : units) {
      const double m = u * decoder.metres_per_unit() + decoder.metres_offset();
      if (!(m >= zmin - slack && m <= zmax + slack)) ++out.coarse_out_of_range;
    }
  }
  const int64_t w = map.width(), h = map.height();
  std::vector<int32_t> units(size_t(w * h));
  std::vector<float> metres(size_t(w * h));
  decoder.decode_units(out.levels - 1, Rect{0, 0, w, h}, units.data(), w);
  decoder.decode_metres(out.levels - 1, Rect{0, 0, w, h}, metres.data(), w);
  out.finest.resize(size_t(w * h));
  double sq = 0;
  int64_t n = 0;
  for (int64_t y = 0; y < h; ++y)
    for (int64_t x = 0; x < w; ++x) {
      const size_t i = size_t(y * w + x);
      if (!map.is_valid(x, y)) {
        if (!std::isnan(metres[i])) ++out.finite_void;
        out.finest[i] = std::numeric_limits<double>::quiet_NaN();
        continue;
      }
      const double got = units[i] * decoder.metres_per_unit() + decoder.metres_offset();
      out.finest[i] = got;
      if (!std::isfinite(got) || !std::isfinite(metres[i])) ++out.non_finite_valid;
      const double e = got - map.metres(x, y);
      sq += e * e;
      out.max_err = std::max(out.max_err, std::abs(e));
      ++n;
    }
  out.rms = std::sqrt(sq / double(std::max<int64_t>(n, 1)));
  return out;
}

// The checks every case shares: nothing non-finite, voids stay voids, coarse levels bounded.
#define STRESS_CHECK_SANE(o)             \
  do {                                   \
    CHECK((o).non_finite_valid == 0);    \
    CHECK((o).finite_void == 0);         \
    CHECK((o).coarse_out_of_range == 0); \
  } while (0)

}  // namespace stress
