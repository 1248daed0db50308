// Geometry clipmap (CPU side): toroidal addressing, incremental update == fill from scratch,
// per-frame budget and cropping of the levels that fall behind, level switching by height.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <functional>
#include <random>
#include <stdexcept>
#include <string>

#include "runtime/clipmap.h"
#include "runtime/height_source.h"

using namespace terrain;
using namespace terrain::runtime;

namespace {

// Integer-valued, position-dependent heights (a different value at every sample of every level), so
// any addressing mistake shows up as a mismatch.
float hashed_height(int level, int64_t x, int64_t y) {
  uint64_t h = uint64_t(x) * 0x9E3779B97F4A7C15ull ^ uint64_t(y) * 0xC2B2AE3D27D4EB4Full ^
               uint64_t(level) * 0x165667B19E3779F9ull;
  h ^= h >> 29;
  h *= 0xBF58476D1CE4E5B9ull;
  h ^= h >> 32;
  return float(h % 2000) * 0.5f;
}

constexpr int kLevels = 6;

FunctionHeightSource hashed_source() {
  return FunctionHeightSource(kLevels, GridSize{1 << 12, 1 << 12}, 1.0, hashed_height, true);
}

// Options under which every update refills every level and none is switched off by height.
ClipmapOptions whole_updates(int n) {
  ClipmapOptions o;
  o.n = n;
  o.budget = 1 << 30;
  o.deactivate_by_height = false;
  return o;
}

bool same_level(const Clipmap& a, const Clipmap& b, int l, std::string& why) {
  const int n = a.n();
  if (a.has_data(l) != b.has_data(l)) return why = "has_data", false;
  if (!a.has_data(l)) return true;
  if (!(a.clip_region(l) == b.clip_region(l))) return why = "clip region", false;
  if (!(a.active_region(l) == b.active_region(l))) return why = "active region", false;
  const Rect c = a.clip_region(l);
  for (int64_t y = c.y0; y < c.y0 + n; ++y)
    for (int64_t x = c.x0; x < c.x0 + n; ++x) {
      const size_t i = a.index(x, y);
      if (a.heights(l)[i] != b.heights(l)[i]) return why = "z", false;
      if (a.coarse_heights(l)[i] != b.coarse_heights(l)[i]) return why = "zc", false;
      for (int64_t t = 0; t < 4; ++t) {  // the sample's four normal-map texels
        const size_t k = a.normal_index(2 * x + (t & 1), 2 * y + (t >> 1));
        if (a.normal_map(l)[2 * k] != b.normal_map(l)[2 * k] ||
            a.normal_map(l)[2 * k + 1] != b.normal_map(l)[2 * k + 1])
          return why = "normal map at sample " + std::to_string(x) + "," + std::to_string(y), false;
      }
    }
  for (int64_t y = c.y0; y < c.y0 + n; y += 5)
    for (int64_t x = c.x0; x < c.x0 + n; x += 7) {
      const LevelRegion r{x, y, x + 6, y + 4};
      const ZRange ra = a.z_bounds(l, r), rb = b.z_bounds(l, r);
      if (ra.lo != rb.lo || ra.hi != rb.hi) return why = "z bounds", false;
    }
  return true;
}

}  // namespace

