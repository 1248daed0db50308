// Where the geometry clipmap gets its heights from: one grid per pyramid level, level 0 coarsest,
// level l sample i on level l+1 sample 2i, heights in metres. Every source repeats the nearest edge
// sample outside a bounded level, so the clipmap never special-cases the terrain's border.
//
// Threads: no source is thread-safe (each reuses scratch buffers, even in its const-looking
// fills); use one source per thread.
#pragma once

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
  const int32_t* data = nullptr;  // n * n units, owned by the caller
  int64_t n = 0;                  // side of the toroidal storage, samples
  Rect region;                    // the samples of the level that data holds (level grid)
};

// Where the time of a fill went, for sources that can say (seconds, added to).
struct FillSplit {
  double upsample = 0;  // U of the coarser level
  double residual = 0;  // the residual: entropy decode (or tile cache) and the addition
};

class HeightSource {
 public:
  virtual ~HeightSource() = default;
  virtual int level_count() const = 0;
  // Samples of `level` (0 .. level_count() - 1; others: std::out_of_range).
  virtual GridSize level_size(int level) const = 0;
  // Horizontal spacing of the finest level, metres.
  virtual double spacing_m() const = 0;
  // Heights (metres) of `level` on `rect` into out (row stride out_stride floats). rect may reach
  // beyond the level: such samples repeat the nearest edge sample (a bounded terrain seen from
  // outside is a flat apron). An empty rect writes nothing. Throws std::out_of_range for a level
  // outside 0 .. level_count() - 1, and what the source's own storage throws (RegionDecoderSource:
  // Error on damaged data).
  virtual void fill(int level, const Rect& rect, float* out, int64_t out_stride) = 0;

  // Sources whose levels are integer grids related by level = U(coarser level) + residual (the
  // compressed pyramid) say so here and implement fill_units; the clipmap then keeps each level's
  // units and refines the finer level from them instead of having the source rebuild it.
  virtual bool refines_units() const { return false; }
  // fill(), also writing the level's integer units at the same positions (units_out, stride
  // out_stride; edge samples repeat beyond the level like the heights; null: heights only).
  // `coarser`, when not null, holds units of level - 1 as this source gives them; where it covers
  // the window U needs, only the residual is decoded (split, when not null, receives the time of U
  // and of the residual). Either way the output equals what fill() writes. Throws as fill() does;
  // the default (refines_units() false) throws std::logic_error.
  virtual void fill_units(int level, const Rect& rect, const HeldUnits* coarser, float* out,
                          int32_t* units_out, int64_t out_stride, FillSplit* split);
};

// A compressed pyramid file through the region decoder. Voids (NaN) come out as 0 m. Safe on
// untrusted files as far as the decoder is: damaged data throws Error from fill.
class RegionDecoderSource final : public HeightSource {
 public:
  // spacing_m: finest-level horizontal spacing in metres (arc-second data: the caller converts).
  // Throws std::invalid_argument for a null decoder or a spacing that is not a positive finite
  // number.
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
  // Level sizes halve from `finest` as in the pyramid (coarse_extent). Throws
  // std::invalid_argument for levels outside 1..30, an empty finest level or an empty function;
  // spacing_m is not checked (the Clipmap constructor rejects a non-positive one).
  FunctionHeightSource(int levels, GridSize finest, double spacing_m, Function f, bool unbounded);
  int level_count() const override { return levels_; }
  GridSize level_size(int level) const override;
  double spacing_m() const override { return spacing_m_; }
  void fill(int level, const Rect& rect, float* out, int64_t out_stride) override;
  int64_t calls() const { return samples_; }  // calls of the function so far (one per sample filled)

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
  // std::invalid_argument on no levels, mismatched sizes or a spacing that is not a positive
  // finite number.
  GridHeightSource(std::vector<GridSize> sizes, std::vector<std::vector<float>> levels, double spacing_m);
  int level_count() const override { return int(sizes_.size()); }
  GridSize level_size(int level) const override { return sizes_.at(size_t(level)); }
  double spacing_m() const override { return spacing_m_; }
  void fill(int level, const Rect& rect, float* out, int64_t out_stride) override;
  // The samples of `level`, row-major (std::out_of_range outside 0 .. level_count() - 1).
  const std::vector<float>& level(int level) const { return levels_.at(size_t(level)); }
  // Validity of the finest level's samples (1 = data); empty when all are valid.
  std::vector<uint8_t> finest_valid;

 private:
  std::vector<GridSize> sizes_;
  std::vector<std::vector<float>> levels_;
  double spacing_m_;
};

// The original (uncompressed) heightmap `input`, in any format libreaders reads, as a lossless
// pyramid with the level count and the D filter (PyramidFile::downsample_filter()) of a compressed
// pyramid: level l is then the exact T_l that the
// compressed file approximates by T^_l. Voids come out as 0 m (as from RegionDecoderSource) and
// are flagged in finest_valid. Reads the whole file and builds the whole pyramid in memory, on the
// calling thread. Throws Error naming the file (unreadable or malformed input), or
// std::invalid_argument when the input's size differs from `finest` or the pyramid does not get
// level_count levels (not the pyramid's input).
GridHeightSource original_source(const std::string& input, const ReadOptions& read_options, GridSize finest,
                                 int level_count, const DownsampleFilter& filter, double spacing_m);

}  // namespace terrain::runtime
