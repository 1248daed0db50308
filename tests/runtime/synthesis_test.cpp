// Terrain synthesis beyond the stored resolution: the variance model, spatial determinism (any
// order and shape of fills, a clipmap moving away and back), the variance of the synthesised
// residuals, and watertight rendering where stored and synthesised levels meet.
#include "runtime/synthesis.h"

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <random>

#include "build/pyramid_build.h"
#include "io/io_test_util.h"
#include "readers/terrain_generator.h"
#include "render/leak_check.h"
#include "render/renderer.h"
#include "render_test_util.h"
#include "runtime/clipmap.h"
#include "runtime/region_decoder.h"

using namespace terrain;
using namespace terrain::runtime;
using namespace terrain::container;
using namespace terrain::build;
using namespace terrain::render;

namespace {

constexpr int kBaseLevels = 4;
constexpr double kBaseSpacing = 20.0;

// Smooth analytic base (metres), sampled at each level's points; bounded (edge repeat outside).
double base_m(double x, double y) {
  return 80.0 * std::sin(x * 0.0013) * std::cos(y * 0.0011) + 8.0 * std::sin(x * 0.007 + y * 0.005) +
         2.0 * std::cos(x * 0.031 - y * 0.023);
}

FunctionHeightSource base_source() {
  return FunctionHeightSource(
      kBaseLevels, GridSize{513, 385}, kBaseSpacing,
      [](int level, int64_t x, int64_t y) {
        const double s = std::ldexp(kBaseSpacing, kBaseLevels - 1 - level);
        return float(base_m(double(x) * s, double(y) * s));
      },
      false);
}

SynthesisOptions detail_options(int levels, double std0_m) {
  SynthesisOptions o;
  o.levels = levels;
  o.std_m = fractal_std(std0_m, 0.8, levels);
  o.seed = 42;
  return o;
}

// Variance (about the mean) and lag-1 correlations along x and y of a w x h grid.
struct Moments {
  double variance = 0, corr_x = 0, corr_y = 0;
};
Moments moments(const std::vector<double>& v, int64_t w, int64_t h) {
  double mean = 0;
  for (double a : v) mean += a;
  mean /= double(v.size());
  double var = 0, cx = 0, cy = 0;
  for (int64_t y = 0; y < h; ++y)
    for (int64_t x = 0; x < w; ++x) {
      const double a = v[size_t(y * w + x)] - mean;
      var += a * a;
      if (x + 1 < w) cx += a * (v[size_t(y * w + x + 1)] - mean);
      if (y + 1 < h) cy += a * (v[size_t((y + 1) * w + x)] - mean);
    }
  Moments m;
  m.variance = var / double(v.size());
  m.corr_x = cx / double((w - 1) * h) / m.variance;
  m.corr_y = cy / double(w * (h - 1)) / m.variance;
  return m;
}

// The synthesised residual R = T_level - U(T_level-1) on rect (metres), with libpyramid's U.
std::vector<double> synthesised_residual(SynthesisSource& s, int level, const Rect& rect) {
  std::vector<int32_t> fine(size_t(rect.width * rect.height)), predicted(fine.size());
  s.fill_quanta(level, rect, fine.data(), rect.width);
  const Rect need = upsample_required_window(rect, s.level_size(level));
  std::vector<int32_t> coarse(size_t(need.width * need.height));
  s.fill_quanta(level - 1, need, coarse.data(), need.width);
  UpsampleScratch scratch;
  upsample_region(CoarseWindow{coarse.data(), need.width, need, s.level_size(level - 1)}, s.level_size(level),
                  rect, predicted.data(), rect.width, scratch);
  std::vector<double> r(fine.size());
  for (size_t i = 0; i < r.size(); ++i) r[i] = double(int64_t(fine[i]) - predicted[i]) * s.quantum_m();
  return r;
}

// All stored heights of every level with data, as (level, x, y) -> z, for comparing clipmaps.
bool same_heights(const Clipmap& a, const Clipmap& b, std::string& why) {
  for (int l = 0; l < a.level_count(); ++l) {
    if (a.has_data(l) != b.has_data(l)) return why = "has_data of level " + std::to_string(l), false;
    if (!a.has_data(l)) continue;
    if (!(a.clip_region(l) == b.clip_region(l)))
      return why = "clip region of level " + std::to_string(l), false;
    const Rect c = a.clip_region(l);
    for (int64_t y = c.y0; y < c.y0 + a.n(); ++y)
      for (int64_t x = c.x0; x < c.x0 + a.n(); ++x)
        if (a.heights(l)[a.index(x, y)] != b.heights(l)[b.index(x, y)] ||
            a.coarse_heights(l)[a.index(x, y)] != b.coarse_heights(l)[b.index(x, y)])
          return why = "level " + std::to_string(l) + " at " + std::to_string(x) + "," + std::to_string(y),
                 false;
  }
  return true;
}

}  // namespace

