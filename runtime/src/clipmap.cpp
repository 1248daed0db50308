// Geometry clipmap update: desired regions, budgeted coarse-to-fine toroidal refill, zc, slopes,
// tile z ranges, level switching by viewer height and active-region cropping (L&H 2004 §4-6.1).
#include "runtime/clipmap.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "core/clones.h"
#include "pyramid/downsample.h"
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
TERRAIN_TARGET_CLONES("avx2", "default") void upsample_row(const float* z, int64_t pairs, float* row) {
  for (int64_t k = 0; k < pairs; ++k) {
    row[2 * k] = kU9 * (z[k + 1] + z[k + 2]) - kU1 * (z[k] + z[k + 3]);
    row[2 * k + 1] = z[k + 2];
  }
}

// The half row between sample rows b and c (a and d the outer taps).
TERRAIN_TARGET_CLONES("avx2", "default")
void upsample_between(const float* a, const float* b, const float* c, const float* d, int64_t count,
                      float* out) {
  for (int64_t i = 0; i < count; ++i) out[i] = kU9 * (b[i] + c[i]) - kU1 * (a[i] + d[i]);
}

// Texels (dz/dx, dz/dy) at half positions c[0 .. count): differences one sample (two half steps)
// apart along the row and across the rows above and below.
TERRAIN_TARGET_CLONES("avx2", "default")
void slopes(const float* above, const float* c, const float* below, int64_t count, float inv_g, float* dst) {
  for (int64_t i = 0; i < count; ++i) {
    dst[2 * i] = (c[i + 1] - c[i - 1]) * inv_g;
    dst[2 * i + 1] = (below[i] - above[i]) * inv_g;
  }
}

