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
// A time budget (budget_ms, the paper's steady frame rate) refills in pieces instead: a level's clip
// region moves towards the desired one by L-shaped strips of at most kPiece columns and rows (each
// piece leaves a whole, valid n x n clip region), a level that must be filled afresh is filled by row strips
// over several updates (without data until the last strip), and the update stops before a piece whose
// predicted time (seconds per sample of the pieces so far) would pass the budget. What a frame gets
// done then depends on the machine's speed: a time budget is not deterministic, the sample budget is.
//
// Edits (invalidate): the samples of every level that an edit of the source's finest level can
// reach (D's reach downwards, U's and zc's upwards) are refilled by later updates, coarse to fine,
// under the same budgets; a level with such samples pending counts as behind.
//
// Each level also keeps, per sample: zc, the coarser level's surface at that vertex (for the
// transition morph), a normal map at twice the geometry's resolution (paper §3: one normal per
// vertex is too blurry) holding the slopes dz/dx, dz/dy of the level upsampled by the pyramid's
// four-point U, and per 8 x 8 tile the z range of z and zc (for view-frustum culling).
//
// Threads: a Clipmap is not thread-safe (update() writes what the accessors read, and drives the
// height source, which is not thread-safe either); the const accessors may be called from several
// threads between updates.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "pyramid/pyramid.h"
#include "runtime/height_source.h"

namespace terrain::runtime {

// Inclusive vertex bounds on a level's grid; empty when x1 < x0 or y1 < y0.
struct LevelRegion {
  int64_t x0 = 0, y0 = 0, x1 = -1, y1 = -1;
  bool empty() const { return x1 < x0 || y1 < y0; }
  bool operator==(const LevelRegion&) const = default;
};

// A range of heights, metres.
struct ZRange {
  float lo = 0, hi = 0;
};

struct ClipmapOptions {
  int n = 255;                       // samples per level side, 2^k - 1, 15..1023
  int levels = 0;                    // 0: as many as the source has
  int64_t budget = 0;                // samples refilled per update; 0: n * n (no limit with budget_ms)
  double budget_ms = 0;              // milliseconds of refill per update (not deterministic); 0: none
  bool deactivate_by_height = true;  // switch off levels too fine for the viewer's height (paper §4)
  double height_factor = 0.4;        // level l off when viewer height above terrain > factor * n * spacing(l)
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
                               // (or that are being filled afresh, or have invalidated samples pending)
  int pieces = 0;              // refill pieces done (one per level refilled without budget_ms)
  bool out_of_time = false;    // budget_ms stopped the update with work left
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
  // Allocates the levels (40 n^2 bytes each, 44 n^2 with units); no data until the first
  // update. Throws std::invalid_argument for an unusable n (not 2^k - 1 in 15..1023), level count
  // (1..min(source levels, kMaxLevels)) or source (no levels, spacing not positive).
  // The source must outlive the clipmap.
  Clipmap(HeightSource& source, const ClipmapOptions& options);

  // Moves the clipmap to a viewer at (x, y, z) metres: desired regions, budgeted coarse-to-fine
  // refill, level switching by height, cropping of the active regions. Throws what the source's
  // fill throws (RegionDecoderSource: Error on damaged data, under DamagePolicy::Throw). The clipmap
  // stays usable: the level whose refill failed has no data (has_data false, its active region and
  // those of the finer levels empty), the coarser levels hold this update's data, and the next
  // update refills that level whole, giving what a fresh clipmap would.
  ClipmapUpdateStats update(double x_m, double y_m, double z_m);

  // The accessors of a level's state (has_data .. dirty_rects, z_bounds) throw std::out_of_range
  // for a level outside 0 .. level_count() - 1.
  int n() const { return n_; }
  int level_count() const { return int(levels_.size()); }
  int source_level(int level) const { return first_source_level_ + level; }
  double spacing(int level) const;            // metres between samples of `level`
  int64_t budget() const { return budget_; }  // samples refilled per update
  // <= 0: n * n, or no limit while a time budget is set.
  void set_budget(int64_t samples);
  double budget_ms() const { return budget_ms_; }
  void set_budget_ms(double ms);     // <= 0 (or not finite): no time budget
  static constexpr int kPiece = 16;  // columns or rows per refill piece under a time budget

