// U (four-point subdivision) and D (11x11 downsampling, least-squares optimal fit).
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <iostream>
#include <map>
#include <random>

#include "pyramid/internal/filter_downsample.h"
#include "pyramid/pyramid.h"
#include "shared_data.h"

using namespace terrain;

namespace {

std::vector<int32_t> random_grid(GridSize s, int seed, int lo = -1000, int hi = 1000) {
  std::mt19937 rng(static_cast<uint32_t>(seed));
  std::uniform_int_distribution<int> d(lo, hi);
  std::vector<int32_t> g(size_t(s.width * s.height));
  for (auto& v : g) v = d(rng);
  return g;
}

std::vector<int32_t> upsampled(const std::vector<int32_t>& coarse, GridSize fine) {
  std::vector<int32_t> out(size_t(fine.width * fine.height));
  upsample(coarse.data(), fine, out.data());
  return out;
}

// A smooth deterministic test terrain (sum of sines), integer metres.
std::vector<int32_t> smooth_terrain(GridSize s, double amplitude = 800) {
  std::vector<int32_t> g(size_t(s.width * s.height));
  for (int64_t y = 0; y < s.height; ++y)
    for (int64_t x = 0; x < s.width; ++x)
      g[size_t(y * s.width + x)] = int32_t(std::lround(amplitude * (std::sin(x * 0.05) * std::cos(y * 0.041) +
                                                                    0.3 * std::sin(x * 0.23 + y * 0.17) +
                                                                    0.1 * std::cos(x * 0.71 - y * 0.53))));
  return g;
}

// A random non-empty rectangle inside a level.
Rect random_rect(GridSize level, std::mt19937& rng) {
  std::uniform_int_distribution<int64_t> dx(0, level.width - 1), dy(0, level.height - 1);
  Rect r;
  r.x0 = dx(rng), r.y0 = dy(rng);
  r.width = std::uniform_int_distribution<int64_t>(1, level.width - r.x0)(rng);
  r.height = std::uniform_int_distribution<int64_t>(1, level.height - r.y0)(rng);
  return r;
}

// Just the window's samples, so that reading outside it would be caught by ASan.
std::vector<int32_t> window_copy(const std::vector<int32_t>& c, GridSize cs, const Rect& window) {
  std::vector<int32_t> win(size_t(window.width * window.height));
  for (int64_t y = 0; y < window.height; ++y)
    for (int64_t x = 0; x < window.width; ++x)
      win[size_t(y * window.width + x)] = c[size_t((window.y0 + y) * cs.width + window.x0 + x)];
  return win;
}

// Coefficients (coarse index -> weight) of the value at extended coarse index e of a level of n
// samples: constant for n == 1, else point reflection about the edge sample, applied again when
// the reflected index is itself outside (n == 2, e == n + 1).
std::map<int64_t, int64_t> extended_value(int64_t e, int64_t n) {
  if (n == 1) return {{0, 1}};
  if (e >= 0 && e < n) return {{e, 1}};
  const int64_t edge = e < 0 ? 0 : n - 1;
  std::map<int64_t, int64_t> v{{edge, 2}};
  for (auto [index, weight] : extended_value(2 * edge - e, n)) v[index] -= weight;
  return v;
}

// 16 x the weights of fine sample x along one axis.
std::map<int64_t, int64_t> axis_weights(int64_t x, int64_t n) {
  const int64_t i = x / 2;
  std::map<int64_t, int64_t> w;
  auto add = [&](int64_t e, int64_t scale) {
    for (auto [index, weight] : extended_value(e, n)) w[index] += scale * weight;
  };
  if (x % 2 == 0) {
    add(i, 16);
  } else {
    add(i - 1, -1), add(i, 9), add(i + 1, 9), add(i + 2, -1);
  }
  return w;
}

// U at fine (x, y): the 256-scaled sum rounded half up once, saturated to int32.
int32_t direct_u(const std::vector<int32_t>& c, GridSize cs, int64_t x, int64_t y) {
  int64_t s = 0;
  for (auto [cy, wy] : axis_weights(y, cs.height))
    for (auto [cx, wx] : axis_weights(x, cs.width)) s += wx * wy * int64_t(c[size_t(cy * cs.width + cx)]);
  const int64_t v = (s + 128) >> 8;
  return int32_t(std::clamp<int64_t>(v, INT32_MIN, INT32_MAX));
}

}  // namespace