TEST_CASE("synthesis: the residual variance is extrapolated along the stored levels' power law",
          "[synthesis]") {
  // Exact power law 2^(10 - 1.4 l) m^2 on levels 1..6 (level 0 is the terrain itself: ignored).
  std::vector<double> v{1e6};
  for (int l = 1; l <= 6; ++l) v.push_back(std::exp2(10.0 - 1.4 * l));
  ResidualFit fit;
  const std::vector<double> s = extrapolate_residual_std(v, 3, &fit);
  REQUIRE(s.size() == 3);
  CHECK(fit.levels_used == std::vector<int>{3, 4, 5, 6});
  CHECK(fit.slope == Approx(-1.4));
  CHECK_FALSE(fit.clamped);
  for (int k = 0; k < 3; ++k) CHECK(s[size_t(k)] == Approx(std::sqrt(std::exp2(10.0 - 1.4 * (7 + k)))));

  // A level whose variance grows finer (noise-dominated data) is clamped to the slowest decay.
  const std::vector<double> rising{1e6, 1.0, 2.0, 4.0};
  extrapolate_residual_std(rising, 2, &fit);
  CHECK(fit.clamped);
  CHECK(fit.slope == ResidualFit::kMaxSlope);
  // One usable level: the default slope through it; none: no detail.
  const std::vector<double> one = extrapolate_residual_std({1e6, 0.0, 9.0}, 2, &fit);
  CHECK(fit.slope == ResidualFit::kDefaultSlope);
  CHECK(one[0] == Approx(std::sqrt(9.0 * std::exp2(ResidualFit::kDefaultSlope))));
  CHECK(extrapolate_residual_std({1e6, 0.0}, 2) == std::vector<double>{0.0, 0.0});
}

TEST_CASE("synthesis: bad options are refused", "[synthesis]") {
  auto base = base_source();
  SynthesisOptions o = detail_options(2, 1.0);
  o.levels = 0;
  CHECK_THROWS_AS(SynthesisSource(base, o), std::invalid_argument);
  o = detail_options(2, 1.0);
  o.std_m.pop_back();
  CHECK_THROWS_AS(SynthesisSource(base, o), std::invalid_argument);
  o = detail_options(2, 1.0);
  o.std_m[0] = std::nan("");
  CHECK_THROWS_AS(SynthesisSource(base, o), std::invalid_argument);
  o = detail_options(2, 1.0);
  o.quantum_m = 0;
  CHECK_THROWS_AS(SynthesisSource(base, o), std::invalid_argument);
  o = detail_options(2, 1.0);
  o.table_log2 = 12;
  CHECK_THROWS_AS(SynthesisSource(base, o), std::invalid_argument);
}

TEST_CASE("synthesis: levels, sizes and spacing extend the base", "[synthesis]") {
  auto base = base_source();
  SynthesisSource s(base, detail_options(3, 1.0));
  REQUIRE(s.level_count() == kBaseLevels + 3);
  CHECK(s.spacing_m() == kBaseSpacing / 8);
  for (int l = 1; l < s.level_count(); ++l) {
    const GridSize f = s.level_size(l), c = s.level_size(l - 1);
    CHECK(coarse_extent(f.width) == c.width);
    CHECK(coarse_extent(f.height) == c.height);
  }
  CHECK(s.level_size(kBaseLevels + 2) == GridSize{4097, 3073});
  // Stored levels pass through unchanged.
  std::vector<float> a(40 * 30), b(a.size());
  s.fill(kBaseLevels - 1, Rect{100, 50, 40, 30}, a.data(), 40);
  base.fill(kBaseLevels - 1, Rect{100, 50, 40, 30}, b.data(), 40);
  CHECK(a == b);
}