TEST_CASE("clipmap: toroidal storage holds the source's samples at their level coordinates", "[clipmap]") {
  auto src = hashed_source();
  const ClipmapOptions o = whole_updates(31);
  Clipmap cm(src, o);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> step(-40.0, 40.0);
  double x = 5, y = -3;  // negative coordinates exercise the wrap of negative indices
  for (int frame = 0; frame < 60; ++frame) {
    x += step(rng);
    y += step(rng);
    cm.update(x, y, 1.0);
    for (int l = 0; l < cm.level_count(); ++l) {
      REQUIRE(cm.has_data(l));
      const Rect c = cm.clip_region(l);
      CHECK(c.x0 == cm.desired_region(l).x0);
      for (int64_t yy = c.y0; yy < c.y0 + c.height; ++yy)
        for (int64_t xx = c.x0; xx < c.x0 + c.width; ++xx) {
          REQUIRE(cm.heights(l)[cm.index(xx, yy)] == hashed_height(cm.source_level(l), xx, yy));
          // zc: the coarser level's surface (vertex, edge midpoint or quad-diagonal midpoint).
          const int cl = l == 0 ? l : l - 1;
          auto C = [&](int64_t cx, int64_t cy) { return hashed_height(cm.source_level(cl), cx, cy); };
          float want;
          if (l == 0)
            want = hashed_height(cm.source_level(0), xx, yy);
          else if (!(xx & 1) && !(yy & 1))
            want = C(xx >> 1, yy >> 1);
          else if (xx & 1 && !(yy & 1))
            want = 0.5f * (C(xx >> 1, yy >> 1) + C((xx >> 1) + 1, yy >> 1));
          else if (!(xx & 1))
            want = 0.5f * (C(xx >> 1, yy >> 1) + C(xx >> 1, (yy >> 1) + 1));
          else
            want = 0.5f * (C(xx >> 1, yy >> 1) + C((xx >> 1) + 1, (yy >> 1) + 1));
          REQUIRE(cm.coarse_heights(l)[cm.index(xx, yy)] == want);
        }
    }
  }
  // wrap() is a true modulus for negatives.
  CHECK(cm.wrap(-1) == 30);
  CHECK(cm.wrap(-31) == 0);
  CHECK(cm.wrap(62) == 0);
}

TEST_CASE("clipmap: desired regions are centred, even-cornered and nested", "[clipmap]") {
  auto src = hashed_source();
  const ClipmapOptions o = whole_updates(63);
  Clipmap cm(src, o);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> pos(-3000.0, 3000.0);
  for (int i = 0; i < 50; ++i) {
    const double x = pos(rng), y = pos(rng);
    cm.update(x, y, 0);
    for (int l = 0; l < cm.level_count(); ++l) {
      const LevelRegion d = cm.desired_region(l), a = cm.active_region(l);
      CHECK((d.x0 & 1) == 0);
      CHECK((d.y0 & 1) == 0);
      CHECK(d.x1 - d.x0 == o.n - 1);
      const auto v = cm.viewer_grid(l);
      CHECK(std::abs(v[0] - 0.5 * double(d.x0 + d.x1)) <= 1.0);
      CHECK(std::abs(v[1] - 0.5 * double(d.y0 + d.y1)) <= 1.0);
      REQUIRE(!a.empty());
      if (l > 0) {
        const LevelRegion p = cm.active_region(l - 1);
        CHECK(a.x0 >= 2 * (p.x0 + 2));
        CHECK(a.x1 <= 2 * (p.x1 - 2));
        CHECK(a.y0 >= 2 * (p.y0 + 2));
        CHECK(a.y1 <= 2 * (p.y1 - 2));
      }
      // Up to date: nothing is cropped.
      CHECK(a == d);
      CHECK(cm.transition_width(l) >= 1.0);
    }
  }
}

TEST_CASE("clipmap: incremental update equals a fill from scratch after a random walk", "[clipmap]") {
  auto src = hashed_source();
  auto src2 = hashed_source();
  for (const int64_t budget : {int64_t(1) << 30, int64_t(0)}) {
    ClipmapOptions o;
    o.n = 31;
    o.budget = budget;
    Clipmap walk(src, o);
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> step(-6.0, 6.0), jump(-200.0, 200.0), height(0.5, 80.0);
    double x = 100, y = 200, z = 10;
    for (int frame = 0; frame < 300; ++frame) {
      if (frame % 50 == 17) {  // occasional teleports force full refills
        x += jump(rng);
        y += jump(rng);
      }
      x += step(rng);
      y += step(rng);
      if (frame % 20 == 0) z = height(rng);  // levels switch off and back on
      walk.update(x, y, z);
    }
    // Let a budget-limited clipmap catch up while the viewer stands still.
    for (int i = 0; i < 4 * kLevels; ++i) walk.update(x, y, z);
    Clipmap fresh(src2, o);
    for (int i = 0; i < 4 * kLevels; ++i) fresh.update(x, y, z);
    for (int l = 0; l < walk.level_count(); ++l) {
      INFO("budget " << budget << " level " << l);
      std::string why;
      CHECK(walk.enabled(l) == fresh.enabled(l));
      if (!walk.enabled(l)) continue;  // switched-off levels keep stale (but correct) data
      const bool same = same_level(walk, fresh, l, why);
      INFO(why);
      CHECK(same);
    }
  }
}