TEST_CASE("level extents: coarse = ceil(fine/2), grid-registered") {
  CHECK(coarse_extent(1201) == 601);
  CHECK(coarse_extent(601) == 301);
  CHECK(coarse_extent(301) == 151);
  CHECK(coarse_extent(1025) == 513);
  CHECK(coarse_extent(513) == 257);
  CHECK(coarse_extent(1) == 1);
  CHECK(coarse_extent(2) == 1);
  auto sizes = pyramid_level_sizes({1201, 1201}, 0);
  REQUIRE(sizes.size() == 4);  // 151 601 ... next would be 76 < 128
  CHECK(sizes.front() == GridSize{151, 151});
  CHECK(sizes.back() == GridSize{1201, 1201});
  auto forced = pyramid_level_sizes({7, 3}, 10);
  CHECK(forced.front() == GridSize{1, 1});  // capped where 1x1 is reached
  CHECK(forced.size() == 4);                // 7x3 4x2 2x1 1x1
  CHECK(pyramid_level_sizes({5, 5}, 0).size() == 1);
}

TEST_CASE("U copies even samples and interpolates odd ones, every size") {
  for (int64_t fw = 1; fw <= 12; ++fw)
    for (int64_t fh = 1; fh <= 12; ++fh) {
      GridSize fine{fw, fh}, cs{coarse_extent(fw), coarse_extent(fh)};
      auto c = random_grid(cs, int(fw * 100 + fh));
      auto f = upsampled(c, fine);
      for (int64_t j = 0; j < cs.height; ++j)
        for (int64_t i = 0; i < cs.width; ++i)
          REQUIRE(f[size_t(2 * j * fw + 2 * i)] == c[size_t(j * cs.width + i)]);
    }
}

TEST_CASE("U boundary rule: point reflection keeps linear ramps exact, also beyond the last coarse sample") {
  // 1-D: coarse (0, 16) -> fine (0, 8, 16, 24): the 4th sample is extrapolated along the ramp.
  std::vector<int32_t> c{0, 16};
  auto f = upsampled(c, {4, 1});
  CHECK(f == std::vector<int32_t>{0, 8, 16, 24});
  for (int64_t fw : {5, 6, 9, 10, 31, 32})
    for (int64_t fh : {1, 3, 4, 7, 8}) {  // fh 2 has one coarse row: constant, see below
      GridSize fine{fw, fh}, cs{coarse_extent(fw), coarse_extent(fh)};
      std::vector<int32_t> ramp(size_t(cs.width * cs.height));
      for (int64_t j = 0; j < cs.height; ++j)
        for (int64_t i = 0; i < cs.width; ++i) ramp[size_t(j * cs.width + i)] = int32_t(6 * i - 10 * j + 3);
      auto out = upsampled(ramp, fine);
      for (int64_t y = 0; y < fh; ++y)
        for (int64_t x = 0; x < fw; ++x) REQUIRE(out[size_t(y * fw + x)] == 3 * x - 5 * y + 3);
    }
  // A single coarse sample extends as a constant.
  auto one = upsampled(std::vector<int32_t>{7}, {2, 2});
  CHECK(one == std::vector<int32_t>{7, 7, 7, 7});
}

