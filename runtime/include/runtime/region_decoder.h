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
// libcodec, never read out of bounds.
//
// Damage contract. What a decode does on damaged data (a band stream whose header or tile index
// fails to open, a tile row whose payload CRC fails, a tile whose bitstream is malformed) is the
// decoder's DamagePolicy, fixed at construction:
//   Throw (the default, for tools that extract or measure data: pyramid-extract, terrain-report,
//     the Python module) throws Error naming the file, level, band, tile and libcodec status.
//   Degrade (for viewers: clipmap-view) adds no residual for the damaged part, so its samples are
//     U of the coarser level: the region shows the next coarser level that decodes there (a damaged
//     coarser level degrades the same way, down to level 0), finer residuals are still added. Each
//     damaged part is recorded once, in the order met, with its level, tiles, samples and file
//     offset (damaged_tiles()); it is cached like a good tile, so it is neither decoded nor reported
//     again. A decode under Degrade throws only for misuse (std::out_of_range, invalid_argument).
// Damage is localised as finely as libcodec can: a tile whose bitstream is bad is one tile; a
// payload CRC covers a whole tile row of the band's stream, so a row that fails it is one report for
// all its tiles; a stream that does not open is one report for the whole band.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "codec/codec.h"
#include "container/pyramid_file.h"

namespace terrain::runtime {

struct RegionStats {
  uint64_t samples_reconstructed = 0;               // samples computed as U + residual, all levels
  uint64_t residual_tiles_decoded = 0;              // libcodec tiles entropy-decoded (cache misses)
  uint64_t residual_samples_decoded = 0;            // their samples, all levels
  uint64_t cache_hits = 0;                          // residual tiles served from the cache
  std::vector<uint64_t> residual_samples_by_level;  // residual_samples_decoded split by level
};

// See "Damage contract" above.
enum class DamagePolicy {
  Throw,    // throw Error (the default)
  Degrade,  // leave the damaged residual out (the coarser level shows there) and record it once
};

// A damaged part of one level met under DamagePolicy::Degrade.
struct DamagedTile {
  int level = 0;
  size_t band = 0;           // index into PyramidFile::bands(level)
  int64_t tile_x = -1;       // the tile column in the band's stream; -1: every tile of the row(s)
  int64_t tile_y = -1;       // the tile row in the band's stream; -1: the whole stream (it did not open)
  Rect area;                 // the level's samples whose residual is left out (level coordinates)
  uint64_t file_offset = 0;  // first byte of the damaged payload (tile, tile row or stream) in the file
  uint64_t bytes = 0;        // its size
  ErrorCode code = ErrorCode::CorruptData;  // ChecksumMismatch (a CRC failed) or CorruptData
  std::string message;  // "<file>: level L, band b (rows ..), tile ..: <libcodec status>", as Throw would say
};

class RegionDecoder {
 public:
  static constexpr int kMaxLevels = 64;

  // cache_bytes bounds the decoded-residual cache (0 disables it: each call decodes exactly the
  // libcodec tiles its rectangles intersect, and nothing is kept); any other bound keeps at least the
  // most recent tile it caches. A request of at least 128x128 samples at a level does not cache the
  // tiles wholly inside it (it uses those already cached): they are decoded straight into the output. `file`
  // must not be null. policy: what damaged data does (the damage contract above). Throws Error(Corrupt) for a
  // file of more than kMaxLevels levels. Band streams are opened on first use, not here.
  explicit RegionDecoder(std::shared_ptr<const container::PyramidFile> file,
                         size_t cache_bytes = size_t(256) << 20, DamagePolicy policy = DamagePolicy::Throw);
  ~RegionDecoder();

  // T^_level on rect in level units (int32) into out (row stride out_stride); rect must lie inside
  // the level, and level inside 0 .. level_count() - 1 (else std::out_of_range; an empty rect
  // writes nothing). Throws Error naming the file, level, band and libcodec status when data
  // is damaged (out then holds unspecified values); under DamagePolicy::Degrade it leaves the
  // damaged residual out instead and records it (damaged_tiles).
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
  DamagePolicy policy() const { return policy_; }
  // DamagePolicy::Degrade: the damaged parts met so far, each once, in the order met, from the
  // `from`-th on (so a caller that remembers how many it has seen gets only the new ones).
  // Always empty under Throw. Not cleared by clear_cache or reset_stats.
  std::vector<DamagedTile> damaged_tiles(size_t from = 0) const;
  size_t damaged_count() const;
  RegionStats stats() const;  // counts since construction or the last reset_stats
  void reset_stats();
  void clear_cache();  // drops every cached tile (the next requests decode again)

 private:
  struct Band;             // a band's libcodec stream, opened (header + tile index parsed) on first use
  using Tile = int32_t[];  // a decoded tile's samples, row-major (allocated uninitialised: decode writes all)
  // The band's opened stream; null when it does not open (Degrade: recorded; Throw: thrown).
  const Band* band(int level, size_t b) const;
  // Throw: throws Error. Degrade: records the damage (once per part) and returns.
  void damaged(int level, size_t b, const Band* bd, int64_t tx, int64_t ty, codec::Status s) const;
  // bulk: tiles wholly inside rect that are not cached are added straight into out, not cached.
  void add_residual(int level, const Rect& rect, int32_t* out, int64_t out_stride, bool bulk) const;
  std::shared_ptr<const Tile> cached_tile(uint64_t key) const;  // null when not cached (counts a hit)
  std::shared_ptr<const Tile> residual_tile(int level, size_t b, const Band& band, int64_t tx,
                                            int64_t ty) const;
  void count_decoded(int level, uint64_t tiles, uint64_t samples) const;

  std::shared_ptr<const container::PyramidFile> file_;
  size_t cache_capacity_;
  DamagePolicy policy_;
  mutable std::mutex damage_mutex_;
  mutable std::vector<DamagedTile> damaged_;                                 // guarded by damage_mutex_
  mutable std::set<std::tuple<int, size_t, int64_t, int64_t>> damage_keys_;  // level, band, tile_x, tile_y
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