// Per-column range of z and zc over one more row (min/max: exact, the same in both clones).
TERRAIN_TARGET_CLONES("avx2", "default")
void accumulate_range(const float* z, const float* zc, int64_t count, float* lo, float* hi) {
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
  budget_ms_ = options.budget_ms > 0 && std::isfinite(options.budget_ms) ? options.budget_ms : 0;
  set_budget(options.budget);
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

void Clipmap::set_budget(int64_t samples) {
  budget_request_ = samples;
  budget_ = samples > 0      ? samples
            : budget_ms_ > 0 ? std::numeric_limits<int64_t>::max() / 4
                             : int64_t(n_) * n_;
}

void Clipmap::set_budget_ms(double ms) {
  budget_ms_ = ms > 0 && std::isfinite(ms) ? ms : 0;
  set_budget(budget_request_);
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
  L.filling = false;
  // Invalidated samples that left the clip region need no refill any more; new ones come fresh.
  const Rect new_clip{x0, y0, n_, n_};
  std::vector<Rect> still;
  for (const Rect& r : L.invalid)
    if (const Rect in = intersect(r, new_clip); in.width > 0 && in.height > 0) still.push_back(in);
  L.invalid = std::move(still);
  if (full) L.invalid.clear();
  // The newly exposed L-shape as two rectangles: whole-height columns, then rows over the rest.
  std::vector<Rect> rects;
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
  const double seconds_fill = since(t0);
  t0 = Clock::now();
  for (const Rect& r : rects) compute_coarse(level, r);
  const double seconds_coarse = since(t0);
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
  const double seconds_normals = since(t0);
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
  add_times(level, seconds_fill, split, seconds_coarse, seconds_normals, since(t0), 0, stats);
  // Normals changed on the ring and on the clip border too: report them for upload.
  if (!full) {
    for (size_t i = 0; i < new_rects; ++i) rects[i] = rings[i];
    for (const Rect& b : bands)
      if (b.width > 0 && b.height > 0) rects.push_back(b);
  }
  L.dirty.insert(L.dirty.end(), rects.begin(), rects.end());
}

void Clipmap::add_times(int level, double fill, const FillSplit& split, double coarse, double normals,
                        double bounds, int64_t samples, ClipmapUpdateStats& stats) {
  ClipmapUpdateStats::Level& mine = stats.per_level[size_t(level)];
  mine.seconds_fill += fill;
  mine.seconds_upsample += split.upsample;
  mine.seconds_residual += split.residual;
  mine.seconds_coarse += coarse;
  mine.seconds_normals += normals;
  mine.seconds_bounds += bounds;
  mine.samples_filled += samples;
  stats.seconds_fill += fill;
  stats.seconds_upsample += split.upsample;
  stats.seconds_residual += split.residual;
  stats.seconds_coarse += coarse;
  stats.seconds_normals += normals;
  stats.seconds_bounds += bounds;
}

bool Clipmap::coarser_covers(int level, int64_t x0, int64_t y0, int64_t x1, int64_t y1) const {
  if (level == 0) return true;
  const Level& C = levels_[size_t(level) - 1];
  if (!C.has_data || C.filling) return false;
  // U reads coarse samples floor(x/2) - 1 .. floor(x/2) + 2, zc floor(x/2) .. floor(x/2) + 1.
  return (x0 >> 1) - 1 >= C.clip_x0 && (x1 >> 1) + 2 <= C.clip_x0 + n_ - 1 && (y0 >> 1) - 1 >= C.clip_y0 &&
         (y1 >> 1) + 2 <= C.clip_y0 + n_ - 1;
}

void Clipmap::fill_strip(int level, int64_t rows, ClipmapUpdateStats& stats) {
  Level& L = levels_[size_t(level)];
  const int64_t r0 = L.rows_done, r1 = std::min<int64_t>(n_, r0 + rows);
  const Rect strip{L.clip_x0, L.clip_y0 + r0, n_, r1 - r0};
  auto t0 = Clock::now();
  FillSplit split;
  fill_rect(level, strip, split);
  stats.samples_filled += strip.width * strip.height;
  const double seconds_fill = since(t0);
  t0 = Clock::now();
  compute_coarse(level, strip);
  const double seconds_coarse = since(t0);
  // A sample's texels need the samples within 2 rows: rows up to r1 - 3 are final now, the last
  // strip finishes the rest (compute_normals clamps to the clip region, as a whole fill does).
  t0 = Clock::now();
  const int64_t a = std::max<int64_t>(r0 - 2, 0), b = r1 == n_ ? n_ : r1 - 2;
  compute_normals(level, Rect{L.clip_x0, L.clip_y0 + a, n_, b - a});
  const double seconds_normals = since(t0);
  t0 = Clock::now();
  L.rows_done = r1;
  if (r1 == n_) {
    compute_tiles(level, Rect{L.clip_x0, L.clip_y0, n_, n_});
    L.filling = false;
    L.has_data = true;
    L.dirty.assign(1, Rect{L.clip_x0, L.clip_y0, n_, n_});
  }
  add_times(level, seconds_fill, split, seconds_coarse, seconds_normals, since(t0),
            strip.width * strip.height, stats);
}

void Clipmap::refill_invalid(int level, const Rect& r, ClipmapUpdateStats& stats) {
  Level& L = levels_[size_t(level)];
  const Rect clip{L.clip_x0, L.clip_y0, n_, n_};
  auto t0 = Clock::now();
  FillSplit split;
  fill_rect(level, r, split);
  stats.samples_filled += r.width * r.height;
  const double seconds_fill = since(t0);
  t0 = Clock::now();
  compute_coarse(level, r);
  const double seconds_coarse = since(t0);
  t0 = Clock::now();
  const Rect ring = intersect(dilate(r, 2), clip);  // texels within U's reach of the new samples
  compute_normals(level, ring);
  const double seconds_normals = since(t0);
  t0 = Clock::now();
  compute_tiles(level, r);
  L.dirty.push_back(ring);
  add_times(level, seconds_fill, split, seconds_coarse, seconds_normals, since(t0), r.width * r.height,
            stats);
}

Clipmap::Piece Clipmap::plan_piece(int level, int64_t lines) const {
  const Level& L = levels_[size_t(level)];
  Piece p;
  auto fresh = [&] {
    p.kind = Piece::StartFill;
    p.x0 = L.desired.x0;
    p.y0 = L.desired.y0;
    p.rows = std::min<int64_t>(lines, n_);
    p.samples = int64_t(n_) * p.rows;
    return p;
  };
  if (L.filling) {
    // Carry on with the fresh fill unless the viewer has gone far from it or the coarser level no
    // longer covers it (its zc and U would read clamped coarse samples).
    const bool far =
        std::abs(L.desired.x0 - L.clip_x0) >= n_ / 2 || std::abs(L.desired.y0 - L.clip_y0) >= n_ / 2;
    if (far || !coarser_covers(level, L.clip_x0, L.clip_y0, L.clip_x0 + n_ - 1, L.clip_y0 + n_ - 1))
      return fresh();
    p.kind = Piece::Strip;
    p.rows = std::min<int64_t>(lines, n_ - L.rows_done);
    p.samples = int64_t(n_) * p.rows;
    return p;
  }
  if (!at_desired(L)) {
    const int64_t dx = L.desired.x0 - L.clip_x0, dy = L.desired.y0 - L.clip_y0;
    if (!L.has_data || std::abs(dx) >= n_ || std::abs(dy) >= n_) return fresh();
    // Every intermediate clip region lies in the box of the old and the new one.
    const int64_t bx0 = std::min(L.clip_x0, L.desired.x0), by0 = std::min(L.clip_y0, L.desired.y0);
    if (!coarser_covers(level, bx0, by0, bx0 + n_ - 1 + std::abs(dx), by0 + n_ - 1 + std::abs(dy)))
      return fresh();
    p.kind = Piece::Move;
    // Both axes in one piece (one L-shape, one pass over the clip border), lines even.
    const int64_t step = std::max<int64_t>(2, lines & ~int64_t(1));
    const int64_t sx = std::clamp<int64_t>(dx, -step, step), sy = std::clamp<int64_t>(dy, -step, step);
    p.x0 = L.clip_x0 + sx;
    p.y0 = L.clip_y0 + sy;
    p.samples = std::abs(sx) * n_ + std::abs(sy) * (n_ - std::abs(sx));
    return p;
  }
  if (!L.invalid.empty()) {
    const Rect& r = L.invalid.front();
    p.kind = Piece::Invalid;
    p.rect =
        Rect{r.x0, r.y0, r.width,
             std::min<int64_t>(r.height, std::max<int64_t>(1, lines * n_ / std::max<int64_t>(r.width, 1)))};
    p.samples = p.rect.width * p.rect.height;
  }
  return p;
}

void Clipmap::run_piece(int level, const Piece& p, ClipmapUpdateStats& stats) {
  Level& L = levels_[size_t(level)];
  switch (p.kind) {
    case Piece::StartFill:
      L.filling = true;
      L.has_data = false;
      L.clip_x0 = p.x0;
      L.clip_y0 = p.y0;
      L.rows_done = 0;
      L.invalid.clear();
      L.dirty.clear();
      fill_strip(level, p.rows, stats);
      break;
    case Piece::Strip:
      fill_strip(level, p.rows, stats);
      break;
    case Piece::Move:
      refill(level, p.x0, p.y0, stats);
      break;
    case Piece::Invalid: {
      refill_invalid(level, p.rect, stats);
      Rect& r = L.invalid.front();
      r.y0 += p.rect.height;
      r.height -= p.rect.height;
      if (r.height <= 0) L.invalid.erase(L.invalid.begin());
      break;
    }
    case Piece::None:
      break;
  }
}

void Clipmap::invalidate(const Rect& finest, int64_t align) {
  if (align < 1) align = 1;
  if (finest.width <= 0 || finest.height <= 0) return;
  const int levels = level_count();
  // Inclusive bounds per level: down from the finest by D's reach (coarse i reads fine 2i - 5 ..
  // 2i + 5), then up again by U's (fine x reads coarse floor(x/2) - 1 .. floor(x/2) + 2) and zc's.
  std::vector<std::array<int64_t, 4>> b(static_cast<size_t>(levels));
  b[size_t(levels) - 1] = {finest.x0, finest.y0, finest.x0 + finest.width - 1, finest.y0 + finest.height - 1};
  const int64_t r = terrain::DownsampleFilter::kRadius;
  auto down_lo = [&](int64_t v) { return -floor_div(-(v - r), 2); };  // ceil((v - r) / 2)
  auto down_hi = [&](int64_t v) { return floor_div(v + r, 2); };
  for (int l = levels - 2; l >= 0; --l) {
    const auto& f = b[size_t(l) + 1];
    b[size_t(l)] = {down_lo(f[0]), down_lo(f[1]), down_hi(f[2]), down_hi(f[3])};
  }
  // Upwards, each level grown outwards to whole `align` tiles first (a re-coded tile changes all of
  // its samples), which U then carries to the finer level.
  for (int l = 0; l < levels; ++l) {
    auto& m = b[size_t(l)];
    if (l > 0) {
      const auto& c = b[size_t(l) - 1];
      m = {std::min(m[0], 2 * c[0] - 4), std::min(m[1], 2 * c[1] - 4), std::max(m[2], 2 * c[2] + 4),
           std::max(m[3], 2 * c[3] + 4)};
    }
    m = {floor_div(m[0], align) * align, floor_div(m[1], align) * align,
         (floor_div(m[2], align) + 1) * align - 1, (floor_div(m[3], align) + 1) * align - 1};
  }
  for (int l = 0; l < levels; ++l) {
    Level& L = levels_[size_t(l)];
    const auto& m = b[size_t(l)];
    if (L.filling) {
      L.rows_done = 0;  // the strips done so far may hold old samples: start again
      continue;
    }
    if (!L.has_data) continue;
    const Rect in =
        intersect(Rect{m[0], m[1], m[2] - m[0] + 1, m[3] - m[1] + 1}, Rect{L.clip_x0, L.clip_y0, n_, n_});
    if (in.width > 0 && in.height > 0) L.invalid.push_back(in);
  }
}

int64_t Clipmap::invalid_samples(int level) const {
  int64_t s = 0;
  for (const Rect& r : lv(level).invalid) s += r.width * r.height;
  return s;
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
  const auto t_start = Clock::now();
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
    // Coarse to fine: a level refines the coarser one as this clipmap holds it, so it waits until
    // that one is complete (at its desired region, nothing invalidated pending).
    if (!blocked && l > 0 && !ready(levels_[size_t(l) - 1])) blocked = true;
    try {
      if (!blocked && budget_ms_ > 0) {
        // Pieces until the level is ready or the next piece would pass the time (or sample) budget;
        // the update's first piece always goes ahead, so the clipmap makes progress.
        const Rect start_clip{L.clip_x0, L.clip_y0, n_, n_};
        const bool start_data = L.has_data;
        int moves = 0;
        bool fresh = false;
        size_t move_rects = 0;
        for (Piece p = plan_piece(l, kPiece); p.kind != Piece::None; p = plan_piece(l, kPiece)) {
          // A move also redoes the clip border's normals and tiles: about 8 n samples' worth.
          const double overhead = p.kind == Piece::Move ? 8.0 * n_ : 0.0;
          // A kind of piece not timed yet takes the dearest estimate there is.
          const double per = seconds_per_sample_[p.kind] > 0
                                 ? seconds_per_sample_[p.kind]
                                 : *std::max_element(seconds_per_sample_.begin(), seconds_per_sample_.end());
          // Thinner pieces when the time left is short, the update's first one too (at a budget of
          // half a millisecond one full piece of n = 511 is the whole budget); stop when not even the
          // thinnest fits, except for the first piece, which always runs, so the clipmap progresses.
          if (per > 0) {
            const double left = budget_ms_ * 1e-3 - since(t_start);
            const int64_t lines = std::clamp<int64_t>(int64_t((left / per - overhead) / n_), 1, kPiece);
            if (lines < kPiece) p = plan_piece(l, lines);
          }
          if (stats.pieces > 0) {
            const double predicted = since(t_start) + (double(p.samples) + overhead) * per;
            if (predicted > budget_ms_ * 1e-3 || spent + p.samples > budget_) {
              stats.out_of_time = predicted > budget_ms_ * 1e-3;
              blocked = true;
              break;
            }
          }
          const auto t0 = Clock::now();
          run_piece(l, p, stats);
          const double dt = since(t0);
          // Seconds per sample, smoothed over the recent pieces (the prediction of the next one).
          const double sps = dt / (double(p.samples) + overhead);
          double& e = seconds_per_sample_[p.kind];
          e = e > 0 ? 0.75 * e + 0.25 * sps : sps;
          spent += p.samples;
          ++stats.pieces;
          if (p.kind == Piece::Move) ++moves, move_rects = L.dirty.size();
          if (p.kind == Piece::StartFill) fresh = true;
        }
        if (moves > 0) ++stats.levels_updated;
        if (moves >= 2 && start_data && !fresh) {
          // Several moves: report the samples gained since the update began, as one move would
          // (the renderer checks the dirty rectangles against the region it last uploaded).
          const Rect now{L.clip_x0, L.clip_y0, n_, n_};
          const int64_t dx = now.x0 - start_clip.x0, dy = now.y0 - start_clip.y0;
          std::vector<Rect> rects;
          if (dx != 0)
            rects.push_back(intersect(
                dilate(Rect{dx > 0 ? start_clip.x0 + n_ : now.x0, now.y0, std::abs(dx), n_}, 2), now));
          if (dy != 0)
            rects.push_back(
                intersect(dilate(Rect{std::max(now.x0, start_clip.x0), dy > 0 ? start_clip.y0 + n_ : now.y0,
                                      n_ - std::abs(dx), std::abs(dy)},
                                 2),
                          now));
          for (const Rect& b : {Rect{now.x0, now.y0, n_, 2}, Rect{now.x0, now.y0 + n_ - 2, n_, 2},
                                Rect{now.x0, now.y0, 2, n_}, Rect{now.x0 + n_ - 2, now.y0, 2, n_}})
            rects.push_back(b);
          rects.insert(rects.end(), L.dirty.begin() + std::ptrdiff_t(move_rects), L.dirty.end());
          L.dirty = std::move(rects);
        }
        if (!ready(L)) blocked = true;
      } else if (!blocked) {
        if (!at_desired(L)) {
          const int64_t cost = exposed_samples(L, L.desired.x0, L.desired.y0);
          // The first refill of an update always goes ahead (at most n^2), so the clipmap makes
          // progress even with a budget below n^2; after that the budget is a hard limit.
          if (spent > 0 && spent + cost > budget_) {
            blocked = true;
          } else {
            refill(l, L.desired.x0, L.desired.y0, stats);
            spent += cost;
            ++stats.levels_updated;
            ++stats.pieces;
          }
        }
        while (!blocked && at_desired(L) && !L.invalid.empty()) {
          const Rect r = L.invalid.front();
          if (spent > 0 && spent + r.width * r.height > budget_) {
            blocked = true;
          } else {
            refill_invalid(l, r, stats);
            L.invalid.erase(L.invalid.begin());
            spent += r.width * r.height;
            ++stats.pieces;
          }
        }
      }
    } catch (...) {
      // refill records the new clip region before filling it, and the toroidal storage now holds
      // parts of the old and the new one: the level has no usable data. Its next update refills
      // it whole; the finer levels wait for it (their own data stays valid).
      L.has_data = false;
      L.filling = false;
      L.invalid.clear();
      L.dirty.clear();
      crop_active_regions();
      throw;
    }
    if (!ready(L)) ++stats.levels_behind;
  }
  crop_active_regions();
  for (const Level& L : levels_) stats.active_levels += L.active.empty() ? 0 : 1;
  return stats;
}

}  // namespace terrain::runtime
