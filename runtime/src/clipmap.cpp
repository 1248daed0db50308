// Geometry clipmap update: desired regions, budgeted coarse-to-fine toroidal refill, zc, slopes,
// tile z ranges, level switching by viewer height and active-region cropping (L&H 2004 §4-6.1).
#include "runtime/clipmap.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "runtime/internal/toroidal_rows.h"

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
  const int64_t x1 = std::min(a.x0 + a.width, b.x0 + b.width),
                y1 = std::min(a.y0 + a.height, b.y0 + b.height);
  return Rect{x0, y0, std::max<int64_t>(x1 - x0, 0), std::max<int64_t>(y1 - y0, 0)};
}

Rect dilate(const Rect& r, int64_t d) { return Rect{r.x0 - d, r.y0 - d, r.width + 2 * d, r.height + 2 * d}; }

// `band` less the part `cut` covers, when that part spans the band across and reaches one of its
// ends (a rectangle remains); otherwise band as it is. The clip-border bands less the new strips,
// which are recomputed anyway (a strip is whole-height or whole-width and lies on the border).
Rect trim(const Rect& band, const Rect& cut) {
  const Rect in = intersect(band, cut);
  if (in.width == 0 || in.height == 0) return band;
  if (in.height == band.height) {
    if (in.x0 == band.x0) return Rect{in.x0 + in.width, band.y0, band.width - in.width, band.height};
    if (in.x0 + in.width == band.x0 + band.width)
      return Rect{band.x0, band.y0, band.width - in.width, band.height};
  }
  if (in.width == band.width) {
    if (in.y0 == band.y0) return Rect{band.x0, in.y0 + in.height, band.width, band.height - in.height};
    if (in.y0 + in.height == band.y0 + band.height)
      return Rect{band.x0, band.y0, band.width, band.height - in.height};
  }
  return band;
}

int64_t floor_div(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

// The normal map's loops, U's four-point rule and central differences. Compiled for AVX2 and for
// the baseline, the dynamic linker picks one at load time (target_clones): about 1.7x faster with
// AVX2 (measured, full level). No FMA, so both clones give the same floats.
constexpr float kU9 = 9.0f / 16.0f, kU1 = 1.0f / 16.0f;

// A sample row z[0 .. pairs + 3) on the half grid: row[2k] between z[k + 1] and z[k + 2],
// row[2k + 1] = z[k + 2].
[[gnu::target_clones("avx2", "default")]] void upsample_row(const float* z, int64_t pairs, float* row) {
  for (int64_t k = 0; k < pairs; ++k) {
    row[2 * k] = kU9 * (z[k + 1] + z[k + 2]) - kU1 * (z[k] + z[k + 3]);
    row[2 * k + 1] = z[k + 2];
  }
}

// The half row between sample rows b and c (a and d the outer taps).
[[gnu::target_clones("avx2", "default")]] void upsample_between(const float* a, const float* b,
                                                                const float* c, const float* d, int64_t count,
                                                                float* out) {
  for (int64_t i = 0; i < count; ++i) out[i] = kU9 * (b[i] + c[i]) - kU1 * (a[i] + d[i]);
}

// Texels (dz/dx, dz/dy) at half positions c[0 .. count): differences one sample (two half steps)
// apart along the row and across the rows above and below.
[[gnu::target_clones("avx2", "default")]] void slopes(const float* above, const float* c, const float* below,
                                                      int64_t count, float inv_g, float* dst) {
  for (int64_t i = 0; i < count; ++i) {
    dst[2 * i] = (c[i + 1] - c[i - 1]) * inv_g;
    dst[2 * i + 1] = (below[i] - above[i]) * inv_g;
  }
}

// Per-column range of z and zc over one more row (min/max: exact, the same in both clones).
[[gnu::target_clones("avx2", "default")]] void accumulate_range(const float* z, const float* zc,
                                                                int64_t count, float* lo, float* hi) {
  for (int64_t i = 0; i < count; ++i) {
    lo[i] = std::min(lo[i], std::min(z[i], zc[i]));
    hi[i] = std::max(hi[i], std::max(z[i], zc[i]));
  }
}

}  // namespace

