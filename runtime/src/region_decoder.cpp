// RegionDecoder: recursive coarse-to-fine reconstruction of rectangles through a tile cache.
#include "runtime/region_decoder.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "codec/codec.h"

namespace terrain::runtime {
namespace {

codec::Scratch& thread_codec_scratch() {
  thread_local codec::Scratch s;
  return s;
}
UpsampleScratch& thread_upsample_scratch() {
  thread_local UpsampleScratch s;
  return s;
}

// Key: level (6 bits), tile row and column (29 bits each): enough for 2^29 tiles per axis.
uint64_t tile_key(int level, int64_t tx, int64_t ty) {
  return (uint64_t(level) << 58) | (uint64_t(ty) << 29) | uint64_t(tx);
}

int32_t saturate(int64_t v) {
  return int32_t(std::clamp<int64_t>(v, std::numeric_limits<int32_t>::min(), std::numeric_limits<int32_t>::max()));
}

}  // namespace

RegionDecoder::RegionDecoder(std::shared_ptr<const PyramidFile> file, size_t cache_bytes, int64_t tile_size)
    : file_(std::move(file)), tile_size_(tile_size), cache_capacity_(cache_bytes) {
  if (tile_size_ < 4 || tile_size_ > 4096) throw std::invalid_argument("region decoder: tile size out of [4, 4096]");
}

RegionStats RegionDecoder::stats() const {
  return RegionStats{tiles_.load(), samples_.load(), hits_.load(), residual_samples_.load()};
}

void RegionDecoder::reset_stats() { tiles_ = 0, samples_ = 0, hits_ = 0, residual_samples_ = 0; }

void RegionDecoder::clear_cache() {
  std::lock_guard<std::mutex> lock(mutex_);
  lru_.clear();
  map_.clear();
  cache_bytes_ = 0;
}

void RegionDecoder::add_residual(int level, const Rect& rect, int32_t* out, int64_t out_stride) const {
  thread_local std::vector<int32_t> residual;
  const auto& bands = file_->bands(level);
  for (size_t b = file_->band_of_row(level, rect.y0); b < bands.size(); ++b) {
    const BandView& band = bands[b];
    if (band.y0 >= rect.y0 + rect.height) break;
    const int64_t y0 = std::max(rect.y0, band.y0), y1 = std::min(rect.y0 + rect.height, band.y0 + band.rows);
    codec::Decoder dec;
    codec::Status s = dec.open(band.data, band.size);
    const codec::Rect cr{rect.x0, y0 - band.y0, rect.width, y1 - y0};
    if (s == codec::Status::Ok) {
      residual.resize(size_t(cr.width * cr.height));
      s = dec.decode_region(cr, residual.data(), cr.width, thread_codec_scratch());
    }
    if (s != codec::Status::Ok)
      throw FormatError(s == codec::Status::ChecksumMismatch ? FormatErrorCode::ChecksumMismatch : FormatErrorCode::Corrupt,
                        file_->path() + ": level " + std::to_string(level) + ", band " + std::to_string(b) +
                            " (rows " + std::to_string(band.y0) + ".." + std::to_string(band.y0 + band.rows - 1) +
                            "), columns " + std::to_string(rect.x0) + ".." + std::to_string(rect.x0 + rect.width - 1) +
                            ": " + codec::status_name(s));
    const int64_t ts = dec.header().tile_size;
    const int64_t tx0 = cr.x / ts, tx1 = (cr.x + cr.width - 1) / ts, ty0 = cr.y / ts, ty1 = (cr.y + cr.height - 1) / ts;
    residual_samples_ += uint64_t((tx1 - tx0 + 1) * (ty1 - ty0 + 1) * ts * ts);
    for (int64_t y = y0; y < y1; ++y) {
      int32_t* row = out + (y - rect.y0) * out_stride;
      const int32_t* r = residual.data() + (y - y0) * cr.width;
      for (int64_t x = 0; x < rect.width; ++x) row[x] = saturate(int64_t(row[x]) + r[x]);
    }
  }
}

std::shared_ptr<const RegionDecoder::Tile> RegionDecoder::build_tile(int level, int64_t tx, int64_t ty) const {
  const GridSize size = file_->level_size(level);
  const Rect r{tx * tile_size_, ty * tile_size_, std::min(tile_size_, size.width - tx * tile_size_),
               std::min(tile_size_, size.height - ty * tile_size_)};
  auto t = std::make_shared<Tile>(size_t(r.width * r.height));
  if (level == 0) {
    std::fill(t->begin(), t->end(), 0);
  } else {
    const Rect need = upsample_required_window(r, size);
    std::vector<int32_t> coarse(size_t(need.width * need.height));
    decode_units(level - 1, need, coarse.data(), need.width);
    const CoarseWindow win{coarse.data(), need.width, need, file_->level_size(level - 1)};
    upsample_region(win, size, r, t->data(), r.width, thread_upsample_scratch());
  }
  add_residual(level, r, t->data(), r.width);
  tiles_ += 1;
  samples_ += uint64_t(r.width * r.height);
  return t;
}

std::shared_ptr<const RegionDecoder::Tile> RegionDecoder::tile(int level, int64_t tx, int64_t ty) const {
  const uint64_t key = tile_key(level, tx, ty);
  if (cache_capacity_ > 0) {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = map_.find(key);
    if (it != map_.end()) {
      lru_.splice(lru_.begin(), lru_, it->second);
      hits_ += 1;
      return it->second->tile;
    }
  }
  // Built outside the lock: two threads may race to build the same tile; both get identical data.
  std::shared_ptr<const Tile> t = build_tile(level, tx, ty);
  if (cache_capacity_ > 0) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (map_.find(key) == map_.end()) {
      lru_.push_front(Entry{key, t});
      map_[key] = lru_.begin();
      cache_bytes_ += t->size() * sizeof(int32_t);
      while (cache_bytes_ > cache_capacity_ && lru_.size() > 1) {
        cache_bytes_ -= lru_.back().tile->size() * sizeof(int32_t);
        map_.erase(lru_.back().key);
        lru_.pop_back();
      }
    }
  }
  return t;
}

