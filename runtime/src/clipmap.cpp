// Geometry clipmap update: desired regions, budgeted coarse-to-fine toroidal refill, zc, slopes,
// tile z ranges, level switching by viewer height and active-region cropping (L&H 2004 §4-6.1).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "runtime/clipmap.h"

namespace terrain::runtime {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Rounding to even coordinates, correct for negative values (C++20: two's complement).
int64_t ceil_even(int64_t v) { return v + (v & 1); }
int64_t floor_even(int64_t v) { return v - (v & 1); }

LevelRegion intersect(const LevelRegion& a, const LevelRegion& b) {
  return LevelRegion{std::max(a.x0, b.x0), std::max(a.y0, b.y0), std::min(a.x1, b.x1), std::min(a.y1, b.y1)};
}

Rect intersect(const Rect& a, const Rect& b) {
  const int64_t x0 = std::max(a.x0, b.x0), y0 = std::max(a.y0, b.y0);
  const int64_t x1 = std::min(a.x0 + a.width, b.x0 + b.width), y1 = std::min(a.y0 + a.height, b.y0 + b.height);
  return Rect{x0, y0, std::max<int64_t>(x1 - x0, 0), std::max<int64_t>(y1 - y0, 0)};
}

Rect dilate(const Rect& r, int64_t d) { return Rect{r.x0 - d, r.y0 - d, r.width + 2 * d, r.height + 2 * d}; }

int64_t floor_div(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

}  // namespace

Clipmap::Clipmap(HeightSource& source, const ClipmapOptions& options) : source_(source), options_(options) {
  n_ = options.n;
  if (n_ < 15 || n_ > 1023 || ((n_ + 1) & n_) != 0)
    throw std::invalid_argument("clipmap size n must be 2^k - 1 in 15..1023, got " + std::to_string(n_));
  const int source_levels = source.level_count();
  if (source_levels < 1) throw std::invalid_argument("clipmap: the height source has no levels");
  const int levels = options.levels == 0 ? source_levels : options.levels;
  if (levels < 1 || levels > source_levels || levels > kMaxLevels)
    throw std::invalid_argument("clipmap: level count must be 1.." + std::to_string(source_levels) + " (the source's), got " +
                                std::to_string(options.levels));
  if (!(source.spacing_m() > 0)) throw std::invalid_argument("clipmap: the height source's spacing must be positive");
  first_source_level_ = source_levels - levels;
  budget_ = options.budget > 0 ? options.budget : int64_t(n_) * n_;
  tiles_ = (n_ - 1) / kTile + 2;
  levels_.resize(size_t(levels));
  const size_t nn = size_t(n_) * size_t(n_);
  for (Level& L : levels_) {
    L.z.assign(nn, 0.0f);
    L.zc.assign(nn, 0.0f);
    L.normal.assign(8 * nn, 0.0f);
    L.tile_range.assign(size_t(tiles_) * size_t(tiles_), ZRange{});
  }
  scratch_.resize(nn);
}

double Clipmap::spacing(int level) const {
  return std::ldexp(source_.spacing_m(), level_count() - 1 - level);
}

std::array<double, 2> Clipmap::viewer_grid(int level) const {
  const double g = spacing(level);
  return {viewer_[0] / g, viewer_[1] / g};
}

LevelRegion Clipmap::desired_for(int level, double x_m, double y_m) const {
  // Centre the n-vertex square on the viewer, corners on even coordinates: x0 = 2 round((v - (n-1)/2) / 2).
  const double g = spacing(level), half = (n_ - 1) / 2.0;
  const int64_t x0 = 2 * int64_t(std::floor((x_m / g - half) / 2.0 + 0.5));
  const int64_t y0 = 2 * int64_t(std::floor((y_m / g - half) / 2.0 + 0.5));
  return LevelRegion{x0, y0, x0 + n_ - 1, y0 + n_ - 1};
}

int64_t Clipmap::exposed_samples(const Level& L, int64_t x0, int64_t y0) const {
  const int64_t nn = int64_t(n_) * n_;
  if (!L.has_data) return nn;
  const int64_t dx = std::abs(x0 - L.clip_x0), dy = std::abs(y0 - L.clip_y0);
  if (dx >= n_ || dy >= n_) return nn;
  return nn - (n_ - dx) * (n_ - dy);
}

void Clipmap::fill_rect(int level, const Rect& r) {
  Level& L = levels_[size_t(level)];
  source_.fill(source_level(level), r, scratch_.data(), r.width);
  for (int64_t y = 0; y < r.height; ++y) {
    const float* src = scratch_.data() + y * r.width;
    float* row = L.z.data() + wrap(r.y0 + y) * n_;
    for (int64_t x = 0; x < r.width; ++x) row[wrap(r.x0 + x)] = src[x];
  }
}

void Clipmap::compute_coarse(int level, const Rect& r) {
  Level& L = levels_[size_t(level)];
  if (level == 0) {  // no coarser level: the morph target is the level itself
    for (int64_t y = r.y0; y < r.y0 + r.height; ++y)
      for (int64_t x = r.x0; x < r.x0 + r.width; ++x) L.zc[index(x, y)] = L.z[index(x, y)];
    return;
  }
  const Level& C = levels_[size_t(level) - 1];
  // Coarse samples are clamped into the coarse clip region; the nesting of the desired regions keeps
  // them inside whenever this level is refilled, the clamp only guards against misuse.
  auto zc_at = [&](int64_t cx, int64_t cy) {
    cx = std::clamp(cx, C.clip_x0, C.clip_x0 + n_ - 1);
    cy = std::clamp(cy, C.clip_y0, C.clip_y0 + n_ - 1);
    return C.z[index(cx, cy)];
  };
  // The coarse surface at a fine vertex: the coarse vertex, the midpoint of the coarse edge, or the
  // midpoint of the quad diagonal (x0, y0)-(x1, y1) that the renderer's triangulation uses.
  for (int64_t y = r.y0; y < r.y0 + r.height; ++y) {
    const int64_t cy = y >> 1;
    const bool oy = (y & 1) != 0;
    for (int64_t x = r.x0; x < r.x0 + r.width; ++x) {
      const int64_t cx = x >> 1;
      const bool ox = (x & 1) != 0;
      float v;
      if (!ox && !oy) v = zc_at(cx, cy);
      else if (ox && !oy) v = 0.5f * (zc_at(cx, cy) + zc_at(cx + 1, cy));
      else if (!ox && oy) v = 0.5f * (zc_at(cx, cy) + zc_at(cx, cy + 1));
      else v = 0.5f * (zc_at(cx, cy) + zc_at(cx + 1, cy + 1));
      L.zc[index(x, y)] = v;
    }
  }
}

void Clipmap::compute_normals(int level, const Rect& r) {
  if (r.width <= 0 || r.height <= 0) return;
  Level& L = levels_[size_t(level)];
  const double inv_g = 1.0 / spacing(level);
  const int64_t cx0 = L.clip_x0, cx1 = L.clip_x0 + n_ - 1, cy0 = L.clip_y0, cy1 = L.clip_y0 + n_ - 1;
  // The level on the half-sample grid: U's four-point rule (-1, 9, 9, -1) / 16 between samples,
  // samples clamped to the clip region. Texel (X, Y) needs half positions X +- 1 and Y +- 1, so the
  // buffer covers half coordinates 2 x0 - 1 .. 2 (x0 + w), likewise in y: z samples x0 - 2 .. x0 + w + 1.
  const int64_t hw = 2 * r.width + 2, hh = 2 * r.height + 2;
  const int64_t hx0 = 2 * r.x0 - 1, hy0 = 2 * r.y0 - 1;
  up_rows_.resize(size_t(hw * (r.height + 4)));
  up_.resize(size_t(hw * hh));
  auto zs = [&](int64_t x, int64_t y) { return L.z[index(std::clamp(x, cx0, cx1), std::clamp(y, cy0, cy1))]; };
  for (int64_t j = 0; j < r.height + 4; ++j) {  // sample rows y0 - 2 .. y0 + h + 1, upsampled in x
    const int64_t y = r.y0 - 2 + j;
    float* row = up_rows_.data() + j * hw;
    for (int64_t i = 0; i < hw; ++i) {
      const int64_t X = hx0 + i;
      if ((X & 1) == 0) {
        row[i] = zs(X >> 1, y);
      } else {
        const int64_t x = X >> 1;  // between x and x + 1
        row[i] = (9.0f * (zs(x, y) + zs(x + 1, y)) - (zs(x - 1, y) + zs(x + 2, y))) * (1.0f / 16.0f);
      }
    }
  }
  for (int64_t k = 0; k < hh; ++k) {  // then in y
    const int64_t Y = hy0 + k;
    float* out = up_.data() + k * hw;
    const int64_t j = (Y >> 1) - (r.y0 - 2);  // row of sample Y >> 1 in up_rows_
    const float* a = up_rows_.data() + j * hw;
    if ((Y & 1) == 0) {
      std::copy_n(a, hw, out);
    } else {
      const float *m1 = a - hw, *p1 = a + hw, *p2 = a + 2 * hw;
      for (int64_t i = 0; i < hw; ++i) out[i] = (9.0f * (a[i] + p1[i]) - (m1[i] + p2[i])) * (1.0f / 16.0f);
    }
  }
  // Central differences one sample apart (two half steps), texels 2 x0 .. 2 (x0 + w) - 1.
  const float s = float(inv_g);
  for (int64_t k = 1; k < hh - 1; ++k) {
    const float *c = up_.data() + k * hw, *above = c - hw, *below = c + hw;
    const int64_t Y = hy0 + k;
    for (int64_t i = 1; i < hw - 1; ++i) {
      const size_t t = normal_index(hx0 + i, Y);
      L.normal[2 * t] = (c[i + 1] - c[i - 1]) * s;
      L.normal[2 * t + 1] = (below[i] - above[i]) * s;
    }
  }
}

void Clipmap::compute_tiles(int level, const Rect& r) {
  Level& L = levels_[size_t(level)];
  const Rect clip{L.clip_x0, L.clip_y0, n_, n_};
  const Rect in = intersect(r, clip);
  if (in.width == 0 || in.height == 0) return;
  const int64_t tx0 = floor_div(in.x0, kTile), tx1 = floor_div(in.x0 + in.width - 1, kTile);
  const int64_t ty0 = floor_div(in.y0, kTile), ty1 = floor_div(in.y0 + in.height - 1, kTile);
  for (int64_t ty = ty0; ty <= ty1; ++ty)
    for (int64_t tx = tx0; tx <= tx1; ++tx) {
      const Rect t = intersect(Rect{tx * kTile, ty * kTile, kTile, kTile}, clip);
      float lo = std::numeric_limits<float>::infinity(), hi = -lo;
      for (int64_t y = t.y0; y < t.y0 + t.height; ++y)
        for (int64_t x = t.x0; x < t.x0 + t.width; ++x) {
          const size_t i = index(x, y);
          lo = std::min({lo, L.z[i], L.zc[i]});
          hi = std::max({hi, L.z[i], L.zc[i]});
        }
      const int64_t wt = ((tx % tiles_) + tiles_) % tiles_, ht = ((ty % tiles_) + tiles_) % tiles_;
      L.tile_range[size_t(ht * tiles_ + wt)] = ZRange{lo, hi};
    }
}

void Clipmap::refill(int level, int64_t x0, int64_t y0, ClipmapUpdateStats& stats) {
  Level& L = levels_[size_t(level)];
  const int64_t dx = x0 - L.clip_x0, dy = y0 - L.clip_y0;
  const int64_t old_x0 = L.clip_x0, old_y0 = L.clip_y0;
  const bool full = !L.has_data || std::abs(dx) >= n_ || std::abs(dy) >= n_;
  L.clip_x0 = x0;
  L.clip_y0 = y0;
  L.has_data = true;
  // The newly exposed L-shape as two rectangles: whole-height columns, then rows over the rest.
  std::vector<Rect>& rects = L.dirty;
  rects.clear();
  if (full) {
    rects.push_back(Rect{x0, y0, n_, n_});
  } else {
    if (dx > 0) rects.push_back(Rect{old_x0 + n_, y0, dx, n_});
    if (dx < 0) rects.push_back(Rect{x0, y0, -dx, n_});
    const int64_t kx0 = std::max(x0, old_x0), kw = n_ - std::abs(dx);
    if (dy > 0) rects.push_back(Rect{kx0, old_y0 + n_, kw, dy});
    if (dy < 0) rects.push_back(Rect{kx0, y0, kw, -dy});
  }
  const Rect clip{x0, y0, n_, n_};
  auto t0 = Clock::now();
  for (const Rect& r : rects) {
    fill_rect(level, r);
    stats.samples_filled += r.width * r.height;
  }
  ClipmapUpdateStats::Level& mine = stats.per_level[size_t(level)];
  mine.seconds_fill = since(t0);
  stats.seconds_fill += mine.seconds_fill;
  for (const Rect& r : rects) mine.samples_filled += r.width * r.height;
  t0 = Clock::now();
  for (const Rect& r : rects) compute_coarse(level, r);
  mine.seconds_coarse = since(t0);
  stats.seconds_coarse += mine.seconds_coarse;
  t0 = Clock::now();
  // A sample's texels depend on the samples within 2 of it (U's support), clamped to the clip
  // region: recompute a 2-sample ring around the new samples, and the 2-sample band along the clip
  // border, where the clamp now reaches other samples than before.
  for (const Rect& r : rects) compute_normals(level, intersect(dilate(r, 2), clip));
  if (!full) {
    compute_normals(level, Rect{x0, y0, n_, 2});
    compute_normals(level, Rect{x0, y0 + n_ - 2, n_, 2});
    compute_normals(level, Rect{x0, y0 + 2, 2, n_ - 4});
    compute_normals(level, Rect{x0 + n_ - 2, y0 + 2, 2, n_ - 4});
  }
  mine.seconds_normals = since(t0);
  stats.seconds_normals += mine.seconds_normals;
  t0 = Clock::now();
  for (const Rect& r : rects) compute_tiles(level, r);
  // Tiles straddling the clip border lost or gained samples where the region moved away: refresh
  // the border tiles so that the ranges equal those of a clipmap filled from scratch.
  if (!full) {
    compute_tiles(level, Rect{x0, y0, n_, kTile});
    compute_tiles(level, Rect{x0, y0 + n_ - kTile, n_, kTile});
    compute_tiles(level, Rect{x0, y0, kTile, n_});
    compute_tiles(level, Rect{x0 + n_ - kTile, y0, kTile, n_});
  }
  mine.seconds_bounds = since(t0);
  stats.seconds_bounds += mine.seconds_bounds;
  // Normals changed on the ring and on the clip border too: report them for upload.
  if (!full) {
    for (Rect& r : rects) r = intersect(dilate(r, 2), clip);
    rects.push_back(Rect{x0, y0, n_, 2});
    rects.push_back(Rect{x0, y0 + n_ - 2, n_, 2});
    rects.push_back(Rect{x0, y0 + 2, 2, n_ - 4});
    rects.push_back(Rect{x0 + n_ - 2, y0 + 2, 2, n_ - 4});
  }
}

float Clipmap::level_height_at(int level, double gx, double gy) const {
  const Level& L = lv(level);
  const double fx = std::floor(gx), fy = std::floor(gy);
  const int64_t x = std::min(int64_t(fx), L.clip_x0 + n_ - 2), y = std::min(int64_t(fy), L.clip_y0 + n_ - 2);
  const double tx = gx - double(x), ty = gy - double(y);
  const double a = L.z[index(x, y)], b = L.z[index(x + 1, y)], c = L.z[index(x, y + 1)], d = L.z[index(x + 1, y + 1)];
  return float((a * (1 - tx) + b * tx) * (1 - ty) + (c * (1 - tx) + d * tx) * ty);
}

float Clipmap::terrain_height_at(double x_m, double y_m) const {
  for (int l = level_count() - 1; l >= 0; --l) {
    const Level& L = lv(l);
    if (!L.has_data) continue;
    const double gx = x_m / spacing(l), gy = y_m / spacing(l);
    if (gx >= double(L.clip_x0) && gx <= double(L.clip_x0 + n_ - 1) && gy >= double(L.clip_y0) &&
        gy <= double(L.clip_y0 + n_ - 1))
      return level_height_at(l, gx, gy);
  }
  return std::numeric_limits<float>::quiet_NaN();
}

ZRange Clipmap::z_bounds(int level, const LevelRegion& r) const {
  const Level& L = lv(level);
  const LevelRegion in = intersect(r, LevelRegion{L.clip_x0, L.clip_y0, L.clip_x0 + n_ - 1, L.clip_y0 + n_ - 1});
  if (in.empty() || !L.has_data) return ZRange{};
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (int64_t ty = floor_div(in.y0, kTile); ty <= floor_div(in.y1, kTile); ++ty)
    for (int64_t tx = floor_div(in.x0, kTile); tx <= floor_div(in.x1, kTile); ++tx) {
      const int64_t wt = ((tx % tiles_) + tiles_) % tiles_, ht = ((ty % tiles_) + tiles_) % tiles_;
      const ZRange& t = L.tile_range[size_t(ht * tiles_ + wt)];
      lo = std::min(lo, t.lo);
      hi = std::max(hi, t.hi);
    }
  return ZRange{lo, hi};
}

void Clipmap::crop_active_regions() {
  bool coarser_empty = false;
  for (int l = 0; l < level_count(); ++l) {
    Level& L = levels_[size_t(l)];
    LevelRegion a;  // empty
    if (L.enabled && L.has_data && !coarser_empty) {
      const LevelRegion clip{ceil_even(L.clip_x0), ceil_even(L.clip_y0), floor_even(L.clip_x0 + n_ - 1),
                             floor_even(L.clip_y0 + n_ - 1)};
      a = intersect(L.desired, clip);
      if (l > 0) {
        // Inside the coarser active region eroded by 2 coarse units (paper §5 constraint 4).
        const LevelRegion& p = levels_[size_t(l) - 1].active;
        a = intersect(a, LevelRegion{2 * (p.x0 + 2), 2 * (p.y0 + 2), 2 * (p.x1 - 2), 2 * (p.y1 - 2)});
      }
      // Fewer than 4 quads a side cannot hold a transition: drop the level.
      if (a.x1 - a.x0 < 4 || a.y1 - a.y0 < 4) a = LevelRegion{};
    }
    L.active = a;
    coarser_empty = a.empty();
  }
  // Transition width: n/10, but alpha must reach 0 before the finer level's perimeter.
  for (int l = 0; l < level_count(); ++l) {
    Level& L = levels_[size_t(l)];
    double w = n_ / 10.0;
    if (l + 1 < level_count() && !levels_[size_t(l) + 1].active.empty()) {
      const LevelRegion& a = L.active;
      const LevelRegion& f = levels_[size_t(l) + 1].active;
      const int64_t room = std::min({f.x0 / 2 - a.x0, a.x1 - f.x1 / 2, f.y0 / 2 - a.y0, a.y1 - f.y1 / 2});
      w = std::min(w, double(room - 2));
    }
    L.transition_width = std::max(w, 1.0);
  }
}

ClipmapUpdateStats Clipmap::update(double x_m, double y_m, double z_m) {
  ClipmapUpdateStats stats;
  viewer_[0] = x_m;
  viewer_[1] = y_m;
  viewer_[2] = z_m;
  for (Level& L : levels_) L.dirty.clear();
  int64_t spent = 0;
  bool blocked = false;
  for (int l = 0; l < level_count(); ++l) {
    Level& L = levels_[size_t(l)];
    L.desired = desired_for(l, x_m, y_m);
    bool on = l == 0 || levels_[size_t(l) - 1].enabled;
    if (on && l > 0 && options_.deactivate_by_height) {
      // Height above the terrain from the finest coarser level holding the viewer (paper §4).
      const float ground = terrain_height_at(x_m, y_m);
      if (!std::isnan(ground)) {
        stats.viewer_height = z_m - double(ground);
        if (stats.viewer_height > options_.height_factor * n_ * spacing(l)) on = false;
      }
    }
    L.enabled = on;
    if (!on) continue;
    ++stats.enabled_levels;
    const bool current = L.has_data && L.clip_x0 == L.desired.x0 && L.clip_y0 == L.desired.y0;
    if (!current && !blocked) {
      const bool coarser_current =
          l == 0 || (levels_[size_t(l) - 1].has_data && levels_[size_t(l) - 1].clip_x0 == levels_[size_t(l) - 1].desired.x0 &&
                     levels_[size_t(l) - 1].clip_y0 == levels_[size_t(l) - 1].desired.y0);
      const int64_t cost = exposed_samples(L, L.desired.x0, L.desired.y0);
      // The first refill of an update always goes ahead (at most n^2), so the clipmap makes progress
      // even with a budget below n^2; after that the budget is a hard limit.
      if (!coarser_current || (spent > 0 && spent + cost > budget_)) {
        blocked = true;
      } else {
        refill(l, L.desired.x0, L.desired.y0, stats);
        spent += cost;
        ++stats.levels_updated;
      }
    }
    if (!(L.has_data && L.clip_x0 == L.desired.x0 && L.clip_y0 == L.desired.y0)) ++stats.levels_behind;
  }
  crop_active_regions();
  for (const Level& L : levels_) stats.active_levels += L.active.empty() ? 0 : 1;
  return stats;
}

}  // namespace terrain::runtime