TEST_CASE("U reproduces bicubic polynomials exactly in the interior") {
  const GridSize fine{41, 38};
  const GridSize cs{coarse_extent(fine.width), coarse_extent(fine.height)};
  auto poly = [](double x, double y) {
    return 0.002 * x * x * x - 0.05 * x * x * y + 0.3 * x * y - 0.001 * y * y * y +
           0.0004 * x * x * x * y * y + 7;
  };
  std::vector<double> c(size_t(cs.width * cs.height)), f(size_t(fine.width * fine.height));
  for (int64_t j = 0; j < cs.height; ++j)
    for (int64_t i = 0; i < cs.width; ++i) c[size_t(j * cs.width + i)] = poly(2.0 * i, 2.0 * j);
  upsample_real(c.data(), fine, f.data());
  // Odd samples read coarse i-1..i+2, so fine samples 3 or more from the edges see no extension.
  for (int64_t y = 3; y < fine.height - 4; ++y)
    for (int64_t x = 3; x < fine.width - 4; ++x)
      REQUIRE(f[size_t(y * fine.width + x)] == Approx(poly(double(x), double(y))).margin(1e-9));

  // Integer U on integer cubics is exact too (the four-point sum is divisible, so rounding is a no-op).
  std::vector<int32_t> ci(c.size());
  auto ipoly = [](int64_t x, int64_t y) {
    return int32_t(x * x * x - 3 * x * x * y + 5 * x * y * y - 2 * y * y * y);
  };
  for (int64_t j = 0; j < cs.height; ++j)
    for (int64_t i = 0; i < cs.width; ++i) ci[size_t(j * cs.width + i)] = ipoly(2 * i, 2 * j);
  auto fi = upsampled(ci, fine);
  for (int64_t y = 3; y < fine.height - 4; ++y)
    for (int64_t x = 3; x < fine.width - 4; ++x) REQUIRE(fi[size_t(y * fine.width + x)] == ipoly(x, y));
}

TEST_CASE("U rounds once, half up, in int64") {
  // Fine (3,3) reads coarse 0..3 on both axes (no extension); coarse (2,2) weighs 81/256 there.
  std::vector<int32_t> c(25, 0);
  c[12] = 128;  // 81 * 128 / 256 = 40.5 -> 41
  auto f = upsampled(c, {9, 9});
  CHECK(f[size_t(3 * 9 + 3)] == 41);
  c[12] = -128;  // -40.5 -> -40 (half up, not away from zero)
  f = upsampled(c, {9, 9});
  CHECK(f[size_t(3 * 9 + 3)] == -40);
  // Large values do not overflow: the 16-tap sum is taken in int64.
  std::vector<int32_t> big(9, 2000000000);
  f = upsampled(big, {5, 5});
  for (int32_t v : f) CHECK(v == 2000000000);
}

TEST_CASE("upsample_region matches whole-level U with only the required coarse window") {
  std::mt19937 rng(7);
  for (GridSize fine : {GridSize{37, 29}, GridSize{64, 64}, GridSize{2, 9}, GridSize{1, 1}, GridSize{6, 5}}) {
    GridSize cs{coarse_extent(fine.width), coarse_extent(fine.height)};
    auto c = random_grid(cs, int(fine.width));
    auto whole = upsampled(c, fine);
    UpsampleScratch scratch;
    for (int trial = 0; trial < 200; ++trial) {
      const Rect r = random_rect(fine, rng);
      Rect need = upsample_required_window(r, fine);
      REQUIRE(need.x0 >= 0);
      REQUIRE(need.x0 + need.width <= cs.width);
      std::vector<int32_t> win = window_copy(c, cs, need);
      CoarseWindow cw{win.data(), need.width, need, cs};
      std::vector<int32_t> out(size_t(r.width * r.height));
      upsample_region(cw, fine, r, out.data(), r.width, scratch);
      for (int64_t y = 0; y < r.height; ++y)
        for (int64_t x = 0; x < r.width; ++x)
          REQUIRE(out[size_t(y * r.width + x)] == whole[size_t((r.y0 + y) * fine.width + r.x0 + x)]);
    }
  }
}

