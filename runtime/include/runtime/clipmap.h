// The geometry clipmap of Losasso & Hoppe 2004 (sections 3-6), CPU side: L nested levels of n x n
// height samples centred on the viewer, stored toroidally and refilled incrementally as it moves.
//
// Coordinates. Clipmap level 0 is the coarsest, level L-1 the finest; level l holds pyramid level
// source_level(l) = P - L + l of a HeightSource with P levels. Each level has its own integer grid:
// level l sample (i, j) sits on level l+1 sample (2i, 2j), and at world position (i, j) * spacing(l)
// metres (x along columns, y along rows; the finest level's spacing is the source's). Heights are
// metres.
//
// Regions (all in the level's own grid): the clip region is the n x n block of samples stored;
// the desired region is the n x n square of vertices centred on the viewer, its corners on even
// coordinates (so its perimeter lies on vertices of the coarser level); the active region is the
// desired region cropped to the clip region and to the coarser active region eroded by 2 of the
// coarser level's units (paper §5 constraints 2-4, §6.1). render region(l) = active(l) - active(l+1).
//
// Update (paper §5): levels are refilled coarse to fine, only the newly exposed L-shaped part of
// each clip region. Filling from RegionDecoderSource is the paper's "upsample the coarser level with
// U and add the decoded residual": decode_units(level, rect) computes exactly U(T^_{level-1}) + R^.
// A per-frame budget of samples stops the update; finer levels then keep their old clip regions and
// their active regions are cropped to them (they shrink until empty while the viewer outruns them).
// Levels whose grid spacing is too fine for the viewer's height above the terrain are switched off
// (paper §4: active region empty when height > 0.4 n g_l).
//
// Each level also keeps, per sample: zc, the coarser level's surface at that vertex (for the
// transition morph), a normal map at twice the geometry's resolution (paper §3: one normal per
// vertex is too blurry) holding the slopes dz/dx, dz/dy of the level upsampled by the pyramid's
// four-point U, and per 8 x 8 tile the z range of z and zc (for view-frustum culling).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "pyramid/pyramid.h"
#include "readers/heightmap.h"

namespace terrain::runtime {

class RegionDecoder;

// Integer units of one level held by the caller (the clipmap) in toroidal storage: sample (x, y) of
// `region` lives at data[wrap(y) * n + wrap(x)], wrap(v) = v mod n in 0..n-1.
struct HeldUnits {
  const int32_t* data = nullptr;
  int64_t n = 0;
  Rect region;
};

// Where the time of a fill went, for sources that can say (seconds, added to).
struct FillSplit {
  double upsample = 0;  // U of the coarser level
  double residual = 0;  // the residual: entropy decode (or tile cache) and the addition
};

// Where the clipmap gets its heights from: one grid per pyramid level, level 0 coarsest, level l
// sample i on level l+1 sample 2i.
class HeightSource {
 public:
  virtual ~HeightSource() = default;
  virtual int level_count() const = 0;
  virtual GridSize level_size(int level) const = 0;
  // Horizontal spacing of the finest level, metres.
  virtual double spacing_m() const = 0;
  // Heights (metres) of `level` on `rect`, which may reach beyond the level: such samples repeat
  // the nearest edge sample (a bounded terrain seen from outside is a flat apron). Not thread-safe.
  virtual void fill(int level, const Rect& rect, float* out, int64_t out_stride) = 0;

  // Sources whose levels are integer grids related by level = U(coarser level) + residual (the
  // compressed pyramid) say so here and implement fill_units; the clipmap then keeps each level's
  // units and refines the finer level from them instead of having the source rebuild it.
  virtual bool refines_units() const { return false; }
  // fill(), also writing the level's integer units at the same positions (units_out, stride
  // out_stride; edge samples repeat beyond the level like the heights). `coarser`, when not null,
  // holds units of level - 1 as this source gives them; where it covers the window U needs, only
  // the residual is decoded (split, when not null, receives the time of U and of the residual).
  // Either way the output equals what fill() writes.
  virtual void fill_units(int level, const Rect& rect, const HeldUnits* coarser, float* out,
                          int32_t* units_out, int64_t out_stride, FillSplit* split);
};

// A compressed pyramid file through the region decoder. Voids (NaN) come out as 0 m.
class RegionDecoderSource final : public HeightSource {
 public:
  // spacing_m: finest-level horizontal spacing in metres (arc-second data: the caller converts).
  RegionDecoderSource(std::shared_ptr<const RegionDecoder> decoder, double spacing_m);
  int level_count() const override;
  GridSize level_size(int level) const override;
  double spacing_m() const override { return spacing_m_; }
  void fill(int level, const Rect& rect, float* out, int64_t out_stride) override;
  bool refines_units() const override { return true; }
  void fill_units(int level, const Rect& rect, const HeldUnits* coarser, float* out, int32_t* units_out,
                  int64_t out_stride, FillSplit* split) override;

