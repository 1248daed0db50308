// RegionDecoder: exact-window coarse-to-fine reconstruction with a cache of decoded residual tiles.
#include "runtime/region_decoder.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "codec/codec.h"

namespace terrain::runtime {

using namespace terrain::container;  // the stage below

struct RegionDecoder::Band {
  std::once_flag once;
  codec::Decoder decoder;
  codec::Status status = codec::Status::Ok;
};

namespace {

using Clock = std::chrono::steady_clock;

codec::Scratch& thread_codec_scratch() {
  thread_local codec::Scratch s;
  return s;
}
UpsampleScratch& thread_upsample_scratch() {
  thread_local UpsampleScratch s;
  return s;
}
// One buffer per level for the coarser windows of the recursion (level l's call fills buffer l-1),
// reused across calls so that steady-state decoding does not allocate.
std::vector<int32_t>& thread_window(int level) {
  thread_local std::array<std::vector<int32_t>, RegionDecoder::kMaxLevels> windows;
  return windows[size_t(level)];
}

// Key: level (6 bits), band (24 bits), tile within the band (34 bits).
uint64_t tile_key(int level, size_t band, int64_t tile) {
  return (uint64_t(level) << 58) | (uint64_t(band) << 34) | uint64_t(tile);
}

// a + b clamped to the int32 range. In 32-bit lanes (no widening), so that the loop below
// vectorises with plain SSE2: the sum overflowed iff both operands' signs differ from its sign,
// and then the bound is the one on a's side.
int32_t saturating_add(int32_t a, int32_t b) {
  const int32_t sum = int32_t(uint32_t(a) + uint32_t(b));
  const int32_t bound = (a >> 31) ^ std::numeric_limits<int32_t>::max();
  return ((a ^ sum) & (b ^ sum)) < 0 ? bound : sum;
}

// out[rect] += residual (rows of `width` samples starting at `res`, `res_stride` apart).
void add_rows(int32_t* out, int64_t out_stride, const int32_t* res, int64_t res_stride, int64_t width,
              int64_t rows) {
  for (int64_t y = 0; y < rows; ++y) {
    int32_t* o = out + y * out_stride;
    const int32_t* r = res + y * res_stride;
    for (int64_t x = 0; x < width; ++x) o[x] = saturating_add(o[x], r[x]);
  }
}

// Rows U and the residual add work on at a time in decode_refined (rounded up to whole tile rows):
// 32 rows of a 4096-sample level are 512 KiB of int32, half of an L2 cache.
constexpr int64_t kStripRows = 32;

// A request at least this wide and high at its level is a bulk read (a whole level, an extract,
// a cold window): the residual tiles wholly inside it that are not cached are decoded straight into
// the output and not cached. A later request meets such a tile again only where its own rectangle
// overlaps this one's interior, which moving windows and row-by-row reads rarely do, while caching
// them costs an allocation, a copy and a second pass per tile (about 10% of a whole-level decode).
constexpr int64_t kBulkSide = 128;

// Sum of the extents of the tiles [t0, t1] of size ts along an axis of length n.
int64_t tiles_extent(int64_t t0, int64_t t1, int64_t ts, int64_t n) {
  return std::min(n, (t1 + 1) * ts) - t0 * ts;
}

// The size of `level`, after checking that rect lies inside it.
GridSize checked_size(const PyramidFile& file, int level, const Rect& rect) {
  const GridSize size = file.level_size(level);
  if (rect.x0 < 0 || rect.y0 < 0 || rect.width < 0 || rect.height < 0 || rect.x0 + rect.width > size.width ||
      rect.y0 + rect.height > size.height)
    throw std::out_of_range("region decoder: rectangle outside level " + std::to_string(level));
  return size;
}

}  // namespace

RegionDecoder::RegionDecoder(std::shared_ptr<const PyramidFile> file, size_t cache_bytes, DamagePolicy policy)
    : file_(std::move(file)), cache_capacity_(cache_bytes), policy_(policy) {
  if (file_->level_count() > kMaxLevels)
    throw Error(ErrorCode::CorruptData,
                file_->path() + ": more than " + std::to_string(kMaxLevels) + " levels");
  bands_.resize(size_t(file_->level_count()));
  for (int l = 0; l < file_->level_count(); ++l) {
    bands_[size_t(l)].resize(file_->bands(l).size());
    for (auto& b : bands_[size_t(l)]) b = std::make_unique<Band>();
  }
}

RegionDecoder::~RegionDecoder() = default;

RegionStats RegionDecoder::stats() const {
  RegionStats s{samples_.load(), tiles_.load(), residual_samples_.load(), hits_.load(), {}};
  for (int l = 0; l < file_->level_count(); ++l)
    s.residual_samples_by_level.push_back(by_level_[size_t(l)].load());
  return s;
}

void RegionDecoder::reset_stats() {
  samples_ = 0, tiles_ = 0, residual_samples_ = 0, hits_ = 0;
  for (auto& c : by_level_) c = 0;
}

void RegionDecoder::clear_cache() {
  std::lock_guard<std::mutex> lock(mutex_);
  lru_.clear();
  map_.clear();
  cache_bytes_ = 0;
}

void RegionDecoder::count_decoded(int level, uint64_t tiles, uint64_t samples) const {
  tiles_ += tiles;
  residual_samples_ += samples;
  by_level_[size_t(level)] += samples;
}

std::vector<DamagedTile> RegionDecoder::damaged_tiles(size_t from) const {
  std::lock_guard<std::mutex> lock(damage_mutex_);
  if (from >= damaged_.size()) return {};
  return std::vector<DamagedTile>(damaged_.begin() + std::ptrdiff_t(from), damaged_.end());
}

size_t RegionDecoder::damaged_count() const {
  std::lock_guard<std::mutex> lock(damage_mutex_);
  return damaged_.size();
}

// The damaged part: the whole stream (ty < 0), a tile row (tx < 0; its payload CRC failed) or one
// tile, located in the band and in the file.
void RegionDecoder::damaged(int level, size_t b, const Band* bd, int64_t tx, int64_t ty,
                            codec::Status s) const {
  const BandView& view = file_->bands(level)[b];
  const int64_t width = file_->level_size(level).width;
  DamagedTile d;
  d.level = level;
  d.band = b;
  d.code = s == codec::Status::ChecksumMismatch ? ErrorCode::ChecksumMismatch : ErrorCode::CorruptData;
  const uint64_t stream_offset = file_->container().offset_of(view.data);
  std::string where;
  if (ty < 0 || !bd) {
    d.area = Rect{0, view.y0, width, view.rows};
    d.file_offset = stream_offset;
    d.bytes = view.size;
    where = "stream header or tile index";
  } else {
    const codec::HeaderInfo& h = bd->decoder.header();
    const int64_t ts = h.tile_size, rows = std::min<int64_t>(ts, h.height - ty * ts);
    // Payload bytes of tiles [t0, t1): the index holds one entry per non-empty tile or empty run.
    const int64_t t0 = ty * h.tiles_x + std::max<int64_t>(tx, 0), t1 = tx < 0 ? t0 + h.tiles_x : t0 + 1;
    uint64_t first = 0, last = 0;
    bool any = false;
    for (const codec::TileEntry& e : bd->decoder.index()) {
      if (e.first_tile + e.count <= t0 || e.first_tile >= t1 || e.size == 0) continue;
      if (!any) first = e.offset;
      last = e.offset + e.size;
      any = true;
    }
    d.tile_x = tx;
    d.tile_y = ty;
    d.file_offset = stream_offset + first;
    d.bytes = any ? last - first : 0;
    if (tx < 0) {
      d.area = Rect{0, view.y0 + ty * ts, width, rows};
      where = "tile row " + std::to_string(ty);
    } else {
      d.area = Rect{tx * ts, view.y0 + ty * ts, std::min<int64_t>(ts, h.width - tx * ts), rows};
      where = "tile " + std::to_string(tx) + "," + std::to_string(ty);
    }
  }
  d.message = file_->path() + ": level " + std::to_string(level) + ", band " + std::to_string(b) + " (rows " +
              std::to_string(view.y0) + ".." + std::to_string(view.y0 + view.rows - 1) + "), " + where +
              " (samples " + std::to_string(d.area.x0) + "," + std::to_string(d.area.y0) + " " +
              std::to_string(d.area.width) + "x" + std::to_string(d.area.height) + ", file offset " +
              std::to_string(d.file_offset) + "): " + codec::status_name(s);
  if (policy_ == DamagePolicy::Throw) throw Error(d.code, d.message);
  std::lock_guard<std::mutex> lock(damage_mutex_);
  if (damage_keys_.emplace(level, b, d.tile_x, d.tile_y).second) damaged_.push_back(std::move(d));
}

const RegionDecoder::Band* RegionDecoder::band(int level, size_t b) const {
  Band& band = *bands_[size_t(level)][b];
  std::call_once(band.once, [&] {
    const BandView& v = file_->bands(level)[b];
    band.status = band.decoder.open(v.data, v.size);
    if (band.status == codec::Status::Ok && (band.decoder.header().width != file_->level_size(level).width ||
                                             band.decoder.header().height != v.rows))
      band.status = codec::Status::Corrupt;
  });
  if (band.status == codec::Status::Ok) return &band;
  damaged(level, b, nullptr, -1, -1, band.status);
  return nullptr;
}

std::shared_ptr<const RegionDecoder::Tile> RegionDecoder::cached_tile(uint64_t key) const {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = map_.find(key);
  if (it == map_.end()) return nullptr;
  lru_.splice(lru_.begin(), lru_, it->second);
  hits_ += 1;
  return it->second->tile;
}

std::shared_ptr<const RegionDecoder::Tile> RegionDecoder::residual_tile(int level, size_t b, const Band& bd,
                                                                        int64_t tx, int64_t ty) const {
  const codec::HeaderInfo& h = bd.decoder.header();
  const uint64_t key = tile_key(level, b, ty * h.tiles_x + tx);
  if (std::shared_ptr<const Tile> t = cached_tile(key)) return t;
  // Decoded outside the lock: two threads may race on the same tile; both get identical data.
  const int64_t ts = h.tile_size;
  const codec::Rect r{tx * ts, ty * ts, std::min(ts, h.width - tx * ts), std::min(ts, h.height - ty * ts)};
  std::shared_ptr<Tile> t = std::make_shared_for_overwrite<Tile>(size_t(r.width * r.height));
  const codec::Status s = bd.decoder.decode_region(r, t.get(), r.width, thread_codec_scratch());
  if (s != codec::Status::Ok) {
    // Degrade (Throw has thrown): a zero residual, cached like a good tile so it is met once.
    damaged(level, b, &bd, s == codec::Status::ChecksumMismatch ? -1 : tx, ty, s);
    std::fill_n(t.get(), size_t(r.width * r.height), 0);
  }
  count_decoded(level, 1, uint64_t(r.width * r.height));
  std::lock_guard<std::mutex> lock(mutex_);
  if (map_.find(key) == map_.end()) {
    const size_t bytes = size_t(r.width * r.height) * sizeof(int32_t);
    lru_.push_front(Entry{key, t, bytes});
    map_[key] = lru_.begin();
    cache_bytes_ += bytes;
    while (cache_bytes_ > cache_capacity_ && lru_.size() > 1) {
      cache_bytes_ -= lru_.back().bytes;
      map_.erase(lru_.back().key);
      lru_.pop_back();
    }
  }
  return t;
}

void RegionDecoder::add_residual(int level, const Rect& rect, int32_t* out, int64_t out_stride,
                                 bool bulk) const {
  const auto& views = file_->bands(level);
  for (size_t b = file_->band_of_row(level, rect.y0); b < views.size(); ++b) {
    const BandView& view = views[b];
    if (view.y0 >= rect.y0 + rect.height) break;
    if (view.empty()) continue;  // an all-zero residual band: nothing to decode or add
    const Band* opened = band(level, b);
    if (!opened) continue;  // Degrade: a stream that does not open adds no residual
    const Band& bd = *opened;
    const int64_t y0 = std::max(rect.y0, view.y0), y1 = std::min(rect.y0 + rect.height, view.y0 + view.rows);
    const codec::Rect cr{rect.x0, y0 - view.y0, rect.width, y1 - y0};
    const codec::HeaderInfo& h = bd.decoder.header();
    const int64_t ts = h.tile_size;
    const int64_t tx0 = cr.x0 / ts, tx1 = (cr.x0 + cr.width - 1) / ts, ty0 = cr.y0 / ts,
                  ty1 = (cr.y0 + cr.height - 1) / ts;
    int32_t* band_out = out + (y0 - rect.y0) * out_stride;
    if (cache_capacity_ == 0) {
      thread_local std::vector<int32_t> residual;
      residual.resize(size_t(cr.width * cr.height));
      const codec::Status s = bd.decoder.decode_region(cr, residual.data(), cr.width, thread_codec_scratch());
      if (s != codec::Status::Ok) {
        // Tile by tile, so that each damaged part is found (and reported) and the good ones kept.
        for (int64_t ty = ty0; ty <= ty1; ++ty)
          for (int64_t tx = tx0; tx <= tx1; ++tx) {
            const int64_t xa = std::max(cr.x0, tx * ts), xb = std::min(cr.x0 + cr.width, (tx + 1) * ts);
            const int64_t ya = std::max(cr.y0, ty * ts), yb = std::min(cr.y0 + cr.height, (ty + 1) * ts);
            int32_t* dst = residual.data() + (ya - cr.y0) * cr.width + (xa - cr.x0);
            const codec::Status st = bd.decoder.decode_region(codec::Rect{xa, ya, xb - xa, yb - ya}, dst,
                                                              cr.width, thread_codec_scratch());
            if (st == codec::Status::Ok) continue;
            damaged(level, b, &bd, st == codec::Status::ChecksumMismatch ? -1 : tx, ty, st);
            for (int64_t y = 0; y < yb - ya; ++y) std::fill_n(dst + y * cr.width, xb - xa, 0);
          }
      }
      count_decoded(level, uint64_t((tx1 - tx0 + 1) * (ty1 - ty0 + 1)),
                    uint64_t(tiles_extent(tx0, tx1, ts, h.width) * tiles_extent(ty0, ty1, ts, h.height)));
      add_rows(band_out, out_stride, residual.data(), cr.width, cr.width, cr.height);
      continue;
    }
    uint64_t bulk_tiles = 0, bulk_samples = 0;
    for (int64_t ty = ty0; ty <= ty1; ++ty)
      for (int64_t tx = tx0; tx <= tx1; ++tx) {
        const int64_t tw = std::min(ts, h.width - tx * ts), th = std::min(ts, h.height - ty * ts);
        const int64_t x0 = std::max(cr.x0, tx * ts), x1 = std::min(cr.x0 + cr.width, tx * ts + tw);
        const int64_t ya = std::max(cr.y0, ty * ts), yb = std::min(cr.y0 + cr.height, ty * ts + th);
        int32_t* dst = band_out + (ya - cr.y0) * out_stride + (x0 - cr.x0);
        std::shared_ptr<const Tile> t;
        if (bulk && x1 - x0 == tw && yb - ya == th &&
            !(t = cached_tile(tile_key(level, b, ty * h.tiles_x + tx)))) {
          // A whole tile of a bulk request: added straight into out, not kept (see kBulkSide).
          const codec::Status s = bd.decoder.decode_region_add(codec::Rect{x0, ya, tw, th}, dst, out_stride,
                                                               thread_codec_scratch());
          // On failure out is untouched there: the coarser level shows, as Degrade wants.
          if (s != codec::Status::Ok)
            damaged(level, b, &bd, s == codec::Status::ChecksumMismatch ? -1 : tx, ty, s);
          bulk_tiles += 1;
          bulk_samples += uint64_t(tw * th);
          continue;
        }
        if (!t) t = residual_tile(level, b, bd, tx, ty);
        add_rows(dst, out_stride, t.get() + (ya - ty * ts) * tw + (x0 - tx * ts), tw, x1 - x0, yb - ya);
      }
    if (bulk_tiles) count_decoded(level, bulk_tiles, bulk_samples);
  }
}

void RegionDecoder::decode_units(int level, const Rect& rect, int32_t* out, int64_t out_stride) const {
  if (level < 0 || level >= file_->level_count())
    throw std::out_of_range("region decoder: no level " + std::to_string(level));
  const GridSize size = checked_size(*file_, level, rect);
  if (rect.width == 0 || rect.height == 0) return;
  if (level == 0) {
    for (int64_t y = 0; y < rect.height; ++y) std::fill_n(out + y * out_stride, rect.width, 0);
    add_residual(level, rect, out, out_stride, rect.width >= kBulkSide && rect.height >= kBulkSide);
    samples_ += uint64_t(rect.width * rect.height);
    return;
  }
  // Exactly the window U needs on rect, reconstructed one level coarser (about 4/3 of the area in all).
  const Rect need = upsample_required_window(rect, size);
  std::vector<int32_t>& coarse = thread_window(level - 1);
  coarse.resize(size_t(need.width * need.height));
  decode_units(level - 1, need, coarse.data(), need.width);
  decode_refined(level, rect, CoarseWindow{coarse.data(), need.width, need, file_->level_size(level - 1)},
                 out, out_stride);
}

void RegionDecoder::decode_refined(int level, const Rect& rect, const CoarseWindow& coarser, int32_t* out,
                                   int64_t out_stride, double* seconds_upsample,
                                   double* seconds_residual) const {
  if (level < 1 || level >= file_->level_count())
    throw std::out_of_range("region decoder: no level " + std::to_string(level) + " above a coarser one");
  const GridSize size = checked_size(*file_, level, rect);
  if (rect.width == 0 || rect.height == 0) return;
  const bool timed = seconds_upsample || seconds_residual;
  double up = 0, res = 0;
  // Strip by strip of whole residual tile rows (at least kStripRows rows), so that the residual is
  // added while U's output for the strip is still in cache: a whole level's U written first and
  // the residual added afterwards misses the cache on every sample. U is pointwise, so its strips
  // give exactly the samples of one call over the rectangle.
  UpsampleScratch& scratch = thread_upsample_scratch();
  const bool bulk = rect.width >= kBulkSide && rect.height >= kBulkSide;
  const auto& views = file_->bands(level);
  const int64_t rect_y1 = rect.y0 + rect.height;
  for (size_t b = file_->band_of_row(level, rect.y0); b < views.size(); ++b) {
    const BandView& view = views[b];
    if (view.y0 >= rect_y1) break;
    const int64_t y0 = std::max(rect.y0, view.y0), y1 = std::min(rect_y1, view.y0 + view.rows);
    int64_t strip = y1 - y0;
    if (!view.empty())
      if (const Band* bd = band(level, b)) {
        const int64_t ts = bd->decoder.header().tile_size;
        strip = ts * std::max<int64_t>(1, (kStripRows + ts - 1) / ts);
      }
    for (int64_t ya = y0, yb; ya < y1; ya = yb) {
      yb = std::min(y1, view.y0 + ((ya - view.y0) / strip + 1) * strip);
      const Rect part{rect.x0, ya, rect.width, yb - ya};
      int32_t* part_out = out + (ya - rect.y0) * out_stride;
      const Clock::time_point t0 = timed ? Clock::now() : Clock::time_point{};
      upsample_region(coarser, size, part, part_out, out_stride, scratch);
      const Clock::time_point t1 = timed ? Clock::now() : Clock::time_point{};
      add_residual(level, part, part_out, out_stride, bulk);
      if (timed) {
        up += std::chrono::duration<double>(t1 - t0).count();
        res += std::chrono::duration<double>(Clock::now() - t1).count();
      }
    }
  }
  if (seconds_upsample) *seconds_upsample += up;
  if (seconds_residual) *seconds_residual += res;
  samples_ += uint64_t(rect.width * rect.height);
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