TEST_CASE("synthesis: the same position gives the same height whatever the fills", "[synthesis]") {
  auto base = base_source();
  const int finest = kBaseLevels + 2;
  for (int level = kBaseLevels; level <= finest; ++level) {
    SynthesisSource whole(base, detail_options(3, 1.5));
    const GridSize size = whole.level_size(level);
    // A reference window reaching past the level's top-left corner (edge repeat outside).
    const Rect ref{-20, -16, 300, 260};
    std::vector<float> expected(size_t(ref.width * ref.height));
    whole.fill(level, ref, expected.data(), ref.width);
    // A fresh source filled piecewise: random rectangles in random order, other levels in between.
    SynthesisSource pieces(base, detail_options(3, 1.5));
    std::mt19937 rng{uint32_t(level)};
    std::vector<float> got(expected.size(), std::nanf(""));
    std::vector<float> tmp;
    for (int i = 0; i < 60; ++i) {
      const int64_t w = 1 + rng() % 90, h = 1 + rng() % 70;
      const int64_t x0 = ref.x0 + int64_t(rng() % uint32_t(ref.width - w + 1));
      const int64_t y0 = ref.y0 + int64_t(rng() % uint32_t(ref.height - h + 1));
      tmp.resize(size_t(w * h));
      pieces.fill(level, Rect{x0, y0, w, h}, tmp.data(), w);
      for (int64_t y = 0; y < h; ++y)
        for (int64_t x = 0; x < w; ++x)
          got[size_t((y0 - ref.y0 + y) * ref.width + (x0 - ref.x0 + x))] = tmp[size_t(y * w + x)];
      const int other = kBaseLevels - 1 + int(rng() % 4);  // disturb any caches and scratch
      pieces.fill(other, Rect{int64_t(rng() % 200), int64_t(rng() % 200), 33, 17}, tmp.data(), 33);
    }
    int64_t compared = 0, differing = 0;
    for (size_t i = 0; i < got.size(); ++i)
      if (!std::isnan(got[i])) ++compared, differing += got[i] != expected[i];
    INFO("level " << level << " (" << size.width << "x" << size.height << ")");
    CHECK(compared > int64_t(got.size() / 2));
    CHECK(differing == 0);
    // Outside the level the edge repeats.
    CHECK(expected[0] == expected[size_t(16 * ref.width + 20)]);
  }
}

TEST_CASE("synthesis: a clipmap over synthesised levels gives the same heights after moving away and back",
          "[synthesis]") {
  auto base = base_source();
  SynthesisSource a_src(base, detail_options(3, 1.5)), b_src(base, detail_options(3, 1.5));
  ClipmapOptions o;
  o.n = 63;
  o.deactivate_by_height = false;
  o.budget = 1 << 30;
  Clipmap a(a_src, o), b(b_src, o);
  REQUIRE(a.level_count() == kBaseLevels + 3);
  const double hx = 3000.0, hy = 2500.0;
  // a flies away (in uneven, budget-limited steps that fill odd L-shaped pieces) and back; b jumps
  // straight to the end point.
  a.set_budget(1500);
  for (int i = 0; i <= 40; ++i) a.update(hx + 37.3 * i, hy + 11.9 * i * (i % 3), 300.0);
  for (int i = 40; i >= 0; --i) a.update(hx + 41.7 * i, hy - 9.1 * i, 300.0);
  a.set_budget(1 << 30);
  ClipmapUpdateStats sa;
  for (int i = 0; i < 3; ++i) sa = a.update(hx, hy, 300.0);
  b.update(hx, hy, 300.0);
  CHECK(sa.levels_behind == 0);
  std::string why;
  CHECK(same_heights(a, b, why));
  INFO(why);
  // And the clipmap holds exactly the source's samples (synthesised levels included).
  for (int l = 0; l < b.level_count(); ++l) {
    const Rect c = b.clip_region(l);
    std::vector<float> z(size_t(c.width * c.height));
    a_src.fill(b.source_level(l), c, z.data(), c.width);
    int64_t bad = 0;
    for (int64_t y = 0; y < c.height; ++y)
      for (int64_t x = 0; x < c.width; ++x)
        bad += z[size_t(y * c.width + x)] != b.heights(l)[b.index(c.x0 + x, c.y0 + y)];
    INFO("level " << l);
    CHECK(bad == 0);
  }
}