namespace {
// A source whose fill throws for one level while `fail_level` names it (a damaged file under a
// strict decoder), otherwise the hashed heights.
class FlakySource final : public HeightSource {
 public:
  int level_count() const override { return inner_.level_count(); }
  GridSize level_size(int level) const override { return inner_.level_size(level); }
  double spacing_m() const override { return inner_.spacing_m(); }
  void fill(int level, const Rect& rect, float* out, int64_t out_stride) override {
    if (level == fail_level) throw std::runtime_error("damaged level " + std::to_string(level));
    inner_.fill(level, rect, out, out_stride);
  }
  int fail_level = -1;

 private:
  FunctionHeightSource inner_ = hashed_source();
};
}  // namespace

TEST_CASE("clipmap: an update whose source throws leaves the clipmap usable, and the next one catches up",
          "[clipmap]") {
  // refill() used to record the new clip region before filling it: after a throw the level looked
  // current with half-old samples, and later updates never refilled it.
  FlakySource flaky;
  auto src = hashed_source();
  const ClipmapOptions o = whole_updates(31);
  Clipmap cm(flaky, o), fresh(src, o);
  cm.update(100, 200, 10);
  for (const double dx : {7.0, 500.0}) {  // an incremental refill, then a full one
    INFO("move " << dx);
    flaky.fail_level = cm.source_level(3);
    CHECK_THROWS_WITH(cm.update(100 + dx, 200, 10), Catch::Contains("damaged level"));
    for (int l = 0; l < cm.level_count(); ++l) {
      INFO("level " << l);
      CHECK(cm.has_data(l) == (l != 3));
      if (l < 3) CHECK(cm.clip_region(l).x0 == cm.desired_region(l).x0);  // refilled before the throw
      if (l >= 3) CHECK(cm.active_region(l).empty());                     // nothing of it is drawn
      if (l == 3) CHECK(cm.dirty_rects(l).empty());
    }
    flaky.fail_level = -1;
    cm.update(100 + dx, 200, 10);
    fresh.update(100 + dx, 200, 10);
    for (int l = 0; l < cm.level_count(); ++l) {
      INFO("level " << l);
      std::string why;
      const bool same = same_level(cm, fresh, l, why);
      INFO(why);
      CHECK(same);
    }
  }
}

