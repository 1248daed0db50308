// Region-of-interest decoding of a compressed pyramid: the "region decoder" stage.
//
// decode_units(level, rect) reconstructs T^_level on rect exactly as the builder did:
// U(T^_{level-1}) on the rectangle plus the decoded residual, recursively down to the coarsest
// level. Each recursion step asks the coarser level for exactly the window that U needs on rect
// (rect/2 plus the four-point support), so reconstruction costs about 4/3 of rect's area in all;
// the residuals are entropy-decoded only for the libcodec tiles those windows intersect. A caller
// that already holds T^_{level-1} around rect (the clipmap: its own coarser level) calls
// decode_refined instead and pays for U and the residual of rect alone.
// Decoded residual tiles are kept in a bounded LRU cache shared by all callers, so requests that
// share tiles (the thin L-shaped strips of a moving clipmap, neighbouring windows) decode each
// tile once.
//
// Thread-safe: any number of threads may call the decode functions (and stats, reset_stats,
// clear_cache) concurrently.
// Untrusted input: safe on any file PyramidFile::open accepts; damaged band streams are caught by
// libcodec and thrown as Error, never read out of bounds.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "container/pyramid_file.h"

namespace terrain::runtime {

struct RegionStats {
  uint64_t samples_reconstructed = 0;               // samples computed as U + residual, all levels
  uint64_t residual_tiles_decoded = 0;              // libcodec tiles entropy-decoded (cache misses)
  uint64_t residual_samples_decoded = 0;            // their samples, all levels
  uint64_t cache_hits = 0;                          // residual tiles served from the cache
  std::vector<uint64_t> residual_samples_by_level;  // residual_samples_decoded split by level
};

class RegionDecoder {
 public:
  static constexpr int kMaxLevels = 64;

  // cache_bytes bounds the decoded-residual cache (0 disables it: each call decodes exactly the
  // libcodec tiles its rectangles intersect, and nothing is kept); any other bound keeps at least the
  // most recent tile. `file` must not be null. Throws Error(Corrupt) for a
  // file of more than kMaxLevels levels. Band streams are opened on first use, not here.
  explicit RegionDecoder(std::shared_ptr<const container::PyramidFile> file, size_t cache_bytes = size_t(256)
                                                                                                  << 20);
  ~RegionDecoder();

  // T^_level on rect in level units (int32) into out (row stride out_stride); rect must lie inside
  // the level, and level inside 0 .. level_count() - 1 (else std::out_of_range; an empty rect
  // writes nothing). Throws Error naming the file, level, band and libcodec status when data
  // is damaged (out then holds unspecified values).
  void decode_units(int level, const Rect& rect, int32_t* out, int64_t out_stride) const;
  // T^_level on rect from the caller's own T^_{level-1}: U(coarser) + the decoded residual, no
  // recursion (the clipmap's update, paper §5: the coarser level is already in the clipmap).
  // coarser.rect must contain upsample_required_window(rect, level size) and hold exactly what
  // decode_units(level - 1, ...) gives there; then the result equals decode_units(level, rect).
  // When seconds_upsample / seconds_residual are given, the time of each half is added to them.
  // Throws std::out_of_range for level 0 or beyond, or rect outside the level; std::invalid_argument
  // when coarser does not hold the window U needs; Error as decode_units.
  void decode_refined(int level, const Rect& rect, const CoarseWindow& coarser, int32_t* out,
                      int64_t out_stride, double* seconds_upsample = nullptr,
                      double* seconds_residual = nullptr) const;
  // The same in metres; voids of the finest level (when the input had nodata) come out as NaN.
  // Throws as decode_units.
  void decode_metres(int level, const Rect& rect, float* out, int64_t out_stride) const;
  // Metres per level unit and offset: metres = units * scale + offset.
  double metres_per_unit() const { return file_->info().vertical_scale; }
  double metres_offset() const { return file_->info().vertical_offset; }

  const container::PyramidFile& file() const { return *file_; }
  RegionStats stats() const;  // counts since construction or the last reset_stats
  void reset_stats();
  void clear_cache();  // drops every cached tile (the next requests decode again)

 private:
  struct Band;             // a band's libcodec stream, opened (header + tile index parsed) on first use
  using Tile = int32_t[];  // a decoded tile's samples, row-major (allocated uninitialised: decode writes all)
  const Band& band(int level, size_t b) const;
  void add_residual(int level, const Rect& rect, int32_t* out, int64_t out_stride) const;
  std::shared_ptr<const Tile> residual_tile(int level, size_t b, const Band& band, int64_t tx,
                                            int64_t ty) const;
  void count_decoded(int level, uint64_t tiles, uint64_t samples) const;

  std::shared_ptr<const container::PyramidFile> file_;
  size_t cache_capacity_;
  std::vector<std::vector<std::unique_ptr<Band>>> bands_;
  // LRU of decoded residual tiles: most recent at the front; the map points into the list.
  struct Entry {
    uint64_t key;
    std::shared_ptr<const Tile> tile;
    size_t bytes;
  };
  mutable std::mutex mutex_;
  mutable std::list<Entry> lru_;
  mutable std::unordered_map<uint64_t, std::list<Entry>::iterator> map_;
  mutable size_t cache_bytes_ = 0;
  mutable std::atomic<uint64_t> samples_ = 0, tiles_ = 0, residual_samples_ = 0, hits_ = 0;
  mutable std::array<std::atomic<uint64_t>, kMaxLevels> by_level_{};
};

}  // namespace terrain::runtime