TEST_CASE("synthesis: synthesised residuals have the target variance per level and are uncorrelated",
          "[synthesis]") {
  auto base = base_source();
  SynthesisSource s(base, detail_options(4, 2.0));
  for (int level = kBaseLevels; level < s.level_count(); ++level) {
    const Rect rect{37, 29, 400, 300};
    const std::vector<double> r = synthesised_residual(s, level, rect);
    const Moments m = moments(r, rect.width, rect.height);
    const double target = s.noise_std_m(level) * s.noise_std_m(level);
    INFO("level " << level << ": variance " << m.variance << " m^2, target " << target
                  << ", lag-1 correlation x " << m.corr_x << " y " << m.corr_y);
    CHECK(std::abs(m.variance / target - 1.0) < 0.10);
    CHECK(std::abs(m.corr_x) < 0.05);
    CHECK(std::abs(m.corr_y) < 0.05);
  }
  // Zero detail: U alone, the residual vanishes.
  SynthesisOptions zero = detail_options(2, 0.0);
  SynthesisSource z(base, zero);
  const std::vector<double> r = synthesised_residual(z, kBaseLevels + 1, Rect{5, 5, 64, 64});
  CHECK(*std::max_element(r.begin(), r.end()) == 0.0);
  CHECK(*std::min_element(r.begin(), r.end()) == 0.0);
}

TEST_CASE("synthesis: below a pyramid file the variance comes from its stored residual statistics",
          "[synthesis]") {
  iotest::TempDir dir;
  SynthOptions so;
  so.width = 300;
  so.height = 260;
  so.seed = 9;
  write_raw(dir.file("t.raw"), synthesize_terrain(so));
  BuildFileOptions bo;
  bo.mode = ErrorMode::Step;
  bo.target_metres = 2.0;
  bo.levels = 5;
  bo.threads = 1;
  build_pyramid_file(dir.file("t.raw"), ReadOptions{}, dir.file("t.pyr"), bo);
  auto file = PyramidFile::open(dir.file("t.pyr"));
  const std::vector<double> stored = stored_residual_variance_m2(*file);
  REQUIRE(stored.size() == 5);
  for (double v : stored) CHECK(v > 0);
  ResidualFit fit;
  const SynthesisOptions o = synthesis_options_for(*file, 3, 7, 1.0, &fit);
  INFO(fit.note << ", slope " << fit.slope << " (fitted " << fit.slope_fitted << ")");
  REQUIRE(o.std_m.size() == 3);
  // Each synthesised level continues the fitted line: successive variances fall by 2^slope, and the
  // first one is the line's value one level below the finest stored level.
  CHECK(o.std_m[0] * o.std_m[0] == Approx(std::exp2(fit.intercept + fit.slope * 5)));
  for (size_t k = 1; k < 3; ++k)
    CHECK(o.std_m[k] * o.std_m[k] / (o.std_m[k - 1] * o.std_m[k - 1]) == Approx(std::exp2(fit.slope)));

  RegionDecoderSource stored_source(std::make_shared<const RegionDecoder>(file), 30.0);
  SynthesisSource s(stored_source, o);
  for (int level = 5; level < 8; ++level) {
    const Rect rect{20, 20, 320, 256};
    const Moments m = moments(synthesised_residual(s, level, rect), rect.width, rect.height);
    const double target = o.std_m[size_t(level - 5)] * o.std_m[size_t(level - 5)];
    INFO("level " << level << ": variance " << m.variance << " m^2, target " << target);
    CHECK(std::abs(m.variance / target - 1.0) < 0.10);
  }
}

TEST_CASE("synthesis: the generator amplifies a coarse base deterministically from a seed", "[synthesis]") {
  FunctionHeightSource coarse(
      1, GridSize{17, 13}, 400.0,
      [](int, int64_t x, int64_t y) { return float(100.0 * std::sin(0.5 * x) + 20.0 * y); }, false);
  SynthesisOptions o;
  o.levels = 4;
  o.std_m = fractal_std(8.0, 0.9, 4);
  o.seed = 3;
  SynthesisSource a(coarse, o), b(coarse, o);
  std::vector<float> ta, tb;
  synthesize_level(a, 4, ta);
  synthesize_level(b, 4, tb);
  REQUIRE(ta.size() == size_t(257 * 193));
  CHECK(ta == tb);
  // The coarse base shows through: the finest level at the base's samples stays near them.
  double worst = 0;
  for (int64_t y = 0; y < 13; ++y)
    for (int64_t x = 0; x < 17; ++x) {
      float c = 0;
      coarse.fill(0, Rect{x, y, 1, 1}, &c, 1);
      worst = std::max(worst, std::abs(double(ta[size_t(y * 16 * 257 + x * 16)]) - c));
    }
  CHECK(worst < 6 * (8.0 + 8.0 * std::exp2(-0.9) + 8.0 * std::exp2(-1.8) + 8.0 * std::exp2(-2.7)));
  // Another seed, another terrain.
  o.seed = 4;
  SynthesisSource c(coarse, o);
  std::vector<float> tc;
  synthesize_level(c, 4, tc);
  CHECK(tc != ta);
}