TEST_CASE("clipmap: the per-frame budget is respected and lagging levels are cropped", "[clipmap]") {
  auto src = hashed_source();
  ClipmapOptions o;
  o.n = 31;
  o.deactivate_by_height = false;
  Clipmap cm(src, o);
  REQUIRE(cm.budget() == 31 * 31);
  const int64_t nn = 31 * 31;
  cm.update(0, 0, 1);
  for (int i = 0; i < kLevels; ++i) cm.update(0, 0, 1);  // initial fill: one level per frame
  for (int l = 0; l < cm.level_count(); ++l) REQUIRE(cm.active_region(l) == cm.desired_region(l));

  // Fast flight along x: finer levels need more samples than the budget allows.
  bool saw_behind = false, saw_cropped = false, saw_dropped = false;
  double x = 0;
  for (int frame = 0; frame < 40; ++frame) {
    x += 25.0;  // 25 finest samples per frame: the two finest levels alone want ~1.2 n^2 samples
    const ClipmapUpdateStats s = cm.update(x, 0, 1);
    CHECK(s.samples_filled <= nn);
    if (s.levels_behind > 0) saw_behind = true;
    for (int l = 0; l < cm.level_count(); ++l) {
      const LevelRegion a = cm.active_region(l);
      if (a.empty()) {
        if (cm.has_data(l)) saw_dropped = true;
        for (int f = l + 1; f < cm.level_count(); ++f) CHECK(cm.active_region(f).empty());
        break;
      }
      const Rect c = cm.clip_region(l);
      // Active within the clip region, corners even.
      CHECK(a.x0 >= c.x0);
      CHECK(a.x1 <= c.x0 + c.width - 1);
      CHECK(a.y0 >= c.y0);
      CHECK(a.y1 <= c.y0 + c.height - 1);
      CHECK(((a.x0 | a.x1 | a.y0 | a.y1) & 1) == 0);
      if (!(a == cm.desired_region(l))) saw_cropped = true;
    }
  }
  CHECK(saw_behind);
  CHECK(saw_cropped);
  CHECK(saw_dropped);

  // A smaller budget: still at most one level's refill (n^2) per frame, never more than the budget
  // once something has been spent.
  cm.set_budget(200);
  for (int frame = 0; frame < 20; ++frame) {
    x += 3.0;
    const ClipmapUpdateStats s = cm.update(x, 0, 1);
    CHECK(s.samples_filled <= nn);
    if (s.levels_updated >= 2) CHECK(s.samples_filled <= 200);
  }
  // Standing still, everything catches up and nothing is cropped any more.
  cm.set_budget(0);
  for (int i = 0; i < 3 * kLevels; ++i) cm.update(x, 0, 1);
  for (int l = 0; l < cm.level_count(); ++l) CHECK(cm.active_region(l) == cm.desired_region(l));
}

TEST_CASE("clipmap: levels switch off when the viewer is high above the terrain", "[clipmap]") {
  FunctionHeightSource flat(
      kLevels, GridSize{1 << 12, 1 << 12}, 2.0, [](int, int64_t, int64_t) { return 100.0f; }, true);
  ClipmapOptions o;
  o.n = 31;
  o.budget = 1 << 30;
  Clipmap cm(flat, o);
  for (const double h : {1.0, 20.0, 30.0, 60.0, 100.0, 500.0, 1000.0, 1e5}) {
    cm.update(500, 500, 100.0 + h);
    cm.update(500, 500, 100.0 + h);
    // Level l is on while h <= 0.4 n g_l, g_l = 2 * 2^(L-1-l); level 0 always.
    int want = 1;
    for (int l = 1; l < kLevels; ++l)
      if (h <= 0.4 * 31 * std::ldexp(2.0, kLevels - 1 - l)) want = l + 1;
    int enabled = 0, active = 0;
    for (int l = 0; l < kLevels; ++l) {
      enabled += cm.enabled(l) ? 1 : 0;
      active += cm.active_region(l).empty() ? 0 : 1;
    }
    INFO("height " << h);
    CHECK(enabled == want);
    CHECK(active == want);
    CHECK(std::abs(cm.terrain_height_at(500, 500) - 100.0f) < 1e-4f);
  }
}

TEST_CASE("clipmap: z bounds cover z and zc of every vertex", "[clipmap]") {
  auto src = hashed_source();
  const ClipmapOptions o = whole_updates(31);
  Clipmap cm(src, o);
  cm.update(17.5, -44.25, 3);
  cm.update(30, -20, 3);
  for (int l = 0; l < cm.level_count(); ++l) {
    const LevelRegion a = cm.active_region(l);
    for (int64_t y = a.y0; y + 6 <= a.y1; y += 6)
      for (int64_t x = a.x0; x + 6 <= a.x1; x += 6) {
        const ZRange r = cm.z_bounds(l, LevelRegion{x, y, x + 6, y + 6});
        float lo = 1e30f, hi = -1e30f;
        for (int64_t yy = y; yy <= y + 6; ++yy)
          for (int64_t xx = x; xx <= x + 6; ++xx) {
            const size_t i = cm.index(xx, yy);
            lo = std::min({lo, cm.heights(l)[i], cm.coarse_heights(l)[i]});
            hi = std::max({hi, cm.heights(l)[i], cm.coarse_heights(l)[i]});
          }
        REQUIRE(r.lo <= lo);
        REQUIRE(r.hi >= hi);
      }
  }
}