TEST_CASE("upsample_region rejects a window that does not cover the rectangle") {
  GridSize fine{20, 20}, cs{10, 10};
  std::vector<int32_t> c(100, 0), out(400);
  UpsampleScratch scratch;
  CoarseWindow small{c.data(), 10, Rect{2, 2, 3, 3}, cs};
  CHECK_THROWS_AS(upsample_region(small, fine, Rect{0, 0, 20, 20}, out.data(), 20, scratch),
                  std::invalid_argument);
  CoarseWindow wrong_level{c.data(), 10, Rect{0, 0, 10, 10}, GridSize{11, 10}};
  CHECK_THROWS_AS(upsample_region(wrong_level, fine, Rect{0, 0, 20, 20}, out.data(), 20, scratch),
                  std::invalid_argument);
}

// The int32 fast path (taken when the coarse values are small enough) and the int64 path against a
// direct evaluation of the U formula, on values on both sides of the fast path's bound.
TEST_CASE("upsample_region equals the direct U formula on both sides of the int32 path's bound") {
  std::mt19937 rng(11);
  // 2^20 stays in the fast path for every rectangle, 5.3e6 only for interior ones, larger values
  // take the int64 path (2^31 - 1 also saturates near edges). 2e6 and 8e6 overflow int32 on the
  // sign patterns below, so a looser bound would fail here.
  const int32_t magnitudes[] = {1000,    1 << 20, 1108000, 1200000, 2000000,
                                5368000, 5400000, 8000000, 1 << 28, INT32_MAX};
  const GridSize levels[] = {{1, 1}, {2, 2}, {3, 4}, {5, 7}, {8, 8}, {9, 13}, {40, 33}, {131, 70}};
  for (GridSize fine : levels) {
    GridSize cs{coarse_extent(fine.width), coarse_extent(fine.height)};
    for (int32_t magnitude : magnitudes) {
      for (int pattern = 0; pattern < 3; ++pattern) {
        // Random values, half of them at the extremes; then the sign patterns that drive the stencils
        // to their largest sums: alternating signs (edges, 25a - 10b + c) and - + + - (interior, 20x).
        std::vector<int32_t> c(size_t(cs.width * cs.height));
        std::uniform_int_distribution<int32_t> any(-magnitude, magnitude);
        std::uniform_int_distribution<int> pick(0, 3);
        for (int64_t y = 0; y < cs.height; ++y) {
          for (int64_t x = 0; x < cs.width; ++x) {
            int32_t& v = c[size_t(y * cs.width + x)];
            if (pattern == 0) {
              int p = pick(rng);
              v = p == 0 ? magnitude : p == 1 ? -magnitude : any(rng);
            } else if (pattern == 1) {
              v = (x + y) % 2 == 0 ? magnitude : -magnitude;
            } else {
              auto inner = [](int64_t t) { return t % 4 == 1 || t % 4 == 2; };
              v = inner(x) == inner(y) ? magnitude : -magnitude;
            }
          }
        }
        UpsampleScratch scratch;
        for (int trial = 0; trial < 40; ++trial) {
          const Rect r = trial == 0 ? Rect{0, 0, fine.width, fine.height} : random_rect(fine, rng);
          const Rect need = upsample_required_window(r, fine);
          std::vector<int32_t> win = window_copy(c, cs, need);
          // Output rows wider than the rectangle: the stride is honoured and nothing beyond is written.
          const int64_t out_stride = r.width + 3;
          std::vector<int32_t> out(size_t(out_stride * r.height), 12345);
          upsample_region(CoarseWindow{win.data(), need.width, need, cs}, fine, r, out.data(), out_stride,
                          scratch);
          for (int64_t y = 0; y < r.height; ++y) {
            for (int64_t x = 0; x < r.width; ++x) {
              INFO("level " << fine.width << "x" << fine.height << " magnitude " << magnitude << " pattern "
                            << pattern << " at " << r.x0 + x << "," << r.y0 + y);
              REQUIRE(out[size_t(y * out_stride + x)] == direct_u(c, cs, r.x0 + x, r.y0 + y));
            }
            for (int64_t x = r.width; x < out_stride; ++x) REQUIRE(out[size_t(y * out_stride + x)] == 12345);
          }
        }
      }
    }
  }
}