  // Marks the samples that a change of the source's finest level inside `finest` (level grid of the
  // finest clipmap level) can have changed on every level: the rect, then per coarser level the
  // samples D reaches (radius 5 on the finer level), and on every level the samples U and zc reach
  // from a changed coarser level; the clip region's part of each is refilled by later updates
  // (coarse to fine, under the budgets) with zc, normals and tile ranges recomputed. Levels being
  // filled afresh start again. An empty rect does nothing. The caller changes the source first (the
  // clipmap re-reads it; a source with a cache must drop what it cached of the region). align > 1:
  // every level's rectangle is first grown outwards to whole align x align tiles of the level grid
  // (an edited compressed pyramid re-codes whole codec tiles, changing all of their samples).
  void invalidate(const Rect& finest, int64_t align = 1);
  // Samples (level grid) invalidated and not yet refilled.
  int64_t invalid_samples(int level) const;

  bool has_data(int level) const { return lv(level).has_data; }  // filled by some update
  bool enabled(int level) const { return lv(level).enabled; }    // not switched off by height
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
  // (conservative: whole tiles). An r outside the clip region, or a level without data, gives {0, 0}.
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
    std::vector<Rect> invalid;  // invalidated rectangles inside the clip region, not yet refilled
    bool filling = false;       // filled afresh by row strips (budget_ms): has_data false meanwhile
    int64_t rows_done = 0;      // rows of the clip region filled so far while `filling`
  };
  const Level& lv(int level) const { return levels_.at(size_t(level)); }
  LevelRegion desired_for(int level, double x_m, double y_m) const;
  int64_t exposed_samples(const Level& L, int64_t x0, int64_t y0) const;
  void refill(int level, int64_t x0, int64_t y0, ClipmapUpdateStats& stats);
  bool at_desired(const Level& L) const {
    return L.has_data && !L.filling && L.clip_x0 == L.desired.x0 && L.clip_y0 == L.desired.y0;
  }
  bool ready(const Level& L) const { return at_desired(L) && L.invalid.empty(); }
  bool coarser_covers(int level, int64_t x0, int64_t y0, int64_t x1, int64_t y1) const;
  // One piece of the time-budgeted work of a level: start a fresh fill (and do its first strip), the
  // next strip of a fresh fill, a move of the clip region by a strip, or a strip of an invalidated
  // rectangle; None when the level is ready.
  struct Piece {
    enum Kind { None, StartFill, Strip, Move, Invalid } kind = None;
    int64_t x0 = 0, y0 = 0;  // StartFill, Move: the clip region's new corner
    Rect rect;               // Invalid: the strip
    int64_t rows = 0;        // StartFill, Strip: rows of the fresh fill
    int64_t samples = 0;
  };
  // The level's next piece, at most `lines` (1..kPiece) columns or rows thick.
  Piece plan_piece(int level, int64_t lines) const;
  void run_piece(int level, const Piece& piece, ClipmapUpdateStats& stats);
  void refill_invalid(int level, const Rect& r, ClipmapUpdateStats& stats);
  void fill_strip(int level, int64_t rows, ClipmapUpdateStats& stats);
  void add_times(int level, double fill, const FillSplit& split, double coarse, double normals, double bounds,
                 int64_t samples, ClipmapUpdateStats& stats);
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
  int64_t budget_request_;  // set_budget's argument (<= 0: the default)
  double budget_ms_ = 0;
  // Seconds per sample of the refill pieces so far, per kind of piece (budget_ms's prediction: a move
  // by a thin strip also recomputes the clip border's normals and tiles, a fresh fill's strip not).
  std::array<double, 5> seconds_per_sample_{};
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
