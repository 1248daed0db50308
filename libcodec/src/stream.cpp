// Stream container: fixed header (with its CRC32C), the tile payloads in raster order, then the tile
// index (varint payload sizes with per-tile CRC32C, and an index CRC). Also the public API entry points.
// Layout: docs/codec.md.
#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>

#include "codec/codec.h"
#include "codec/crc32c.h"
#include "codec/internal/quantizer.h"
#include "codec/internal/tile_coder.h"
#include "core/bytes.h"
#include "core/text.h"

namespace codec {

struct Scratch::Impl {
  struct IndexEntry {
    uint32_t size, crc;
  };
  detail::TileWork work;
  std::vector<IndexEntry> index;  // encoder: entries until the index is written
  // Decoder: band steps of the last (step, fraction bits) seen; computing them costs about as much as
  // decoding a few hundred samples, and region decoders ask for one small tile at a time.
  uint32_t steps_step_q8 = 0;
  int steps_fraction_bits = -1;
  detail::BandSteps steps{};
  const detail::BandSteps& band_steps(uint32_t step_q8, int fraction_bits) {
    if (step_q8 != steps_step_q8 || fraction_bits != steps_fraction_bits) {
      steps = fraction_bits == 0 ? detail::unit_band_steps() : detail::band_steps_for(step_q8, fraction_bits);
      steps_step_q8 = step_q8;
      steps_fraction_bits = fraction_bits;
    }
    return steps;
  }
};

Scratch::Scratch() : impl_(std::make_unique<Impl>()) {}
Scratch::~Scratch() = default;

namespace {

constexpr uint8_t kMagic[4] = {'T', 'P', 'T', 'C'};
constexpr size_t kHeaderSize = 56;
constexpr size_t kHeaderCrcOffset = 52;
constexpr size_t kMaxEntrySize = 5 + 4;  // varint payload size + CRC32C
constexpr uint32_t kFlagBoundMaxError = 1;
constexpr int64_t kMaxSide = int64_t(1) << 40;
constexpr uint32_t kMinTile = 16, kMaxTile = 4096;
constexpr double kRmsPerStep = 0.31457;  // sqrt(1/12 + 1/64)

using terrain::bytes::get_u16;
using terrain::bytes::get_u32;
using terrain::bytes::get_u64;
using terrain::bytes::put_u16;
using terrain::bytes::put_u32;
using terrain::bytes::put_u64;
size_t put_varint(uint8_t* p, uint32_t v) { return size_t(terrain::bytes::put_varint(p, v) - p); }
// A tile size in the index is at most 32 bits.
bool get_varint(const uint8_t*& p, const uint8_t* end, uint32_t* v) {
  uint64_t value = 0;
  if (!terrain::bytes::get_varint(p, end, &value, UINT32_MAX)) return false;
  *v = uint32_t(value);
  return true;
}

bool valid_tile_size(uint32_t t) { return t >= kMinTile && t <= kMaxTile && t % 16 == 0; }

int64_t ceil_div(int64_t a, int64_t b) { return (a + b - 1) / b; }

int tile_extent(int64_t image_side, int64_t tile, int64_t index) {
  return int(std::min(tile, image_side - index * tile));
}

struct StreamLayout {
  int64_t tiles_x, tiles_y;
  size_t index_bound;  // largest index (entries + CRC)
};

bool layout_for(int64_t w, int64_t h, uint32_t tile, StreamLayout* out) {
  if (w < 1 || h < 1 || w > kMaxSide || h > kMaxSide || !valid_tile_size(tile)) return false;
  out->tiles_x = ceil_div(w, tile);
  out->tiles_y = ceil_div(h, tile);
  const unsigned __int128 n = (unsigned __int128)out->tiles_x * out->tiles_y;
  if (n > (unsigned __int128)(SIZE_MAX / 32)) return false;
  out->index_bound = size_t(n) * kMaxEntrySize + 4;
  return true;
}

}  // namespace

const char* status_name(Status status) {
  static constexpr const char* kNames[] = {"ok",
                                           "output buffer too small",
                                           "truncated stream",
                                           "corrupt stream",
                                           "checksum mismatch",
                                           "unsupported stream version",
                                           "invalid argument",
                                           "sample value out of range"};
  return terrain::enum_name(status, kNames);
}

double predicted_rms(double step) { return step * kRmsPerStep; }
double step_for_target_rms(double target_rms) { return std::max(1.0, target_rms / kRmsPerStep); }

size_t encode_bound(int64_t width, int64_t height, const EncodeOptions& options) {
  StreamLayout layout;
  if (!layout_for(width, height, options.tile_size, &layout)) return 0;
  const int64_t t = options.tile_size;
  const int64_t full_x = width / t, full_y = height / t;
  const int rest_x = int(width % t), rest_y = int(height % t);
  unsigned __int128 total = kHeaderSize + layout.index_bound;
  const auto add = [&](int64_t count, int w, int h) {
    if (count > 0 && w > 0 && h > 0) total += (unsigned __int128)count * detail::tile_payload_bound(w, h);
  };
  add(full_x * full_y, int(t), int(t));
  add(full_y, rest_x, int(t));
  add(full_x, int(t), rest_y);
  add(1, rest_x, rest_y);
  return total > SIZE_MAX ? 0 : size_t(total);
}

Status encode(const int32_t* src, ptrdiff_t src_stride, int64_t width, int64_t height,
              const EncodeOptions& options, uint8_t* dst, size_t dst_capacity, size_t* bytes_written,
              Scratch& scratch, int32_t* recon, ptrdiff_t recon_stride) {
  assert(src && dst && bytes_written);
  assert(src_stride >= width && (!recon || recon_stride >= width));
  *bytes_written = 0;
  StreamLayout layout;
  if (!layout_for(width, height, options.tile_size, &layout)) return Status::InvalidArgument;
  if (options.bound_max_error && options.max_error > uint32_t(kMaxAbsSample)) return Status::InvalidArgument;
  // Measured on SRTM tiles (docs/codec.md): transform + corrections is smallest near S = 2E. A step
  // of 1 (the default) would make the transform lossless, which never beats spatial quantisation, so
  // it selects the automatic step too.
  const double step = options.bound_max_error && options.step <= 1.0 && options.step >= 0.0
                          ? std::clamp(2.0 * options.max_error, 1.0, double(kMaxAbsSample))
                          : options.step;
  if (!(step >= 1.0 && step <= double(kMaxAbsSample))) return Status::InvalidArgument;
  int32_t lo = 0, hi = 0;
  for (int64_t y = 0; y < height; ++y) {
    const int32_t* row = src + y * src_stride;
    for (int64_t x = 0; x < width; ++x) {
      lo = std::min(lo, row[x]);
      hi = std::max(hi, row[x]);
    }
  }
  if (hi > kMaxAbsSample || lo < -kMaxAbsSample) return Status::ValueOutOfRange;
  if (dst_capacity < kHeaderSize) return Status::BufferTooSmall;

  const uint32_t step_q8 = uint32_t(std::lround(step * 256.0));
  detail::TileParams params;
  const bool lossless = step_q8 <= detail::kStepOne;
  const bool fine = hi <= detail::kFineRange && lo >= -detail::kFineRange;
  params.fraction_bits = lossless ? 0 : fine ? detail::kFineFractionBits : detail::kWideFractionBits;
  params.steps = lossless ? detail::unit_band_steps() : detail::band_steps_for(step_q8, params.fraction_bits);
  params.bound_max_error = options.bound_max_error;
  params.max_error = options.bound_max_error ? options.max_error : 0;

  // Payloads first, then the index (its size depends on theirs), then the header that points at it.
  detail::TileWork& work = scratch.impl().work;
  const int64_t t = options.tile_size;
  const size_t tile_count = size_t(layout.tiles_x * layout.tiles_y);
  if (scratch.impl().index.size() < tile_count) scratch.impl().index.resize(tile_count);
  size_t pos = kHeaderSize;
  for (int64_t ty = 0; ty < layout.tiles_y; ++ty)
    for (int64_t tx = 0; tx < layout.tiles_x; ++tx) {
      const int tw = tile_extent(width, t, tx), th = tile_extent(height, t, ty);
      const int32_t* tile_src = src + ty * t * src_stride + tx * t;
      const size_t size = detail::encode_tile(tile_src, src_stride, tw, th, params, work, dst + pos,
                                              dst_capacity - pos, recon != nullptr);
      if (size == 0) return Status::BufferTooSmall;
      scratch.impl().index[size_t(ty * layout.tiles_x + tx)] = {uint32_t(size), crc32c(dst + pos, size)};
      pos += size;
      if (recon) {
        int32_t* out = recon + ty * t * recon_stride + tx * t;
        for (int y = 0; y < th; ++y)
          std::memcpy(out + y * recon_stride, work.reconstruction.data() + size_t(y) * tw,
                      size_t(tw) * sizeof(int32_t));
      }
    }
  const size_t index_offset = pos;
  for (size_t i = 0; i < tile_count; ++i) {
    uint8_t varint[5];
    const size_t length = put_varint(varint, scratch.impl().index[i].size);
    if (dst_capacity - pos < length + 4) return Status::BufferTooSmall;
    std::memcpy(dst + pos, varint, length);
    pos += length;
    put_u32(dst + pos, scratch.impl().index[i].crc);
    pos += 4;
  }
  if (dst_capacity - pos < 4) return Status::BufferTooSmall;
  put_u32(dst + pos, crc32c(dst + index_offset, pos - index_offset));
  pos += 4;

  uint8_t* h = dst;
  std::memset(h, 0, kHeaderSize);
  std::memcpy(h, kMagic, 4);
  put_u16(h + 4, uint16_t(kFormatVersion));
  put_u16(h + 6, uint16_t(kHeaderSize));
  put_u64(h + 8, uint64_t(width));
  put_u64(h + 16, uint64_t(height));
  put_u32(h + 24, options.tile_size);
  put_u32(h + 28, options.bound_max_error ? kFlagBoundMaxError : 0);
  put_u32(h + 32, step_q8);
  put_u32(h + 36, params.max_error);
  put_u32(h + 40, uint32_t(params.fraction_bits));
  put_u64(h + 44, index_offset);
  put_u32(h + kHeaderCrcOffset, crc32c(h, kHeaderCrcOffset));
  *bytes_written = pos;
  return Status::Ok;
}

Status read_header(const uint8_t* data, size_t size, HeaderInfo* header) {
  assert(header);
  if (!data) return Status::InvalidArgument;
  if (std::memcmp(data, kMagic, std::min<size_t>(size, 4)) != 0) return Status::Corrupt;
  if (size < 6) return Status::Truncated;
  if (get_u16(data + 4) != kFormatVersion) return Status::UnsupportedVersion;
  if (size < kHeaderSize) return Status::Truncated;
  if (crc32c(data, kHeaderCrcOffset) != get_u32(data + kHeaderCrcOffset)) return Status::ChecksumMismatch;
  if (get_u16(data + 6) != kHeaderSize) return Status::Corrupt;
  HeaderInfo info;
  info.version = kFormatVersion;
  const uint64_t w = get_u64(data + 8), h = get_u64(data + 16);
  info.tile_size = get_u32(data + 24);
  const uint32_t flags = get_u32(data + 28);
  const uint32_t step_q8 = get_u32(data + 32);
  info.max_error = get_u32(data + 36);
  if (w > uint64_t(kMaxSide) || h > uint64_t(kMaxSide)) return Status::Corrupt;
  info.width = int64_t(w);
  info.height = int64_t(h);
  StreamLayout layout;
  if (!layout_for(info.width, info.height, info.tile_size, &layout)) return Status::Corrupt;
  if ((flags & ~kFlagBoundMaxError) != 0 || step_q8 < detail::kStepOne) return Status::Corrupt;
  info.bound_max_error = (flags & kFlagBoundMaxError) != 0;
  if (info.max_error > uint32_t(kMaxAbsSample) || (!info.bound_max_error && info.max_error != 0))
    return Status::Corrupt;
  if (step_q8 > uint32_t(kMaxAbsSample) * 256u) return Status::Corrupt;
  // Lossless streams (step 1) have 0 fraction bits, lossy ones kFineFractionBits or kWideFractionBits.
  // (A decoder cannot tell whether the encoder's samples were fine-range; either value decodes safely.)
  const uint32_t fraction_bits = get_u32(data + 40);
  if (step_q8 <= detail::kStepOne ? fraction_bits != 0
                                  : fraction_bits != uint32_t(detail::kFineFractionBits) &&
                                        fraction_bits != uint32_t(detail::kWideFractionBits))
    return Status::Corrupt;
  const uint64_t index_offset = get_u64(data + 44);
  if (index_offset < kHeaderSize || index_offset > SIZE_MAX / 2) return Status::Corrupt;
  info.step = step_q8 / 256.0;
  info.tiles_x = layout.tiles_x;
  info.tiles_y = layout.tiles_y;
  info.index_offset = size_t(index_offset);
  info.data_offset = kHeaderSize;
  *header = info;
  return Status::Ok;
}

Status read_tile_index(const uint8_t* data, size_t size, const HeaderInfo& header, TileEntry* entries) {
  assert(data && entries);
  if (size < header.index_offset) return Status::Truncated;
  const uint8_t* p = data + header.index_offset;
  const uint8_t* const end = data + size;
  const int64_t t = header.tile_size;
  uint64_t offset = header.data_offset;
  for (int64_t ty = 0; ty < header.tiles_y; ++ty)
    for (int64_t tx = 0; tx < header.tiles_x; ++tx) {
      TileEntry entry;
      uint32_t tile_size = 0;
      if (!get_varint(p, end, &tile_size)) return p == end ? Status::Truncated : Status::Corrupt;
      if (end - p < 4) return Status::Truncated;
      entry.crc = get_u32(p);
      p += 4;
      entry.offset = offset;
      entry.size = tile_size;
      const size_t bound =
          detail::tile_payload_bound(tile_extent(header.width, t, tx), tile_extent(header.height, t, ty));
      if (entry.size < 1 || entry.size > bound) return Status::Corrupt;
      offset += entry.size;
      if (offset > header.index_offset) return Status::Corrupt;
      entries[size_t(ty * header.tiles_x + tx)] = entry;
    }
  if (offset != header.index_offset) return Status::Corrupt;  // payloads are back to back
  if (end - p < 4) return Status::Truncated;
  if (crc32c(data + header.index_offset, size_t(p - (data + header.index_offset))) != get_u32(p))
    return Status::ChecksumMismatch;
  return Status::Ok;
}

Status Decoder::open(const uint8_t* data, size_t size) {
  data_ = nullptr;
  size_ = 0;
  index_.clear();
  HeaderInfo header;
  Status s = read_header(data, size, &header);
  if (s != Status::Ok) return s;
  // Every tile takes at least 1 payload byte and 5 index bytes: reject impossible tile counts before
  // allocating the index (a forged header could otherwise ask for terabytes).
  if (uint64_t(header.tile_count()) > (size - header.data_offset) / 6) return Status::Truncated;
  std::vector<TileEntry> index(size_t(header.tile_count()));
  s = read_tile_index(data, size, header, index.data());
  if (s != Status::Ok) return s;
  data_ = data;
  size_ = size;
  header_ = header;
  index_ = std::move(index);
  return Status::Ok;
}

Status Decoder::decode_region(const Rect& rect, int32_t* dst, ptrdiff_t dst_stride, Scratch& scratch) const {
  assert(dst && dst_stride >= rect.width);
  if (!data_) return Status::InvalidArgument;
  if (rect.width < 1 || rect.height < 1 || rect.x0 < 0 || rect.y0 < 0 ||
      rect.x0 > header_.width - rect.width || rect.y0 > header_.height - rect.height)
    return Status::InvalidArgument;
  detail::TileParams params;
  params.fraction_bits = int(get_u32(data_ + 40));
  const uint32_t step_q8 = get_u32(data_ + 32);
  params.steps = scratch.impl().band_steps(step_q8, params.fraction_bits);
  params.bound_max_error = header_.bound_max_error;
  params.max_error = header_.max_error;
  detail::TileWork& work = scratch.impl().work;
  const int64_t t = header_.tile_size;
  const int64_t tx0 = rect.x0 / t, tx1 = (rect.x0 + rect.width - 1) / t;
  const int64_t ty0 = rect.y0 / t, ty1 = (rect.y0 + rect.height - 1) / t;
  for (int64_t ty = ty0; ty <= ty1; ++ty)
    for (int64_t tx = tx0; tx <= tx1; ++tx) {
      const TileEntry& entry = index_[size_t(ty * header_.tiles_x + tx)];
      const uint8_t* payload = data_ + entry.offset;
      if (crc32c(payload, entry.size) != entry.crc) return Status::ChecksumMismatch;
      const int tw = tile_extent(header_.width, t, tx), th = tile_extent(header_.height, t, ty);
      const int64_t x0 = std::max(rect.x0, tx * t), x1 = std::min(rect.x0 + rect.width, tx * t + tw);
      const int64_t y0 = std::max(rect.y0, ty * t), y1 = std::min(rect.y0 + rect.height, ty * t + th);
      const detail::TileWindow window{int(x0 - tx * t),
                                      int(y0 - ty * t),
                                      int(x1 - tx * t),
                                      int(y1 - ty * t),
                                      dst + (y0 - rect.y0) * dst_stride + (x0 - rect.x0),
                                      dst_stride};
      if (detail::decode_tile(payload, entry.size, tw, th, params, work, window) != detail::TileResult::Ok)
        return Status::Corrupt;
    }
  return Status::Ok;
}

Status decode(const uint8_t* data, size_t size, int32_t* dst, ptrdiff_t dst_stride, Scratch& scratch) {
  Decoder decoder;
  const Status s = decoder.open(data, size);
  if (s != Status::Ok) return s;
  return decoder.decode_region({0, 0, decoder.header().width, decoder.header().height}, dst, dst_stride,
                               scratch);
}

Status decode_region(const uint8_t* data, size_t size, const Rect& rect, int32_t* dst, ptrdiff_t dst_stride,
                     Scratch& scratch) {
  Decoder decoder;
  const Status s = decoder.open(data, size);
  if (s != Status::Ok) return s;
  return decoder.decode_region(rect, dst, dst_stride, scratch);
}

}  // namespace codec