TEST_CASE("D wavelet: separable, normalised, and the dual of U up to its two dropped taps") {
  const DownsampleFilter d = DownsampleFilter::wavelet();
  CHECK(d.kind == DownsampleFilter::Kind::Wavelet);
  CHECK(d.sum() == Approx(1.0).epsilon(1e-12));
  CHECK(d.symmetric8());
  const double c = std::sqrt(d.tap(0, 0));
  for (int dy = -5; dy <= 5; ++dy)
    for (int dx = -5; dx <= 5; ++dx) REQUIRE(d.tap(dx, dy) == Approx(d.tap(dx, 0) / c * d.tap(0, dy) / c));
  // U's 1-D kernel: a coarse impulse becomes 1 at fine 0, 9/16 at +-1, -1/16 at +-3. D applied to it
  // at fine 2j is delta(j) for the full 13-tap dual; without its +-6 taps (-1/512, which met U's 1 at
  // j = +-3) and renormalised by 514 / 512 it is 512 / 514 at j = 0, 1 / 514 at j = +-3, 0 elsewhere.
  const auto u = [](int k) {
    return k == 0 ? 1.0 : (k == 1 || k == -1) ? 9.0 / 16 : (k == 3 || k == -3) ? -1.0 / 16 : 0.0;
  };
  for (int j = -4; j <= 4; ++j) {
    double sum = 0;
    for (int k = -5; k <= 5; ++k) sum += d.tap(k, 0) / c * u(2 * j - k);
    CHECK(sum == Approx(j == 0 ? 512.0 / 514.0 : (j == 3 || j == -3) ? 1.0 / 514.0 : 0.0).margin(1e-12));
  }
  std::vector<int32_t> flat(33 * 20, -777), coarse(17 * 10);
  downsample(d, flat.data(), GridSize{33, 20}, coarse.data());
  for (int32_t v : coarse) REQUIRE(v == -777);
}

TEST_CASE("D basics: impulse subsamples, constants stay constant, filters are normalised") {
  for (GridSize s : {GridSize{1, 1}, GridSize{2, 3}, GridSize{7, 5}, GridSize{33, 20}}) {
    auto g = random_grid(s, 3);
    std::vector<int32_t> c(size_t(coarse_extent(s.width) * coarse_extent(s.height)));
    downsample(DownsampleFilter::impulse(), g.data(), s, c.data());
    for (int64_t j = 0; j < coarse_extent(s.height); ++j)
      for (int64_t i = 0; i < coarse_extent(s.width); ++i)
        REQUIRE(c[size_t(j * coarse_extent(s.width) + i)] == g[size_t(2 * j * s.width + 2 * i)]);
    std::vector<int32_t> flat(g.size(), 1234);
    downsample(DownsampleFilter::default_filter(), flat.data(), s, c.data());
    for (int32_t v : c) REQUIRE(v == 1234);
  }
  CHECK(DownsampleFilter::default_filter().sum() == Approx(1.0));
  CHECK(DownsampleFilter::default_filter().symmetric8());
  CHECK_FALSE(DownsampleFilter::box2x2().symmetric8());
  CHECK(DownsampleFilter::box2x2().sum() == Approx(1.0));
  int members = 0;
  for (auto& o : symmetric_orbits()) members += o.count;
  CHECK(members == 121);
}

TEST_CASE("D threads: bit-identical for 1 and 2 threads") {
  GridSize s{301, 257};
  auto g = smooth_terrain(s);
  std::array<double, 21> w{};
  for (size_t k = 0; k < w.size(); ++k) w[k] = 0.01 * double(k % 5) - 0.01;
  w[0] = 0;
  double rest = 0;
  for (size_t k = 1; k < w.size(); ++k) rest += symmetric_orbits()[k].count * w[k];
  w[0] = 1 - rest;
  auto f = DownsampleFilter::from_orbit_weights(w, DownsampleFilter::Kind::Custom);
  std::vector<int32_t> a(size_t(151 * 129)), b(a.size());
  downsample(f, g.data(), s, a.data(), 1);
  downsample(f, g.data(), s, b.data(), 2);
  CHECK(a == b);
}

