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
  // Each row lands in at most two contiguous runs of the toroidal storage.
  const int64_t tx = wrap(r.x0), run1 = std::min<int64_t>(r.width, n_ - tx);
  for (int64_t y = 0; y < r.height; ++y) {
    const float* src = scratch_.data() + y * r.width;
    float* row = L.z.data() + wrap(r.y0 + y) * n_;
    std::copy_n(src, run1, row + tx);
    std::copy_n(src + run1, r.width - run1, row);
  }
}

void Clipmap::compute_coarse(int level, const Rect& r) {
  if (r.width <= 0 || r.height <= 0) return;
  Level& L = levels_[size_t(level)];
  if (level == 0) {  // no coarser level: the morph target is the level itself
    const int64_t tx = wrap(r.x0), run1 = std::min<int64_t>(r.width, n_ - tx);
    for (int64_t y = r.y0; y < r.y0 + r.height; ++y) {
      const size_t row = size_t(wrap(y) * n_);
      std::copy_n(L.z.data() + row + tx, run1, L.zc.data() + row + tx);
      std::copy_n(L.z.data() + row, r.width - run1, L.zc.data() + row);
    }
    return;
  }
  const Level& C = levels_[size_t(level) - 1];
  // Coarse samples are clamped into the coarse clip region; the nesting of the desired regions keeps
  // them inside whenever this level is refilled, the clamp only guards against misuse. Storage
  // columns of cx and cx + 1 for every fine column, computed once per call.
  auto ccol = [&](int64_t cx) { return int32_t(wrap(std::clamp(cx, C.clip_x0, C.clip_x0 + n_ - 1))); };
  auto crow = [&](int64_t cy) { return C.z.data() + wrap(std::clamp(cy, C.clip_y0, C.clip_y0 + n_ - 1)) * n_; };
  up_cols_.resize(size_t(3 * r.width));
  for (int64_t i = 0; i < r.width; ++i) {
    const int64_t cx = (r.x0 + i) >> 1;
    up_cols_[size_t(3 * i)] = ccol(cx);
    up_cols_[size_t(3 * i + 1)] = ccol(cx + 1);
    up_cols_[size_t(3 * i + 2)] = int32_t(wrap(r.x0 + i));
  }
  // The coarse surface at a fine vertex: the coarse vertex, the midpoint of the coarse edge, or the
  // midpoint of the quad diagonal (x0, y0)-(x1, y1) that the renderer's triangulation uses.
  for (int64_t y = r.y0; y < r.y0 + r.height; ++y) {
    const float* c0 = crow(y >> 1);
    const float* c1 = (y & 1) ? crow((y >> 1) + 1) : c0;
    float* out = L.zc.data() + wrap(y) * n_;
    for (int64_t i = 0; i < r.width; ++i) {
      const int64_t x = r.x0 + i;
      const int32_t* col = up_cols_.data() + 3 * i;
      const int32_t a = col[0], b = col[1];
      float v;
      if ((x & 1) == 0) v = (y & 1) ? 0.5f * (c0[a] + c1[a]) : c0[a];
      else v = 0.5f * (c0[a] + ((y & 1) ? c1[b] : c0[b]));
      out[col[2]] = v;
    }
  }
}

