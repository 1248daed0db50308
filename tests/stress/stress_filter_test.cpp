// The least-squares D filter on degenerate data (issue 7 stress suite). Bound: the fit never
// returns non-finite taps, the taps always sum to 1 (DC gain), no tap exceeds the documented
// max_abs_tap, degenerate inputs fall back to the default filter with a reason, and the
// prediction rms of whatever filter comes back is finite.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "pyramid/pyramid.h"

using namespace terrain;

namespace {

struct Fit {
  DownsampleFilter filter;
  FilterFitReport report;
};

Fit fit(const std::vector<int32_t>& grid, GridSize g) {
  Fit f;
  f.filter = fit_optimal_filter(grid.data(), g, FilterFitOptions{}, &f.report);
  return f;
}

void check_sane(const Fit& f, const std::vector<int32_t>& grid, GridSize g) {
  INFO(f.report.summary());
  for (double t : f.filter.taps) CHECK(std::isfinite(t));
  CHECK(std::abs(f.filter.sum() - 1.0) < 1e-9);
  for (double t : f.filter.taps) CHECK(std::abs(t) <= FilterFitOptions{}.max_abs_tap);
  CHECK(std::isfinite(prediction_rms(f.filter, grid.data(), g)));
  if (f.report.fallback) CHECK(!f.report.reason.empty());
}

std::vector<int32_t> grid_of(GridSize g, int32_t (*fn)(int64_t, int64_t)) {
  std::vector<int32_t> v(size_t(g.width * g.height));
  for (int64_t y = 0; y < g.height; ++y)
    for (int64_t x = 0; x < g.width; ++x) v[size_t(y * g.width + x)] = fn(x, y);
  return v;
}

}  // namespace

TEST_CASE("stress: D filter fit on degenerate data falls back or stays bounded", "[stress]") {
  const GridSize g{256, 256};
  SECTION("flat: falls back") {
    const auto v = grid_of(g, [](int64_t, int64_t) { return int32_t(500); });
    const Fit f = fit(v, g);
    check_sane(f, v, g);
    CHECK(f.report.fallback);
  }
  SECTION("single spike: falls back") {
    const auto v = grid_of(g, [](int64_t x, int64_t y) { return int32_t(x == 100 && y == 77 ? 8000 : 0); });
    const Fit f = fit(v, g);
    check_sane(f, v, g);
    CHECK(f.report.fallback);
  }
  SECTION("constant rows (varies in y only): falls back or stays bounded") {
    const auto v = grid_of(g, [](int64_t, int64_t y) { return int32_t(y * 37 % 1000); });
    check_sane(fit(v, g), v, g);
  }
  SECTION("exact plane (U reproduces it for any D with DC gain 1): bounded") {
    const auto v = grid_of(g, [](int64_t x, int64_t y) { return int32_t(3 * x - 2 * y); });
    check_sane(fit(v, g), v, g);
  }
  SECTION("checkerboard at the Nyquist frequency: bounded") {
    const auto v = grid_of(g, [](int64_t x, int64_t y) { return int32_t((x + y) & 1 ? 1000 : -1000); });
    check_sane(fit(v, g), v, g);
  }
  SECTION("full int16 swing noise: bounded") {
    const auto v = grid_of(g, [](int64_t x, int64_t y) {
      return int32_t(((uint64_t(x) * 2654435761u + uint64_t(y) * 40503u) >> 7) % 65536) - 32768;
    });
    check_sane(fit(v, g), v, g);
  }
  SECTION("too small (below the fit window): falls back") {
    const GridSize s{20, 20};
    const auto v = grid_of(s, [](int64_t x, int64_t y) { return int32_t(x * y); });
    const Fit f = fit(v, s);
    check_sane(f, v, s);
    CHECK(f.report.fallback);
  }
  SECTION("tiny grids 1x1..5x5 downsample without overflow") {
    for (int64_t n = 1; n <= 5; ++n) {
      const GridSize s{n, n};
      std::vector<int32_t> v(size_t(n * n), 2147483000);
      std::vector<int32_t> c(size_t(coarse_extent(n) * coarse_extent(n)));
      downsample(DownsampleFilter::default_filter(), v.data(), s, c.data());
      for (int32_t x : c) CHECK(x == 2147483000);
    }
  }
}