TEST_CASE("optimal D beats the 2x2 box and plain subsampling on every shared DEM") {
  auto dems = testdata::all_dems();
  for (const auto& path : dems) {
    INFO(path);
    Heightmap map = read_heightmap(path);
    BuildOptions opt;
    if (!map.info.integer_valued()) opt.value_scale = 10;  // Terrain-RGB: 0.1 m steps
    std::vector<int32_t> grid = to_level_grid(map, opt);
    GridSize s{map.width(), map.height()};
    FilterFitReport report;
    DownsampleFilter d = fit_optimal_filter(grid.data(), s, FilterFitOptions{}, &report);
    const double opt_rms = prediction_rms(d, grid.data(), s, 2);
    const double box_rms = prediction_rms(DownsampleFilter::box2x2(), grid.data(), s, 2);
    const double imp_rms = prediction_rms(DownsampleFilter::impulse(), grid.data(), s, 2);
    std::cout << "[D fit] " << std::filesystem::path(path).filename().string()
              << "  rms |T-U(D(T))|: optimal " << opt_rms << ", box2x2 " << box_rms << ", impulse " << imp_rms
              << "  (" << report.summary() << ")\n";
    CHECK_FALSE(report.fallback);
    CHECK(d.sum() == Approx(1.0).margin(1e-12));
    CHECK(d.symmetric8());
    CHECK(opt_rms < box_rms);
    CHECK(opt_rms < imp_rms);
  }
}

TEST_CASE("degenerate D inputs fall back to the default filter without NaN") {
  auto check_fallback = [](const std::vector<int32_t>& g, GridSize s, const char* what) {
    INFO(what);
    FilterFitReport report;
    DownsampleFilter d = fit_optimal_filter(g.data(), s, FilterFitOptions{}, &report);
    CHECK(report.fallback);
    CHECK_FALSE(report.reason.empty());
    CHECK(d.kind == DownsampleFilter::Kind::Default);
    for (double t : d.taps) REQUIRE(std::isfinite(t));
    CHECK(d.sum() == Approx(1.0));
  };
  GridSize s{200, 150};
  check_fallback(std::vector<int32_t>(size_t(s.width * s.height), 500), s, "flat");
  std::vector<int32_t> spike(size_t(s.width * s.height), 0);
  spike[size_t(75 * s.width + 100)] = 3000;
  check_fallback(spike, s, "single spike");
  std::vector<int32_t> rows(size_t(s.width * s.height));
  for (int64_t y = 0; y < s.height; ++y)
    for (int64_t x = 0; x < s.width; ++x) rows[size_t(y * s.width + x)] = int32_t((y * 37) % 101);
  check_fallback(rows, s, "constant rows");
  GridSize tiny{10, 10};
  check_fallback(random_grid(tiny, 1), tiny, "tiny grid");
  check_fallback(std::vector<int32_t>{5}, GridSize{1, 1}, "1x1");

  // A well-posed input is not flagged.
  GridSize t{256, 256};
  FilterFitReport report;
  auto g = smooth_terrain(t);
  DownsampleFilter d = fit_optimal_filter(g.data(), t, FilterFitOptions{}, &report);
  CHECK_FALSE(report.fallback);
  CHECK(report.rank == 20);
  CHECK(std::isfinite(report.condition));
  CHECK(report.rms_optimal < report.rms_default);
  CHECK(report.rms_optimal < report.rms_impulse);
  CHECK(d.kind == DownsampleFilter::Kind::Optimal);
}

