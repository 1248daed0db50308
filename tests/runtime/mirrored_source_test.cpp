// The mirrored virtual terrain (the trillion-sample test's source): its levels are the stored
// pyramid's reflected, its computed coarser levels D of the reflected tiling, and its memory does
// not grow with the virtual size.
#include "runtime/mirrored_source.h"

#include <catch2/catch.hpp>
#include <cmath>
#include <random>

#include "pyramid/levels.h"

using namespace terrain;
using namespace terrain::runtime;

namespace {

// A stored pyramid of 65^2, 33^2, 17^2 (every level lines up under reflection) with distinct values.
GridHeightSource stored_pyramid() {
  std::vector<GridSize> sizes{{17, 17}, {33, 33}, {65, 65}};
  std::vector<std::vector<float>> levels;
  for (size_t l = 0; l < sizes.size(); ++l) {
    std::vector<float> z(size_t(sizes[l].width * sizes[l].height));
    for (size_t i = 0; i < z.size(); ++i) z[i] = float(l * 10000 + i % 977) + 0.25f * float(i % 7);
    levels.push_back(std::move(z));
  }
  return GridHeightSource(sizes, std::move(levels), 30.0);
}

float sample(HeightSource& s, int level, int64_t x, int64_t y) {
  float v = 0;
  s.fill(level, Rect{x, y, 1, 1}, &v, 1);
  return v;
}

}  // namespace

TEST_CASE("mirrored source: stored levels reflected, computed levels D of the tiling", "[mirror]") {
  GridHeightSource base = stored_pyramid();
  const DownsampleFilter d = DownsampleFilter::default_filter();
  MirroredSource big(base, GridSize{1 << 20, 1 << 20}, d);
  const int V = big.level_count();
  CHECK(V == int(pyramid_level_sizes(GridSize{1 << 20, 1 << 20}, 0, 128).size()));
  CHECK(big.level_size(V - 1).width == (1 << 20));
  CHECK(big.spacing_m() == 30.0);
  std::mt19937_64 rng(5);
  for (int k = 0; k < 3; ++k) {  // the three stored levels, at the finest end of the virtual pyramid
    const int v = V - 1 - k, s = 2 - k;
    REQUIRE(big.base_level(v) == s);
    const GridSize bs = base.level_size(s), vs = big.level_size(v);
    std::uniform_int_distribution<int64_t> px(0, vs.width - 1);
    for (int i = 0; i < 200; ++i) {
      const int64_t x = px(rng), y = px(rng);
      const float want = base.level(
          s)[size_t(MirroredSource::reflect(y, bs.height) * bs.width + MirroredSource::reflect(x, bs.width))];
      REQUIRE(sample(big, v, x, y) == want);
    }
  }
  // Reflection: no repeated edge sample (x = 64 is the axis of the finest level's first mirror).
  CHECK(sample(big, V - 1, 65, 3) == base.level(2)[3 * 65 + 63]);
  CHECK(sample(big, V - 1, 128, 3) == base.level(2)[3 * 65 + 0]);
  // The computed levels: D (radius 5) of the next finer virtual level at (2i, 2j), periodic.
  for (int v = V - 4; v >= V - 6; --v) {
    REQUIRE(big.base_level(v) == -1);
    for (int i = 0; i < 6; ++i) {
      const int64_t x = 1000 + 37 * i, y = 2000 - 11 * i;
      std::vector<float> fine(121);
      big.fill(v + 1, Rect{2 * x - 5, 2 * y - 5, 11, 11}, fine.data(), 11);
      double want = 0;
      for (int dy = -5; dy <= 5; ++dy)
        for (int dx = -5; dx <= 5; ++dx) want += d.tap(dx, dy) * fine[size_t((dy + 5) * 11 + dx + 5)];
      CHECK(sample(big, v, x, y) == Approx(want).margin(1e-3));
    }
  }
  // A window fill equals the samples one by one, across many periods and beyond the virtual edge.
  for (int v : {V - 1, V - 5}) {
    const GridSize vs = big.level_size(v);
    const Rect r{vs.width - 150, 7, 170, 3};
    std::vector<float> w(size_t(r.width * r.height));
    big.fill(v, r, w.data(), r.width);
    for (int64_t y = 0; y < r.height; ++y)
      for (int64_t x = 0; x < r.width; ++x)
        REQUIRE(w[size_t(y * r.width + x)] ==
                sample(big, v, std::min(r.x0 + x, vs.width - 1), std::min(r.y0 + y, vs.height - 1)));
  }
}

TEST_CASE("mirrored source: memory does not depend on the virtual size", "[mirror]") {
  GridHeightSource base = stored_pyramid();
  const DownsampleFilter d = DownsampleFilter::default_filter();
  MirroredSource small(base, GridSize{1 << 12, 1 << 12}, d), big(base, GridSize{1 << 20, 1 << 20}, d);
  CHECK(big.level_count() == small.level_count() + 8);
  // The same fills through both; the big one holds a few more (tiny, period-sized) computed levels.
  std::vector<float> out(size_t(255 * 255));
  for (MirroredSource* s : {&small, &big})
    for (int l = 0; l < s->level_count(); ++l) s->fill(l, Rect{100, 100, 255, 255}, out.data(), 255);
  CHECK(big.memory_bytes() < small.memory_bytes() + 8 * 1024);
  CHECK(big.memory_bytes() < size_t(1) << 20);  // vs 4 TiB for the virtual finest level in floats
  CHECK_THROWS_AS(MirroredSource(base, GridSize{64, 65}, d), std::invalid_argument);
}