 private:
  std::shared_ptr<const RegionDecoder> decoder_;
  double spacing_m_;
  std::vector<int32_t> units_, window_;  // the decoded part of the level; the coarser window gathered for U
  std::vector<uint8_t> valid_;           // void mask rows of the finest level
};

// Heights from a function of (level, x, y); `unbounded` lets the function be evaluated anywhere
// (tests, synthetic worlds), otherwise samples outside level_size repeat the edge like any source.
class FunctionHeightSource final : public HeightSource {
 public:
  using Function = std::function<float(int level, int64_t x, int64_t y)>;
  FunctionHeightSource(int levels, GridSize finest, double spacing_m, Function f, bool unbounded);
  int level_count() const override { return levels_; }
  GridSize level_size(int level) const override;
  double spacing_m() const override { return spacing_m_; }
  void fill(int level, const Rect& rect, float* out, int64_t out_stride) override;
  int64_t calls() const { return samples_; }  // samples evaluated so far

 private:
  int levels_;
  GridSize finest_;
  double spacing_m_;
  Function f_;
  bool unbounded_;
  int64_t samples_ = 0;
};

// Heights held in memory, one grid per level in metres, level 0 coarsest (sizes halve as in the
// pyramid); outside a level the nearest edge sample repeats, like every source. The verification
// reference: the original input's lossless pyramid (original_source), rendered beside the
// compressed one.
class GridHeightSource final : public HeightSource {
 public:
  // levels[l] holds sizes[l].width * sizes[l].height samples, row-major. Throws
  // std::invalid_argument on mismatched sizes or a non-positive spacing.
  GridHeightSource(std::vector<GridSize> sizes, std::vector<std::vector<float>> levels, double spacing_m);
  int level_count() const override { return int(sizes_.size()); }
  GridSize level_size(int level) const override { return sizes_.at(size_t(level)); }
  double spacing_m() const override { return spacing_m_; }
  void fill(int level, const Rect& rect, float* out, int64_t out_stride) override;
  const std::vector<float>& level(int level) const { return levels_.at(size_t(level)); }
  // Validity of the finest level's samples (1 = data); empty when all are valid.
  std::vector<uint8_t> finest_valid;