TEST_CASE("D's row rounding equals round_to_int32 on every kind of value") {
  // The vectorised path (every |x| < 2^30) and the fallback (a row with one value beyond) must both
  // give round_to_int32's result: halves either side of zero, the 2^30 and int32 limits, infinities,
  // NaN, and random values at every scale.
  std::vector<double> values = {0.0,
                                -0.0,
                                0.5,
                                -0.5,
                                1.5,
                                -1.5,
                                2.5,
                                -2.5,
                                0.49999999999999994,
                                -0.49999999999999994,
                                1073741823.5,
                                -1073741823.5,
                                1073741824.0,
                                -1073741824.0,
                                2147483646.5,
                                2147483647.5,
                                -2147483647.5,
                                -2147483648.5,
                                4e9,
                                -4e9,
                                1e300,
                                -1e300,
                                INFINITY,
                                -INFINITY,
                                NAN};
  std::mt19937_64 rng(11);
  for (int k = 0; k < 200000; ++k) {
    const double scale = std::ldexp(1.0, int(rng() % 34) - 3);
    const double x = (double(rng() >> 11) / 9007199254740992.0 - 0.5) * scale;
    values.push_back(x);
    values.push_back(std::floor(x) + 0.5);  // halves
  }
  const auto check = [](std::vector<double> row) {
    std::vector<double> expected(row.size());
    for (size_t i = 0; i < row.size(); ++i) expected[i] = double(detail::round_to_int32(row[i]));
    detail::round_row(row.data(), int64_t(row.size()));
    for (size_t i = 0; i < row.size(); ++i) REQUIRE(row[i] == expected[i]);
  };
  check(values);  // the fallback: the row holds values beyond 2^30
  std::vector<double> small;
  for (double v : values)
    if (std::fabs(v) < 1073741824.0) small.push_back(v);
  REQUIRE(small.size() > 300000);
  check(small);  // the vectorised path
}

TEST_CASE(
    "D engine: the integer-pair and fused-rounding paths give the double path's rows, extremes included") {
  // max_abs lets the wavelet D add symmetric pairs as int32; the doubles must not change. Rows at the
  // bound (int16's limits, 2^30 - 1; 2^30 itself takes the double path) and random ones.
  for (const int64_t bound : {int64_t(32768), (int64_t(1) << 30) - 1, int64_t(1) << 30})
    for (const GridSize fine : {GridSize{37, 29}, GridSize{130, 70}, GridSize{16, 16}}) {
      std::mt19937_64 rng(uint64_t(bound + fine.width));
      std::vector<int32_t> grid(size_t(fine.width * fine.height));
      for (size_t i = 0; i < grid.size(); ++i) {
        const int64_t r = int64_t(rng() % uint64_t(2 * bound + 1)) - bound;
        grid[i] = int32_t(i % 7 == 0 ? (i % 2 ? bound : -bound) : r);
      }
      const auto run = [&](int64_t max_abs, bool rounded) {
        detail::DownsampleEngine engine(DownsampleFilter::wavelet(), fine, 2, 4, rounded, max_abs);
        std::vector<double> out;
        const auto emit = [&](int64_t, int64_t n, const double* rows) {
          out.insert(out.end(), rows, rows + n * engine.coarse().width);
        };
        for (int64_t y = 0; y < fine.height; y += 5)
          engine.push_rows(grid.data() + y * fine.width, std::min<int64_t>(5, fine.height - y), emit);
        engine.finish(emit);
        return out;
      };
      INFO("bound " << bound << " grid " << fine.width << "x" << fine.height);
      // Rounded too: with int16-range samples the rows round inside the row taps (fused), else after.
      for (const bool rounded : {false, true}) {
        INFO("rounded " << rounded);
        const std::vector<double> plain = run(0, rounded), pairs = run(bound, rounded);
        REQUIRE(plain.size() == size_t(coarse_extent(fine.width) * coarse_extent(fine.height)));
        CHECK(std::memcmp(plain.data(), pairs.data(), plain.size() * sizeof(double)) == 0);
      }
    }
  CHECK(detail::DownsampleEngine::coarse_bound(DownsampleFilter::wavelet(), 32768) > 32768 * 2.6);
  CHECK(detail::DownsampleEngine::coarse_bound(DownsampleFilter::wavelet(), 0) == 0);
}