Clipmap::Clipmap(HeightSource& source, const ClipmapOptions& options) : source_(source), options_(options) {
  n_ = options.n;
  if (n_ < 15 || n_ > 1023 || ((n_ + 1) & n_) != 0)
    throw std::invalid_argument("clipmap size n must be 2^k - 1 in 15..1023, got " + std::to_string(n_));
  const int source_levels = source.level_count();
  if (source_levels < 1) throw std::invalid_argument("clipmap: the height source has no levels");
  const int levels = clipmap_level_count(options, source_levels);
  if (levels < 1 || levels > source_levels || levels > kMaxLevels)
    throw std::invalid_argument("clipmap: level count must be 1.." + std::to_string(source_levels) +
                                " (the source's), got " + std::to_string(options.levels));
  if (!(source.spacing_m() > 0))
    throw std::invalid_argument("clipmap: the height source's spacing must be positive");
  first_source_level_ = source_levels - levels;
  budget_ = options.budget > 0 ? options.budget : int64_t(n_) * n_;
  tiles_ = (n_ - 1) / kTile + 2;
  levels_.resize(size_t(levels));
  refines_units_ = source.refines_units();
  const size_t nn = size_t(n_) * size_t(n_);
  for (Level& L : levels_) {
    if (refines_units_) L.units.assign(nn, 0);
    L.z.assign(nn, 0.0f);
    L.zc.assign(nn, 0.0f);
    L.normal.assign(8 * nn, 0.0f);
    L.tile_range.assign(size_t(tiles_) * size_t(tiles_), ZRange{});
  }
  scratch_.resize(nn);
  if (refines_units_) unit_scratch_.resize(nn);
  // The most any of compute_coarse, compute_normals and compute_tiles takes for an n-wide rectangle.
  rows_.resize(size_t(16) * size_t(n_ + 16));
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

void Clipmap::fill_rect(int level, const Rect& r, FillSplit& split) {
  Level& L = levels_[size_t(level)];
  if (refines_units_) {
    // The paper's update: U of the coarser level as this clipmap holds it, plus the residual.
    const Level* coarser =
        level > 0 && levels_[size_t(level) - 1].has_data ? &levels_[size_t(level) - 1] : nullptr;
    const HeldUnits held =
        coarser ? HeldUnits{coarser->units.data(), n_, Rect{coarser->clip_x0, coarser->clip_y0, n_, n_}}
                : HeldUnits{};
    source_.fill_units(source_level(level), r, coarser ? &held : nullptr, scratch_.data(),
                       unit_scratch_.data(), r.width, &split);
  } else {
    source_.fill(source_level(level), r, scratch_.data(), r.width);
  }
  const RowRuns runs(n_, r.x0, r.width);
  for (int64_t y = 0; y < r.height; ++y) {
    const size_t row = size_t(wrap(r.y0 + y) * n_);
    runs.scatter(scratch_.data() + y * r.width, L.z.data() + row);
    if (refines_units_) runs.scatter(unit_scratch_.data() + y * r.width, L.units.data() + row);
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
  // them inside whenever this level is refilled, the clamp only guards against misuse.
  const int64_t ccx0 = C.clip_x0, ccx1 = C.clip_x0 + n_ - 1, ccy0 = C.clip_y0, ccy1 = C.clip_y0 + n_ - 1;
  const int64_t gx0 = r.x0 >> 1, gw = ((r.x0 + r.width - 1) >> 1) + 2 - gx0;  // coarse columns used
  float* g0 = rows_.data();  // coarse row y >> 1 at columns gx0 ..
  float* g1 = g0 + gw;       // coarse row (y >> 1) + 1 (odd y)
  float* fine = g1 + gw;     // the output row, fine columns x0 ..
  const RowRuns coarse_runs(n_, gx0, gw, ccx0, ccx1), fine_runs(n_, r.x0, r.width);
  // The coarse surface at a fine vertex: the coarse vertex, the midpoint of the coarse edge, or the
  // midpoint of the quad diagonal (x0, y0)-(x1, y1) that the renderer's triangulation uses.
  for (int64_t y = r.y0; y < r.y0 + r.height; ++y) {
    const int64_t cy = y >> 1;
    coarse_runs.gather(C.z.data() + wrap(std::clamp(cy, ccy0, ccy1)) * n_, g0);
    // An even fine column sits on coarse column k of g0/g1, the odd one after it between k and k + 1:
    // written as (even, odd) pairs from the first even column, so that the loop vectorises.
    const float* next = g0;  // the coarse row the edge or diagonal midpoints reach: y's or the next
    if (y & 1) {
      coarse_runs.gather(C.z.data() + wrap(std::clamp(cy + 1, ccy0, ccy1)) * n_, g1);
      next = g1;
    }
    const int64_t first = r.x0 & 1;  // fine column `first` is the first even one (coarse column 1 if odd)
    if (first) fine[0] = 0.5f * (g0[0] + next[1]);
    const int64_t pairs = (r.width - first) / 2;
    float* f = fine + first;
    const float* c = g0 + first;
    const float* c1 = next + first;
    if (y & 1) {
      for (int64_t p = 0; p < pairs; ++p) {
        f[2 * p] = 0.5f * (c[p] + c1[p]);
        f[2 * p + 1] = 0.5f * (c[p] + c1[p + 1]);
      }
    } else {
      for (int64_t p = 0; p < pairs; ++p) {
        f[2 * p] = c[p];
        f[2 * p + 1] = 0.5f * (c[p] + c[p + 1]);
      }
    }
    if (first + 2 * pairs < r.width) f[2 * pairs] = (y & 1) ? 0.5f * (c[pairs] + c1[pairs]) : c[pairs];
    fine_runs.scatter(fine, L.zc.data() + wrap(y) * n_);
  }
}

void Clipmap::compute_normals(int level, const Rect& r) {
  if (r.width <= 0 || r.height <= 0) return;
  Level& L = levels_[size_t(level)];
  const float inv_g = float(1.0 / spacing(level));
  const int64_t cx0 = L.clip_x0, cx1 = L.clip_x0 + n_ - 1, cy0 = L.clip_y0, cy1 = L.clip_y0 + n_ - 1;
  // The level on the half-sample grid: U's four-point rule (-1, 9, 9, -1) / 16 between samples,
  // samples clamped to the clip region. Texel (X, Y) needs half positions X +- 1 and Y +- 1, so a
  // half row covers half coordinates 2 x0 - 1 .. 2 (x0 + w) (hw values, from samples x0 - 2 ..
  // x0 + w + 1), and half rows 2 y0 - 1 .. 2 (y0 + h) are made one after the other (from sample rows
  // y0 - 2 .. y0 + h + 1), each texel row written once its half rows above and below exist.
  const int64_t zw = r.width + 4, hw = 2 * r.width + 2, hh = 2 * r.height + 2;
  const int64_t hy0 = 2 * r.y0 - 1;
  float* zrow = rows_.data();    // one gathered sample row
  float* xrows = zrow + zw;      // ring of 4 sample rows upsampled in x: sample row y0 - 2 + j in slot j & 3
  float* even = xrows + 4 * hw;  // ring of 2 half rows between sample rows
  int64_t next_j = 0;            // the next sample row to upsample in x
  const RowRuns sample_runs(n_, r.x0 - 2, zw, cx0, cx1);
  auto upsample_rows_to = [&](int64_t j_last) {
    for (; next_j <= j_last; ++next_j) {
      sample_runs.gather(L.z.data() + wrap(std::clamp(r.y0 - 2 + next_j, cy0, cy1)) * n_, zrow);
      // Half coordinate 2 x0 - 1 + i: even i lies between samples x0 - 2 + i/2 and x0 - 1 + i/2,
      // odd i on sample x0 - 1 + i/2 (zrow[0] = sample x0 - 2).
      upsample_row(zrow, r.width + 1, xrows + (next_j & 3) * hw);
    }
  };
  // Central differences one sample apart (two half steps), texels 2 x0 .. 2 (x0 + w) - 1, written
  // toroidally in at most two runs per row.
  const int64_t m = 2 * int64_t(n_);
  const int64_t tx0 = ((2 * r.x0) % m + m) % m, texels = 2 * r.width;
  const int64_t run1 = std::min(texels, m - tx0);
  const float* half[3] = {nullptr, nullptr, nullptr};  // half rows k - 2, k - 1, k
  for (int64_t k = 0; k < hh; ++k) {                   // half row hy0 + k (odd k: a sample row)
    const float* row;
    if (k & 1) {
      upsample_rows_to(k / 2 + 2);
      row = xrows + ((k / 2 + 2) & 3) * hw;
    } else {
      upsample_rows_to(k / 2 + 3);  // sample rows y0 - 2 + k/2 .. + 3
      const float *a = xrows + ((k / 2) & 3) * hw, *b = xrows + ((k / 2 + 1) & 3) * hw;
      const float *c = xrows + ((k / 2 + 2) & 3) * hw, *d = xrows + ((k / 2 + 3) & 3) * hw;
      float* out = even + ((k / 2) & 1) * hw;
      upsample_between(a, b, c, d, hw, out);
      row = out;
    }
    half[0] = half[1], half[1] = half[2], half[2] = row;
    if (k < 2) continue;
    float* dst = L.normal.data() + 2 * size_t(((hy0 + k - 1) % m + m) % m * m);
    slopes(half[0] + 1, half[1] + 1, half[2] + 1, run1, inv_g, dst + 2 * tx0);
    slopes(half[0] + 1 + run1, half[1] + 1 + run1, half[2] + 1 + run1, texels - run1, inv_g, dst);
  }
}

void Clipmap::compute_tiles(int level, const Rect& r) {
  Level& L = levels_[size_t(level)];
  const Rect clip{L.clip_x0, L.clip_y0, n_, n_};
  const Rect in = intersect(r, clip);
  if (in.width == 0 || in.height == 0) return;
  const int64_t tx0 = floor_div(in.x0, kTile), tx1 = floor_div(in.x0 + in.width - 1, kTile);
  const int64_t ty0 = floor_div(in.y0, kTile), ty1 = floor_div(in.y0 + in.height - 1, kTile);
  // Level columns the tiles span (clip region only): per column the range over a tile row's rows,
  // then per tile the range over its columns.
  const int64_t colx0 = std::max(tx0 * kTile, clip.x0), colx1 = std::min((tx1 + 1) * kTile, clip.x0 + n_);
  const int64_t cols = colx1 - colx0;
  float* lo = rows_.data();
  float* hi = lo + cols;
  // The columns are inside the clip region: two runs of the storage, the same for every row.
  const RowRuns runs(n_, colx0, cols);
  for (int64_t ty = ty0; ty <= ty1; ++ty) {
    const int64_t y0 = std::max(ty * kTile, clip.y0), y1 = std::min((ty + 1) * kTile, clip.y0 + n_);
    std::fill_n(lo, cols, std::numeric_limits<float>::infinity());
    std::fill_n(hi, cols, -std::numeric_limits<float>::infinity());
    for (int64_t y = y0; y < y1; ++y) {
      const float* z = L.z.data() + wrap(y) * n_;
      const float* zc = L.zc.data() + wrap(y) * n_;
      accumulate_range(z + runs.start, zc + runs.start, runs.run1, lo, hi);
      accumulate_range(z, zc, cols - runs.run1, lo + runs.run1, hi + runs.run1);
    }
    for (int64_t tx = tx0; tx <= tx1; ++tx) {
      const int64_t a = std::max(tx * kTile, colx0) - colx0, b = std::min((tx + 1) * kTile, colx1) - colx0;
      float tlo = lo[a], thi = hi[a];
      for (int64_t i = a + 1; i < b; ++i) tlo = std::min(tlo, lo[i]), thi = std::max(thi, hi[i]);
      const int64_t wt = ((tx % tiles_) + tiles_) % tiles_, ht = ((ty % tiles_) + tiles_) % tiles_;
      L.tile_range[size_t(ht * tiles_ + wt)] = ZRange{tlo, thi};
    }
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
  FillSplit split;
  for (const Rect& r : rects) {
    fill_rect(level, r, split);
    stats.samples_filled += r.width * r.height;
  }
  ClipmapUpdateStats::Level& mine = stats.per_level[size_t(level)];
  mine.seconds_fill = since(t0);
  mine.seconds_upsample = split.upsample;
  mine.seconds_residual = split.residual;
  stats.seconds_fill += mine.seconds_fill;
  stats.seconds_upsample += split.upsample;
  stats.seconds_residual += split.residual;
  for (const Rect& r : rects) mine.samples_filled += r.width * r.height;
  t0 = Clock::now();
  for (const Rect& r : rects) compute_coarse(level, r);
  mine.seconds_coarse = since(t0);
  stats.seconds_coarse += mine.seconds_coarse;
  t0 = Clock::now();
  // A sample's texels depend on the samples within 2 of it (U's support), clamped to the clip
  // region: recompute a 2-sample ring around the new samples, and the 2-sample band along the clip
  // border, where the clamp now reaches other samples than before (less what the rings cover).
  const size_t new_rects = rects.size();
  std::array<Rect, 2> rings;
  for (size_t i = 0; i < new_rects; ++i) rings[i] = intersect(dilate(rects[i], 2), clip);
  std::array<Rect, 4> bands = {Rect{x0, y0, n_, 2}, Rect{x0, y0 + n_ - 2, n_, 2}, Rect{x0, y0 + 2, 2, n_ - 4},
                               Rect{x0 + n_ - 2, y0 + 2, 2, n_ - 4}};
  for (Rect& b : bands)
    for (size_t i = 0; i < new_rects; ++i) b = trim(b, rings[i]);
  for (size_t i = 0; i < new_rects; ++i) compute_normals(level, rings[i]);
  if (!full)
    for (const Rect& b : bands) compute_normals(level, b);
  mine.seconds_normals = since(t0);
  stats.seconds_normals += mine.seconds_normals;
  t0 = Clock::now();
  for (const Rect& r : rects) compute_tiles(level, r);
  // Tiles straddling the clip border lost or gained samples where the region moved away: refresh
  // the border tiles so that the ranges equal those of a clipmap filled from scratch (those of the
  // new samples' tiles are fresh already).
  if (!full) {
    for (Rect b : {Rect{x0, y0, n_, kTile}, Rect{x0, y0 + n_ - kTile, n_, kTile}, Rect{x0, y0, kTile, n_},
                   Rect{x0 + n_ - kTile, y0, kTile, n_}}) {
      for (size_t i = 0; i < new_rects; ++i) b = trim(b, rects[i]);
      compute_tiles(level, b);
    }
  }
  mine.seconds_bounds = since(t0);
  stats.seconds_bounds += mine.seconds_bounds;
  // Normals changed on the ring and on the clip border too: report them for upload.
  if (!full) {
    for (size_t i = 0; i < new_rects; ++i) rects[i] = rings[i];
    for (const Rect& b : bands)
      if (b.width > 0 && b.height > 0) rects.push_back(b);
  }
}

float Clipmap::level_height_at(int level, double gx, double gy) const {
  const Level& L = lv(level);
  const double fx = std::floor(gx), fy = std::floor(gy);
  const int64_t x = std::min(int64_t(fx), L.clip_x0 + n_ - 2), y = std::min(int64_t(fy), L.clip_y0 + n_ - 2);
  const double tx = gx - double(x), ty = gy - double(y);
  const double a = L.z[index(x, y)], b = L.z[index(x + 1, y)], c = L.z[index(x, y + 1)],
               d = L.z[index(x + 1, y + 1)];
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
  const LevelRegion in =
      intersect(r, LevelRegion{L.clip_x0, L.clip_y0, L.clip_x0 + n_ - 1, L.clip_y0 + n_ - 1});
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
          l == 0 || (levels_[size_t(l) - 1].has_data &&
                     levels_[size_t(l) - 1].clip_x0 == levels_[size_t(l) - 1].desired.x0 &&
                     levels_[size_t(l) - 1].clip_y0 == levels_[size_t(l) - 1].desired.y0);
      const int64_t cost = exposed_samples(L, L.desired.x0, L.desired.y0);
      // The first refill of an update always goes ahead (at most n^2), so the clipmap makes progress
      // even with a budget below n^2; after that the budget is a hard limit.
      if (!coarser_current || (spent > 0 && spent + cost > budget_)) {
        blocked = true;
      } else {
        try {
          refill(l, L.desired.x0, L.desired.y0, stats);
        } catch (...) {
          // refill records the new clip region before filling it, and the toroidal storage now holds
          // parts of the old and the new one: the level has no usable data. Its next update refills
          // it whole; the finer levels wait for it (their own data stays valid).
          L.has_data = false;
          L.dirty.clear();
          crop_active_regions();
          throw;
        }
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