 private:
  std::vector<GridSize> sizes_;
  std::vector<std::vector<float>> levels_;
  double spacing_m_;
};

// The original (uncompressed) heightmap `input`, in any format libpyramid reads, as a lossless
// pyramid with the level count and the D filter of a compressed pyramid: level l is then the
// exact T_l that the compressed file approximates by T^_l. Voids come out as 0 m (as from
// RegionDecoderSource) and are flagged in finest_valid. Throws Error naming the file, or
// std::invalid_argument when the input's size differs from `finest` (not the pyramid's input).
GridHeightSource original_source(const std::string& input, const ReadOptions& read_options, GridSize finest,
                                 int level_count, const std::vector<double>& filter_11x11, double spacing_m);

// Screen-space geometric error of one rendered level against the finest original data (L&H 2004
// §9, Table 2): e_l = PL(T^_l) - T_m at every finest-level sample (PL: the renderer's
// triangulation), projected as e_l * s / g_l pixels, s = the screen-space size of a grid cell.
struct LevelScreenError {
  int level = 0;                // source level (0 coarsest)
  double spacing_m = 0;         // g_l
  double rms_m = 0, max_m = 0;  // |e_l| in metres
  double rms_px = 0, p999_px = 0, max_px = 0;
};
// s (pixels per grid cell at the average ring depth 0.4 n g_l, L&H 2004 §4):
// 1.25 W / (n tan(phi/2)), W the frame width and phi the horizontal field of view.
double triangle_size_px(int width, int height, double fov_y_deg, int n);
// Levels first_level..finest of `rendered` (the heights the clipmap draws) against `original`'s
// finest level (same finest size); only samples valid in original.finest_valid count.
std::vector<LevelScreenError> screen_space_error(HeightSource& rendered, const GridHeightSource& original,
                                                 int first_level, double s_px);
// The same analysis without the original: `source`'s own finest level stands in for the truth, so
// the figures leave out the finest level's compression error (level l's error against the data is at
// most this plus that). Over the whole finest level when it has at most max_samples samples,
// otherwise over a grid of 256x256 windows spread evenly over it, max_samples in all.
std::vector<LevelScreenError> estimate_screen_space_error(HeightSource& source, int first_level, double s_px,
                                                          int64_t max_samples = int64_t(1) << 22);
// Makes such an estimate an upper bound of the figures against the data, given how far the finest
// level is from the data (rms and max |T^_m - T_m| in metres, e.g. the builder's figures the .pyr
// records): the true error is the estimate's plus that difference, so on the same samples rms grows
// by at most finest_rms_m (triangle inequality), p99.9 and max by at most finest_max_m; in pixels
// each times s_px / g_l.
void add_finest_error_bound(std::vector<LevelScreenError>& errors, double finest_rms_m, double finest_max_m,
                            double s_px);

// The smallest clipmap size n = 2^k - 1 (15..1023) whose worst level's p99.9 screen-space error is at
// most tolerance_px, from `errors` computed at triangle size s_px (errors scale with s, s with 1/n;
// L&H 2004 §9 suggest sizing the clipmap by the terrain's error). met = false: even n = 1023 exceeds it.
struct ClipmapSizeChoice {
  int n = 0;
  double p999_px = 0;  // the worst level's p99.9 at that n
  bool met = false;
};
ClipmapSizeChoice clipmap_size_for_screen_error(const std::vector<LevelScreenError>& errors, double s_px,
                                                int width, int height, double fov_y_deg, double tolerance_px);

// Inclusive vertex bounds on a level's grid; empty when x1 < x0 or y1 < y0.
struct LevelRegion {
  int64_t x0 = 0, y0 = 0, x1 = -1, y1 = -1;
  bool empty() const { return x1 < x0 || y1 < y0; }
  bool operator==(const LevelRegion&) const = default;
};

struct ZRange {
  float lo = 0, hi = 0;
};

struct ClipmapOptions {
  int n = 255;         // samples per level side, 2^k - 1, 15..1023
  int levels = 0;      // 0: as many as the source has
  int64_t budget = 0;  // samples refilled per update; 0: n * n
  bool deactivate_by_height = true;
  double height_factor = 0.4;  // level l off when viewer height above terrain > factor * n * spacing(l)
};
// How many levels a clipmap with these options has over a source of source_levels levels (the
// `levels = 0: all` rule, for callers that size things before constructing one); the Clipmap
// constructor checks the count.
inline int clipmap_level_count(const ClipmapOptions& options, int source_levels) {
  return options.levels == 0 ? source_levels : options.levels;
}

struct ClipmapUpdateStats {
  // seconds_fill: the height source in all, including what it could not split (a recursive region
  // decode when the coarser level is not in the clipmap, edge replication, units to metres) and the
  // copy into the toroidal storage; for a source that refines units (the compressed pyramid) its
  // parts seconds_upsample (U of the clipmap's coarser level) and seconds_residual (residual decode
  // and addition) are also given.
  double seconds_fill = 0;
  double seconds_upsample = 0;
  double seconds_residual = 0;
  double seconds_coarse = 0;   // zc: the coarser level's surface at each new vertex
  double seconds_normals = 0;  // normal map texels of the new samples and their neighbours
  double seconds_bounds = 0;   // per-tile z ranges
  int64_t samples_filled = 0;  // samples taken from the source this update
  int levels_updated = 0;      // levels whose clip region moved
  int levels_behind = 0;       // enabled levels whose clip region still differs from the desired one
  int enabled_levels = 0;      // levels not switched off by height (0 .. L)
  int active_levels = 0;       // levels with a non-empty active region
  double viewer_height = 0;    // viewer height above the terrain used for switching levels, metres
  // The same split per clipmap level (index = level; levels beyond level_count() stay zero).
  struct Level {
    double seconds_fill = 0, seconds_upsample = 0, seconds_residual = 0;
    double seconds_coarse = 0, seconds_normals = 0, seconds_bounds = 0;
    int64_t samples_filled = 0;
  };
  std::array<Level, 32> per_level{};
};

class Clipmap {
 public:
  static constexpr int kTile = 8;  // z-range tiles are kTile x kTile samples, aligned to the level grid

  static constexpr int kMaxLevels = 32;
  // Throws std::invalid_argument for an unusable n (not 2^k - 1 in 15..1023) or level count
  // (1..min(source levels, kMaxLevels)).
  // The source must outlive the clipmap.
  Clipmap(HeightSource& source, const ClipmapOptions& options);

  // Moves the clipmap to a viewer at (x, y, z) metres: desired regions, budgeted coarse-to-fine
  // refill, level switching by height, cropping of the active regions.
  ClipmapUpdateStats update(double x_m, double y_m, double z_m);

