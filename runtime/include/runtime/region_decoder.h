// Region-of-interest decoding of a compressed pyramid: the "region decoder" stage.
//
// decode_units(level, rect) reconstructs T^_level on rect exactly as the builder did:
// U(T^_{level-1}) on the rectangle plus the decoded residual, recursively down to the coarsest
// level, decoding only the libcodec tiles that the rectangle and the upsampling support need.
// Reconstructed tiles (tile_size x tile_size, aligned to the level's origin) are kept in a bounded
// LRU cache shared by all callers, so coarse levels that neighbouring requests share are decoded once.
//
// Thread-safe: any number of threads may call the decode functions concurrently.
#pragma once

#include <atomic>
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "runtime/pyramid_file.h"

namespace terrain::runtime {

struct RegionStats {
  uint64_t tiles_reconstructed = 0;   // cache misses: tiles rebuilt (U + residual)
  uint64_t samples_reconstructed = 0; // their samples, all levels
  uint64_t cache_hits = 0;
  uint64_t residual_samples_decoded = 0;  // samples of the libcodec tiles entropy-decoded
};

class RegionDecoder {
 public:
  // cache_bytes bounds the reconstructed-tile cache (0 disables it: every call rebuilds what it needs).
  explicit RegionDecoder(std::shared_ptr<const PyramidFile> file, size_t cache_bytes = size_t(256) << 20,
                         int64_t tile_size = 64);

  // T^_level on rect in level units (int32); rect must lie inside the level (else std::out_of_range).
  // Throws FormatError naming the file, level, band and libcodec status when data is damaged.
  void decode_units(int level, const Rect& rect, int32_t* out, int64_t out_stride) const;
  // The same in metres; voids of the finest level (when the input had nodata) come out as NaN.
  void decode_metres(int level, const Rect& rect, float* out, int64_t out_stride) const;
  // Metres per level unit and offset: metres = units * scale + offset.
  double metres_per_unit() const { return file_->info().vertical_scale; }
  double metres_offset() const { return file_->info().vertical_offset; }

  const PyramidFile& file() const { return *file_; }
  RegionStats stats() const;
  void reset_stats();
  void clear_cache();

 private:
  using Tile = std::vector<int32_t>;
  std::shared_ptr<const Tile> tile(int level, int64_t tx, int64_t ty) const;
  std::shared_ptr<const Tile> build_tile(int level, int64_t tx, int64_t ty) const;
  void add_residual(int level, const Rect& rect, int32_t* out, int64_t out_stride) const;

  std::shared_ptr<const PyramidFile> file_;
  int64_t tile_size_;
  size_t cache_capacity_;
  // LRU: most recent at the front; the map points into the list.
  struct Entry {
    uint64_t key;
    std::shared_ptr<const Tile> tile;
  };
  mutable std::mutex mutex_;
  mutable std::list<Entry> lru_;
  mutable std::unordered_map<uint64_t, std::list<Entry>::iterator> map_;
  mutable size_t cache_bytes_ = 0;
  mutable std::atomic<uint64_t> tiles_ = 0, samples_ = 0, hits_ = 0, residual_samples_ = 0;
};

}  // namespace terrain::runtime