TEST_CASE("clipmap: bad options are rejected with a clear error", "[clipmap]") {
  auto src = hashed_source();
  ClipmapOptions o;
  o.n = 32;
  CHECK_THROWS_WITH(Clipmap(src, o), Catch::Contains("2^k - 1"));
  o.n = 31;
  o.levels = kLevels + 1;
  CHECK_THROWS_WITH(Clipmap(src, o), Catch::Contains("level count"));
}

TEST_CASE("clipmap: the normal map has twice the geometry's resolution (slopes of U's cubic surface)",
          "[clipmap]") {
  // U's four-point rule reproduces cubics, so on z = c x^3 + d y (sample units) every texel away from
  // the clip border is exact: at a vertex the slope between the half positions x -+ 1/2, between
  // vertices the secant slope; neither is an interpolation of per-vertex normals.
  constexpr double c = 1e-4, d = 0.25, g = 2.0;
  const int levels = 3;
  FunctionHeightSource src(
      levels, GridSize{1 << 10, 1 << 10}, g,
      [](int, int64_t x, int64_t y) { return float(c * double(x) * double(x) * double(x) + d * double(y)); },
      true);
  const ClipmapOptions o = whole_updates(31);
  Clipmap cm(src, o);
  cm.update(37.0 * g, 11.0 * g, 10.0);
  cm.update(61.0 * g, 3.0 * g, 10.0);  // an incremental move: ring and border texels recomputed
  const int l = levels - 1;
  REQUIRE(cm.has_data(l));
  const double gl = cm.spacing(l);
  const Rect r = cm.clip_region(l);
  int checked = 0;
  for (int64_t y = r.y0 + 2; y < r.y0 + r.height - 2; y += 3)
    for (int64_t x = r.x0 + 2; x < r.x0 + r.width - 2; ++x) {
      auto cube = [](double v) { return c * v * v * v; };
      const size_t at_vertex = cm.normal_index(2 * x, 2 * y), between = cm.normal_index(2 * x + 1, 2 * y);
      INFO("sample " << x << "," << y);
      CHECK(cm.normal_map(l)[2 * at_vertex] == Approx((cube(x + 0.5) - cube(x - 0.5)) / gl).margin(1e-4));
      CHECK(cm.normal_map(l)[2 * between] == Approx((cube(x + 1.0) - cube(double(x))) / gl).margin(1e-4));
      CHECK(cm.normal_map(l)[2 * at_vertex + 1] == Approx(d / gl).margin(1e-5));
      ++checked;
    }
  CHECK(checked > 200);
}

namespace {

// Every level with data holds the source's samples on its whole clip region (a time-budgeted
// update leaves no half-moved level).
bool holds_source(const Clipmap& cm, const std::function<float(int, int64_t, int64_t)>& f, std::string& why) {
  for (int l = 0; l < cm.level_count(); ++l) {
    if (!cm.has_data(l)) continue;
    const Rect c = cm.clip_region(l);
    for (int64_t y = c.y0; y < c.y0 + c.height; ++y)
      for (int64_t x = c.x0; x < c.x0 + c.width; ++x)
        if (cm.heights(l)[cm.index(x, y)] != f(cm.source_level(l), x, y))
          return why =
                     "level " + std::to_string(l) + " sample " + std::to_string(x) + "," + std::to_string(y),
                 false;
  }
  return true;
}

// Updates at (x, y) until no level is behind (at most `limit` updates); returns the count.
int settle(Clipmap& cm, double x, double y, int limit) {
  for (int i = 1; i <= limit; ++i)
    if (cm.update(x, y, 1.0).levels_behind == 0) return i;
  return limit + 1;
}

}  // namespace