void Clipmap::compute_normals(int level, const Rect& r) {
  if (r.width <= 0 || r.height <= 0) return;
  Level& L = levels_[size_t(level)];
  const float inv_g = float(1.0 / spacing(level));
  const int64_t cx0 = L.clip_x0, cx1 = L.clip_x0 + n_ - 1, cy0 = L.clip_y0, cy1 = L.clip_y0 + n_ - 1;
  // The level on the half-sample grid: U's four-point rule (-1, 9, 9, -1) / 16 between samples,
  // samples clamped to the clip region. Texel (X, Y) needs half positions X +- 1 and Y +- 1, so the
  // buffer covers half coordinates 2 x0 - 1 .. 2 (x0 + w), likewise in y: z samples x0 - 2 .. x0 + w + 1.
  const int64_t zw = r.width + 4, zh = r.height + 4;
  const int64_t hw = 2 * r.width + 2, hh = 2 * r.height + 2;
  const int64_t hy0 = 2 * r.y0 - 1;
  up_cols_.resize(size_t(zw));
  up_rows_.resize(size_t(hw * zh) + size_t(zw));
  up_.resize(size_t(hw * hh));
  // Storage column of each sample column (clamped, wrapped): computed once per call, not per access.
  for (int64_t i = 0; i < zw; ++i) up_cols_[size_t(i)] = int32_t(wrap(std::clamp(r.x0 - 2 + i, cx0, cx1)));
  float* zrow = up_rows_.data() + hw * zh;  // one gathered sample row
  const float k9 = 9.0f / 16.0f, k1 = 1.0f / 16.0f;
  for (int64_t j = 0; j < zh; ++j) {  // sample rows y0 - 2 .. y0 + h + 1, upsampled in x
    const float* src = L.z.data() + wrap(std::clamp(r.y0 - 2 + j, cy0, cy1)) * n_;
    for (int64_t i = 0; i < zw; ++i) zrow[i] = src[up_cols_[size_t(i)]];
    float* row = up_rows_.data() + j * hw;
    // Half coordinate hx0 + i: odd i is sample x0 - 2 + (i + 3) / 2 - 1 ... written out per pair:
    // i = 2k: between samples x0 - 2 + k and x0 - 1 + k (hx0 is odd); i = 2k + 1: sample x0 - 1 + k.
    for (int64_t k = 0; k < r.width + 1; ++k) {
      const float* z = zrow + k;  // z[0] = sample x0 - 2 + k
      row[2 * k] = k9 * (z[1] + z[2]) - k1 * (z[0] + z[3]);
      row[2 * k + 1] = z[2];
    }
  }
  for (int64_t k = 0; k < hh; ++k) {  // then in y: half row hy0 + k (odd k: a sample row)
    float* out = up_.data() + k * hw;
    if (k & 1) {
      std::copy_n(up_rows_.data() + (k / 2 + 2) * hw, hw, out);
    } else {
      const float* a = up_rows_.data() + (k / 2) * hw;  // sample rows y0 - 2 + k/2 .. + 3
      const float *b = a + hw, *c = b + hw, *d = c + hw;
      for (int64_t i = 0; i < hw; ++i) out[i] = k9 * (b[i] + c[i]) - k1 * (a[i] + d[i]);
    }
  }
  // Central differences one sample apart (two half steps), texels 2 x0 .. 2 (x0 + w) - 1, written
  // toroidally in at most two runs per row.
  const int64_t m = 2 * int64_t(n_);
  const int64_t tx0 = ((2 * r.x0) % m + m) % m, texels = 2 * r.width;
  const int64_t run1 = std::min(texels, m - tx0);
  for (int64_t k = 1; k < hh - 1; ++k) {
    const float *c = up_.data() + k * hw, *above = c - hw, *below = c + hw;
    float* dst = L.normal.data() + 2 * size_t(((hy0 + k) % m + m) % m * m);
    for (int64_t i = 1; i <= texels; ++i) {
      const int64_t t = i - 1 < run1 ? tx0 + i - 1 : i - 1 - run1;
      dst[2 * t] = (c[i + 1] - c[i - 1]) * inv_g;
      dst[2 * t + 1] = (below[i] - above[i]) * inv_g;
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
  // Storage column of every level column the tiles span (clip region only), computed once.
  const int64_t colx0 = std::max(tx0 * kTile, clip.x0), colx1 = std::min((tx1 + 1) * kTile, clip.x0 + n_);
  up_cols_.resize(size_t(colx1 - colx0));
  for (int64_t x = colx0; x < colx1; ++x) up_cols_[size_t(x - colx0)] = int32_t(wrap(x));
  for (int64_t ty = ty0; ty <= ty1; ++ty)
    for (int64_t tx = tx0; tx <= tx1; ++tx) {
      const Rect t = intersect(Rect{tx * kTile, ty * kTile, kTile, kTile}, clip);
      float lo = std::numeric_limits<float>::infinity(), hi = -lo;
      const int32_t* cols = up_cols_.data() + (t.x0 - colx0);
      for (int64_t y = t.y0; y < t.y0 + t.height; ++y) {
        const float* z = L.z.data() + wrap(y) * n_;
        const float* zc = L.zc.data() + wrap(y) * n_;
        for (int64_t i = 0; i < t.width; ++i) {
          lo = std::min({lo, z[cols[i]], zc[cols[i]]});
          hi = std::max({hi, z[cols[i]], zc[cols[i]]});
        }
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
