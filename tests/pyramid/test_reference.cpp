// reference_levels (the D cascade alone) against what the closed-loop builder codes.
#include <unistd.h>

#include <catch2/catch.hpp>
#include <filesystem>
#include <random>

#include "pyramid/reference.h"
#include "shared_data.h"

using namespace terrain;

namespace {

BuildOptions reference_options(int levels) {
  BuildOptions o;
  o.level_count = levels;
  return o;
}

// A lossless build reconstructs T_l exactly, except at voids (there it gives its prediction U(T^_{m-1})
// where the reference holds the push-pull fill). Returns the number of voids.
int64_t require_reference_is_lossless_build(const Heightmap& map, const BuildOptions& o) {
  UniformQuantizerCoder lossless(1);
  MemoryPyramid built;
  const BuildResult result = build_pyramid(map, o, lossless, built);
  const ReferenceLevels ref = reference_levels(map, o);
  REQUIRE(ref.sizes == result.header.levels);
  REQUIRE(ref.filter.taps == result.header.filter.taps);
  REQUIRE(ref.levels.size() == built.recon.size());
  const size_t m = ref.levels.size() - 1;
  for (size_t l = 0; l < m; ++l) {
    INFO("level " << l);
    REQUIRE(ref.levels[l] == built.recon[l]);
  }
  std::vector<uint8_t> valid;
  REQUIRE(ref.levels[m] == to_level_grid(map, o, &valid));
  int64_t differ = 0, voids = 0;
  for (size_t i = 0; i < valid.size(); ++i) {
    voids += !valid[i];
    differ += valid[i] && ref.levels[m][i] != built.recon[m][i];
  }
  CHECK(differ == 0);
  return voids;
}

Heightmap rough_grid(int64_t w, int64_t h) {
  Heightmap m;
  m.info.width = w, m.info.height = h;
  m.info.sample_type = SampleType::Int16;
  m.values.resize(size_t(w * h));
  std::mt19937 rng(7);
  for (int64_t y = 0; y < h; ++y)
    for (int64_t x = 0; x < w; ++x)
      m.values[size_t(y * w + x)] =
          std::round(800 * std::sin(0.021 * double(x)) * std::cos(0.017 * double(y)) +
                     40 * std::sin(0.3 * x) + double(rng() % 9) + 1000);
  return m;
}

}  // namespace

TEST_CASE("reference_levels: a fixed filter gives the lossless build's levels") {
  Heightmap map = rough_grid(301, 190);
  map.valid.assign(map.values.size(), 1);
  for (int64_t y = 40; y < 70; ++y)
    for (int64_t x = 100; x < 160; ++x)
      map.valid[size_t(y * 301 + x)] = 0, map.values[size_t(y * 301 + x)] = -32768;
  for (const DownsampleFilter& f : {DownsampleFilter::default_filter(), DownsampleFilter::box2x2()}) {
    BuildOptions o = reference_options(4);
    o.use_fixed_filter = true;
    o.fixed_filter = f;
    o.value_scale = 2;  // the level grid is scaled as the builder scales it
    CHECK(require_reference_is_lossless_build(map, o) == 30 * 60);
  }
}

TEST_CASE("reference_levels: the fitted filter is the builder's (top fit_rows rows)") {
  const Heightmap map = rough_grid(257, 300);
  BuildOptions o = reference_options(0);
  o.min_coarsest_side = 16;
  o.fit_rows = 160;  // fewer than the grid's rows: the fit must see only those
  o.threads = 1;
  CHECK(require_reference_is_lossless_build(map, o) == 0);
}

TEST_CASE("reference_levels: real DEMs with voids equal the lossless build") {
  for (const char* name :
       {"srtm3_N44E033_crimea_coast_mountains.hgt", "srtm3_N52E013_berlin_flat_plain.hgt"}) {
    const std::string path = testdata::require(name);
    if (path.empty()) continue;
    INFO(name);
    const Heightmap map = read_heightmap(path);
    CHECK(require_reference_is_lossless_build(map, reference_options(0)) > 0);
  }
}