TEST_CASE("render: rings stay watertight where stored and synthesised levels meet", "[render][synthesis]") {
  GlLeakCheckPause pause;
  auto base = base_source();
  SynthesisSource source(base, detail_options(2, 1.5));  // 4 stored + 2 synthesised levels
  ClipmapOptions o;
  o.n = 31;
  o.budget = 1 << 30;
  Clipmap clipmap(source, o);
  constexpr int kW = 320, kH = 240;
  ClipmapRenderer renderer((rendertest::gl(), 31), clipmap.level_count(), kW, kH);
  RenderOptions opt = rendertest::crack_check_options(), broken = rendertest::cracked_options();
  const int first_synthesised = kBaseLevels;  // clipmap level = source level here
  std::vector<uint8_t> pixels;
  int64_t broken_background = 0;
  int views_with_boundary = 0;
  for (int i = 0; i < 16; ++i) {
    const double x = 2400.0 + 83.3 * i, y = 1900.0 + 51.7 * i * (i % 3);
    // The top of the frame looks 0.15 rad below the horizon: over this terrain (range < 200 m)
    // every ray meets the ground within the coarsest level, so a background pixel is a crack.
    double above = 0;
    const Camera cam = rendertest::low_grazing_view(source, i, x, y, &above);
    clipmap.update(x, y, cam.position[2]);
    clipmap.update(x, y, cam.position[2]);
    REQUIRE(!clipmap.active_region(clipmap.level_count() - 1).empty());  // synthesised levels drawn
    // On flat ground the frame reaches (above / tan 0.15) ahead; the first synthesised level's
    // outer perimeter (its boundary with the finest stored level) lies within that.
    const LevelRegion a = clipmap.active_region(first_synthesised);
    const double half = 0.5 * double(a.x1 - a.x0) * clipmap.spacing(first_synthesised);
    views_with_boundary += above / std::tan(0.15) > 1.2 * half;
    renderer.upload(clipmap);
    renderer.render(clipmap, cam, opt);
    renderer.read_rgba(pixels);
    INFO("view " << i << " at (" << x << ", " << y << ")");
    CHECK(rendertest::background_pixels(pixels) == 0);
    renderer.render(clipmap, cam, broken);
    renderer.read_rgba(pixels);
    broken_background += rendertest::background_pixels(pixels);
  }
  CHECK(views_with_boundary == 16);
  CHECK(broken_background > 0);
}

TEST_CASE("synthesis: terrain-synth --detail-levels amplifies a coarser generator run", "[synthesis]") {
  iotest::TempDir dir;
  const std::vector<std::string> size{"--width", "70", "--height", "50", "--seed", "9", "-q"};
  auto call = [&](const std::string& out, std::vector<std::string> extra) {
    std::vector<std::string> args{"-o", dir.file(out)};
    args.insert(args.end(), size.begin(), size.end());
    args.insert(args.end(), extra.begin(), extra.end());
    return iotest::Invocation{"terrain-synth", args};
  };
  const auto results = iotest::run_tools(
      dir, {call("a.raw", {"--detail-levels", "2"}), call("b.raw", {"--detail-levels", "2"}),
            call("c.raw", {"--detail-levels", "2", "--detail-std", "-1"})});
  REQUIRE(results[0].status == 0);
  REQUIRE(results[1].status == 0);
  CHECK(iotest::read_file(dir.file("a.raw")) == iotest::read_file(dir.file("b.raw")));  // reproducible
  CHECK(results[2].status == 1);
  const Heightmap out = read_heightmap(dir.file("a.raw"));
  REQUIRE(out.width() == 70);
  REQUIRE(out.height() == 50);
  // The generator at 1/4 of the size (70 -> 35 -> 18, 50 -> 25 -> 13) shows through at every 4th
  // sample, within the added noise (default std 0.02 x 60 m, then 2^-0.8 of that; 6 sigma each).
  SynthOptions so;
  so.width = 18;
  so.height = 13;
  so.seed = 9;
  const Heightmap base = synthesize_terrain(so);
  const double bound = 6.0 * 1.2 * (1.0 + std::exp2(-0.8)) + 1.0;
  double worst = 0, moved = 0;
  for (int64_t y = 0; y < 13; ++y)
    for (int64_t x = 0; x < 18; ++x)
      if (4 * x < 70 && 4 * y < 50) {
        const double d = std::abs(out.metres(4 * x, 4 * y) - base.metres(x, y));
        worst = std::max(worst, d);
        moved += d;
      }
  CHECK(worst <= bound);
  CHECK(moved > 0);  // detail was added
}