TEST_CASE("clipmap: a time budget refills in pieces, every level stays whole, and it converges",
          "[clipmap]") {
  auto src = hashed_source();
  ClipmapOptions o = whole_updates(63);
  o.budget = 0;        // no sample limit beside the time budget
  o.budget_ms = 1e-6;  // far below one piece: every update does exactly its first piece
  Clipmap cm(src, o);
  CHECK(cm.budget_ms() == 1e-6);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> step(-30.0, 30.0);
  double x = 100, y = -50;
  bool saw_fill_strips = false, saw_behind = false;
  for (int frame = 0; frame < 120; ++frame) {
    if (frame > 40) x += step(rng), y += step(rng);
    const ClipmapUpdateStats s = cm.update(x, y, 1.0);
    CHECK(s.pieces <= 1);                                          // none once caught up
    CHECK(s.samples_filled <= 2 * int64_t(Clipmap::kPiece) * 63);  // one L-shaped piece at most
    if (s.levels_behind > 0) saw_behind = true;
    for (int l = 0; l < cm.level_count(); ++l)
      if (!cm.has_data(l) && l == 0 && frame > 0) saw_fill_strips = true;
    std::string why;
    const bool ok = holds_source(cm, hashed_height, why);
    INFO(why);
    REQUIRE(ok);
  }
  CHECK(saw_fill_strips);
  CHECK(saw_behind);
  // Standing still it catches up and equals a clipmap filled from scratch there.
  REQUIRE(settle(cm, x, y, 2000) <= 2000);
  auto src2 = hashed_source();
  Clipmap fresh(src2, whole_updates(63));
  fresh.update(x, y, 1.0);
  for (int l = 0; l < cm.level_count(); ++l) {
    std::string why;
    const bool same = same_level(cm, fresh, l, why);
    INFO("level " << l << ": " << why);
    CHECK(same);
  }
  // A generous time budget does a whole flight step in one update.
  cm.set_budget_ms(1e4);
  const ClipmapUpdateStats s = cm.update(x + 40, y, 1.0);
  CHECK(s.levels_behind == 0);
  CHECK(!s.out_of_time);
}

TEST_CASE("clipmap: invalidate then update equals a fresh clipmap over the edited source", "[clipmap]") {
  // The hashed terrain plus an edit: a bump on the finest level's rect and on each coarser level's
  // samples under it (the region D spreads it to lies inside what invalidate marks).
  Rect edit{0, 0, 0, 0};
  float bump = 0;
  auto edited = [&](int level, int64_t x, int64_t y) {
    const int k = kLevels - 1 - level;
    const bool in = x >= (edit.x0 >> k) && x <= ((edit.x0 + edit.width - 1) >> k) && y >= (edit.y0 >> k) &&
                    y <= ((edit.y0 + edit.height - 1) >> k);
    return hashed_height(level, x, y) + (in ? bump : 0.0f);
  };
  for (const bool timed : {false, true}) {
    DYNAMIC_SECTION((timed ? "time budget" : "sample budget")) {
      FunctionHeightSource src(kLevels, GridSize{1 << 12, 1 << 12}, 1.0, edited, true);
      ClipmapOptions o = whole_updates(63);
      if (timed) o.budget = 0, o.budget_ms = 1e-6;
      Clipmap cm(src, o);
      double x = 300, y = 200;
      REQUIRE(settle(cm, x, y, 2000) <= 2000);
      for (int round = 0; round < 3; ++round) {
        edit = Rect{int64_t(x) - 20 + 13 * round, int64_t(y) - 7, 25, 18};
        bump += 100.0f;
        cm.invalidate(edit);
        int64_t pending = 0;
        for (int l = 0; l < cm.level_count(); ++l) pending += cm.invalid_samples(l);
        CHECK(pending > 0);
        REQUIRE(settle(cm, x, y, 2000) <= 2000);
        for (int l = 0; l < cm.level_count(); ++l) CHECK(cm.invalid_samples(l) == 0);
        FunctionHeightSource src2(kLevels, GridSize{1 << 12, 1 << 12}, 1.0, edited, true);
        Clipmap fresh(src2, whole_updates(63));
        fresh.update(x, y, 1.0);
        for (int l = 0; l < cm.level_count(); ++l) {
          std::string why;
          const bool same = same_level(cm, fresh, l, why);
          INFO("round " << round << " level " << l << ": " << why);
          CHECK(same);
        }
        x += 9, y -= 5;  // the next edit comes after a move, with invalidated samples moving out
      }
    }
  }
}