void RegionDecoder::decode_units(int level, const Rect& rect, int32_t* out, int64_t out_stride) const {
  if (level < 0 || level >= file_->level_count()) throw std::out_of_range("region decoder: no level " + std::to_string(level));
  const GridSize size = file_->level_size(level);
  if (rect.x0 < 0 || rect.y0 < 0 || rect.width < 0 || rect.height < 0 || rect.x0 + rect.width > size.width ||
      rect.y0 + rect.height > size.height)
    throw std::out_of_range("region decoder: rectangle outside level " + std::to_string(level));
  if (rect.width == 0 || rect.height == 0) return;
  const int64_t T = tile_size_;
  for (int64_t ty = rect.y0 / T; ty <= (rect.y0 + rect.height - 1) / T; ++ty)
    for (int64_t tx = rect.x0 / T; tx <= (rect.x0 + rect.width - 1) / T; ++tx) {
      std::shared_ptr<const Tile> t = tile(level, tx, ty);
      const int64_t tw = std::min(T, size.width - tx * T);
      const int64_t x0 = std::max(rect.x0, tx * T), x1 = std::min(rect.x0 + rect.width, tx * T + tw);
      const int64_t y0 = std::max(rect.y0, ty * T), y1 = std::min(rect.y0 + rect.height, (ty + 1) * T);
      for (int64_t y = y0; y < y1; ++y)
        std::copy_n(t->data() + (y - ty * T) * tw + (x0 - tx * T), x1 - x0,
                    out + (y - rect.y0) * out_stride + (x0 - rect.x0));
    }
}

void RegionDecoder::decode_metres(int level, const Rect& rect, float* out, int64_t out_stride) const {
  std::vector<int32_t> units(size_t(rect.width * rect.height));
  decode_units(level, rect, units.data(), rect.width);
  const double scale = metres_per_unit(), offset = metres_offset();
  const bool finest = level == file_->level_count() - 1;
  const bool voids = finest && file_->info().void_count > 0;
  std::vector<uint8_t> valid;
  if (voids) valid.resize(size_t(rect.height * file_->level_size(level).width));
  if (voids) file_->container().mask_rows(uint64_t(rect.y0), uint64_t(rect.height), valid.data());
  const int64_t w = file_->level_size(level).width;
  for (int64_t y = 0; y < rect.height; ++y)
    for (int64_t x = 0; x < rect.width; ++x) {
      const bool ok = !voids || valid[size_t(y * w + rect.x0 + x)];
      out[y * out_stride + x] = ok ? float(units[size_t(y * rect.width + x)] * scale + offset)
                                   : std::numeric_limits<float>::quiet_NaN();
    }
}

}  // namespace terrain::runtime