  int n() const { return n_; }
  int level_count() const { return int(levels_.size()); }
  int source_level(int level) const { return first_source_level_ + level; }
  double spacing(int level) const;  // metres between samples of `level`
  int64_t budget() const { return budget_; }
  void set_budget(int64_t samples) { budget_ = samples > 0 ? samples : int64_t(n_) * n_; }

  bool has_data(int level) const { return lv(level).has_data; }
  bool enabled(int level) const { return lv(level).enabled; }
  Rect clip_region(int level) const { return Rect{lv(level).clip_x0, lv(level).clip_y0, n_, n_}; }
  LevelRegion desired_region(int level) const { return lv(level).desired; }
  LevelRegion active_region(int level) const { return lv(level).active; }
  // Transition width (level units) for the morph of `level`: min(n/10, room to the finer active
  // region - 2), at least 1, so that alpha is 0 on the finer level's perimeter.
  double transition_width(int level) const { return lv(level).transition_width; }
  // The viewer in the level's grid units (continuous).
  std::array<double, 2> viewer_grid(int level) const;

  // Toroidal storage: sample (x, y) of the clip region lives at index wrap(y) * n + wrap(x).
  int64_t wrap(int64_t v) const { return ((v % n_) + n_) % n_; }
  size_t index(int64_t x, int64_t y) const { return size_t(wrap(y) * n_ + wrap(x)); }
  const float* heights(int level) const { return lv(level).z.data(); }          // n*n toroidal
  const float* coarse_heights(int level) const { return lv(level).zc.data(); }  // n*n toroidal
  // Normal map: 2n x 2n texels of (dz/dx, dz/dy), toroidal like the heights: texel (X, Y), at level
  // position (X / 2, Y / 2), lives at normal_index(X, Y); sample (x, y) owns texels 2x..2x+1, 2y..2y+1.
  const float* normal_map(int level) const { return lv(level).normal.data(); }  // 2 * 4n^2 floats
  size_t normal_index(int64_t X, int64_t Y) const {
    const int64_t m = 2 * int64_t(n_);
    return size_t((((Y % m) + m) % m) * m + (((X % m) + m) % m));
  }
  // Samples (level grid) written by the last update, as rectangles inside the clip region.
  const std::vector<Rect>& dirty_rects(int level) const { return lv(level).dirty; }

  // Range of z and zc over the vertices of `r` (within the clip region), from the tile ranges
  // (conservative: whole tiles). Empty r gives {0, 0}.
  ZRange z_bounds(int level, const LevelRegion& r) const;
  // Terrain height under (x, y) metres from the finest level with data there (bilinear); NaN when
  // no level holds the point.
  float terrain_height_at(double x_m, double y_m) const;

 private:
  struct Level {
    bool has_data = false;
    bool enabled = false;
    int64_t clip_x0 = 0, clip_y0 = 0;
    LevelRegion desired, active;
    double transition_width = 1;
    std::vector<float> z, zc, normal;
    std::vector<int32_t> units;  // the source's integer units of z (sources that refine units only)
    // Toroidal tile table: tile (tx, ty) at wrap_tile(ty) * tiles + wrap_tile(tx).
    std::vector<ZRange> tile_range;
    std::vector<Rect> dirty;
  };
  const Level& lv(int level) const { return levels_.at(size_t(level)); }
  LevelRegion desired_for(int level, double x_m, double y_m) const;
  int64_t exposed_samples(const Level& L, int64_t x0, int64_t y0) const;
  void refill(int level, int64_t x0, int64_t y0, ClipmapUpdateStats& stats);
  void fill_rect(int level, const Rect& r, FillSplit& split);
  void compute_coarse(int level, const Rect& r);
  void compute_normals(int level, const Rect& r);
  void compute_tiles(int level, const Rect& r);
  float level_height_at(int level, double gx, double gy) const;  // bilinear, inside clip region
  void crop_active_regions();

  HeightSource& source_;
  int n_;
  int first_source_level_;
  int64_t budget_;
  ClipmapOptions options_;
  double viewer_[3] = {0, 0, 0};
  int tiles_;  // tile table side
  std::vector<Level> levels_;
  bool refines_units_;          // source_.refines_units(): levels keep their units
  std::vector<float> scratch_;  // fill buffer, reused
  std::vector<int32_t> unit_scratch_;
  // Row buffers of zc, the normal map and the tile ranges, sized once for n-wide rectangles (no
  // allocation per update).
  std::vector<float> rows_;
};

}  // namespace terrain::runtime
