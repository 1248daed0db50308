// A virtual terrain of any size that repeats a stored pyramid by mirror reflection (as mirror-tile
// does, without materialising it): the paper's trillion-sample test (Bhattacharjee et al. 2008) on
// a 1201^2 tile repeated to 1,048,576^2 samples, in bounded memory.
//
// Levels. The virtual finest level is the stored finest level reflected at every edge without
// repeating the edge sample (period 2 (w - 1)). A stored level s whose finer neighbour's size is
// 2 (w_s - 1) + 1 (1201 -> 601 -> 301 -> 151) lines up with it under reflection (its sample i on
// fine sample 2i, its mirror axes on the finer level's), and since the pyramid's D extends a level
// beyond its edges by the same reflection, such a stored level is exactly D of the reflected finer
// level: those levels are the stored ones, reflected. The virtual terrain needs more levels than
// the stored pyramid has (a 1,048,576^2 finest level wants ~14 for a coarsest level of ~128): they
// are computed once, in memory, by D (the pyramid's own filter) from the coarsest lined-up stored
// level's reflected tiling. A level computed by D from a level of period p has period p / 2 (p even)
// or p (p odd), so each is stored as one period (75 x 75 samples for a 1201^2 tile): the memory is
// that of the stored pyramid's coarsest lined-up level plus a few small tiles, whatever the virtual
// size. Outside the virtual extent the edge samples repeat, like every source.
//
// Threads: not thread-safe (reuses scratch buffers and drives the base source); use one per thread.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "pyramid/downsample.h"
#include "runtime/height_source.h"

namespace terrain::runtime {

class MirroredSource final : public HeightSource {
 public:
  // Repeats `base` (which must outlive this) to a virtual finest level of finest.width x
  // finest.height samples (each at least the base's finest size, at most 2^30), with pyramid levels
  // down to a coarsest side below 2 * min_coarsest_side (pyramid_level_sizes). `filter`: the base
  // pyramid's D (for the computed levels). Reads the base's coarsest lined-up level whole (throws
  // std::invalid_argument when it has more than 2^24 samples, or for a bad size), and what the
  // base's fill throws.
  MirroredSource(HeightSource& base, GridSize finest, const DownsampleFilter& filter,
                 int64_t min_coarsest_side = 128);
  int level_count() const override { return int(sizes_.size()); }
  GridSize level_size(int level) const override { return sizes_.at(size_t(level)); }
  double spacing_m() const override { return base_.spacing_m(); }
  // Heights of the virtual level: from the base (reflected) or from the computed tiles.
  void fill(int level, const Rect& rect, float* out, int64_t out_stride) override;

  // The base level that virtual `level` reflects, or -1 for a computed level.
  int base_level(int level) const;
  // Bytes this source holds (computed tiles and scratch), independent of the virtual size.
  size_t memory_bytes() const;
  // Mirror reflection without repeating the edge sample: index i of an axis of n samples.
  static int64_t reflect(int64_t i, int64_t n);

 private:
  HeightSource& base_;
  std::vector<GridSize> sizes_;
  int offset_;        // virtual level = base level + offset_ for the lined-up levels
  int first_mapped_;  // the coarsest virtual level that reflects a base level
  struct Tile {
    int64_t px = 0, py = 0;  // period
    std::vector<float> z;    // one period, row-major
  };
  std::vector<Tile> tiles_;  // computed levels 0 .. first_mapped_ - 1
  std::vector<int64_t> xs_, ys_;
  std::vector<float> window_;
};

}  // namespace terrain::runtime
