// Stream container: compact varint header, the tile payloads in raster order, then the tile index
// (varint records: a payload size, or a run of empty tiles), one CRC32C per tile row of payloads and
// a CRC32C over header and index. Also the public API entry points. Layout: docs/codec.md.
#include <algorithm>
#include <atomic>
#include <cassert>
#include <cmath>
#include <cstring>
#include <exception>
#include <memory>
#include <thread>
#include <vector>

#include "codec/codec.h"
#include "codec/crc32c.h"
#include "codec/internal/phase_coder.h"
#include "codec/internal/quantizer.h"
#include "codec/internal/tile_coder.h"
#include "core/bytes.h"
#include "core/fork_join.h"
#include "core/text.h"

namespace codec {

// The encoder's state for one chunk of tile rows (EncodeOptions::threads: chunks are coded at once).
struct EncodeChunk {
  detail::TileWork work;
  detail::PhaseRecord phase_record;  // the phase statistics pass's levels of the chunk's tiles, replayed
  std::unique_ptr<detail::PhaseCounts> counts;  // its token counts, added up over the chunks in order
  std::vector<uint8_t> body;                    // its payloads, back to back
  size_t size = 0;                              // payload bytes in body
  bool any_phase = false;                       // a tile kept the phase mode
  Status status = Status::Ok;
};

struct Scratch::Impl {
  detail::TileWork work;                             // decoder (the encoder's are its chunks')
  std::vector<std::unique_ptr<EncodeChunk>> chunks;  // encoder: chunk 0 is the calling thread's
  std::vector<uint32_t> tile_sizes;  // encoder: payload bytes per tile (0 = empty) until the index is written
  std::vector<uint8_t> body;         // encoder: payloads and index, until the header's size is known
  // Decoder: band steps of the last (step, fraction bits) seen; computing them costs about as much as
  // decoding a few hundred samples, and region decoders ask for one small tile at a time.
  uint32_t steps_step_q8 = 0;
  int steps_fraction_bits = -1;
  detail::BandSteps steps{}, lifting_steps{};
  void band_steps(uint32_t step_q8, int fraction_bits, detail::TileParams& params) {
    if (step_q8 != steps_step_q8 || fraction_bits != steps_fraction_bits) {
      steps = detail::stream_band_steps(step_q8, fraction_bits, false);
      lifting_steps = detail::stream_band_steps(step_q8, fraction_bits, true);
      steps_step_q8 = step_q8;
      steps_fraction_bits = fraction_bits;
    }
    params.steps = steps;
    params.lifting_steps = lifting_steps;
  }
};

Scratch::Scratch() : impl_(std::make_unique<Impl>()) {}
Scratch::~Scratch() = default;

namespace {

constexpr uint8_t kMagic[4] = {'T', 'P', 'T', 'C'};
constexpr size_t kFixedHeader = 6;  // magic + u16 version; varint fields follow
// Magic, version and the varints at their longest: sides (6 bytes each), tile size / 16 (2), flags
// (1), step * 256 (4), E (3), the phase model and the payload size (10).
constexpr size_t kMaxHeaderSize = kFixedHeader + 6 + 6 + 2 + 1 + 4 + 3 + detail::kPhaseModelBytes + 10;
constexpr uint32_t kPhaseVersion = 7;  // phase tiles with static token tables (6: adaptive binary, retired)
constexpr uint32_t kPhaseLanesVersion = 8;  // the same with two interleaved rANS states per tile
constexpr size_t kMaxRecordSize = 5;        // index record of a non-empty tile: size << 1 (< 2^33)
constexpr uint32_t kFlagBoundMaxError = 1;
constexpr uint32_t kFlagWideFraction = 2;  // lossy streams: kWideFractionBits (else kFineFractionBits)
constexpr uint32_t kFlagResidual = 4;      // format 5: transform-mode tiles use Transform::Residual
constexpr uint32_t kFlagPhase = 8;  // formats 7, 8: phase tiles (max-error: beside the others; else all)
constexpr int64_t kMaxSide = int64_t(1) << 40;
constexpr uint32_t kMinTile = 16, kMaxTile = 4096;
constexpr double kRmsPerStep = 0.31457;  // sqrt(1/12 + 1/64)
// Lossy tiles whose samples all lie within +-kEmptyProbeSteps steps are decoded by the encoder to see
// whether they reconstruct to zero; a tile with a larger sample never did on SRTM residuals, and
// probing every tile would cost an inverse transform each when the caller wants no reconstruction.
constexpr double kEmptyProbeSteps = 4.0;

using terrain::bytes::get_u16;
using terrain::bytes::get_u32;
using terrain::bytes::put_u16;
using terrain::bytes::put_u32;
using terrain::bytes::put_varint;

bool get_varint(const uint8_t*& p, const uint8_t* end, uint64_t* v) {
  return terrain::bytes::get_varint(p, end, v);
}

bool is_phase_version(uint32_t version) { return version == kPhaseVersion || version == kPhaseLanesVersion; }
// rANS states per phase tile in a stream of that version, and the version of a phase stream with that many.
int phase_lanes(uint32_t version) { return version == kPhaseLanesVersion ? 2 : 1; }
uint32_t phase_version(int lanes) { return lanes == 2 ? kPhaseLanesVersion : kPhaseVersion; }

bool valid_tile_size(uint32_t t) { return t >= kMinTile && t <= kMaxTile && t % 16 == 0; }

int64_t ceil_div(int64_t a, int64_t b) { return (a + b - 1) / b; }

int tile_extent(int64_t image_side, int64_t tile, int64_t index) {
  return int(std::min(tile, image_side - index * tile));
}

struct StreamLayout {
  int64_t tiles_x, tiles_y;
  size_t index_bound;  // largest index (records, row CRCs and the stream CRC)
};

bool layout_for(int64_t w, int64_t h, uint32_t tile, StreamLayout* out) {
  if (w < 1 || h < 1 || w > kMaxSide || h > kMaxSide || !valid_tile_size(tile)) return false;
  out->tiles_x = ceil_div(w, tile);
  out->tiles_y = ceil_div(h, tile);
  const unsigned __int128 n = (unsigned __int128)out->tiles_x * out->tiles_y;
  if (n > (unsigned __int128)(SIZE_MAX / 32)) return false;
  out->index_bound = size_t(n) * kMaxRecordSize + size_t(out->tiles_y) * 4 + 4;
  return true;
}

// Whether a tile's samples all lie within +-limit.
bool within(const int32_t* src, ptrdiff_t stride, int w, int h, int64_t limit) {
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (std::abs(int64_t(src[y * stride + x])) > limit) return false;
  return true;
}

// The phase tiles' bin in 1/256 samples: 2E + 1 in a max-error stream, else the step (rms streams).
uint32_t phase_bin_q8(bool bound_max_error, uint32_t max_error, uint32_t step_q8) {
  return bound_max_error ? 256 * (2 * max_error + 1) : step_q8;
}

// Rate-distortion test of a coded tile of small samples (rms and step streams): left empty, it costs
// no payload and about nothing in the index, and adds the squared error its coding removed. Worth
// coding when that error, at lambda bits per squared sample unit (the slope of an entropy-coded
// uniform quantiser at the step, as for the transform choice), outweighs its payload and index
// record. Measured (terrain-bench --quick, pyramid only, 13 shared DEMs, bits at equal finest rms):
// geometric mean -1.1 % at rms 1 m and -1.2 % at 2 m, Swabia -8 % at 1 m, Gothenburg -5 % at 2 m, no
// DEM above +0.1 %; three synthetic terrains -0.7 % / -1.3 %.
bool not_worth_coding(const int32_t* src, ptrdiff_t stride, int w, int h, const int32_t* recon, double lambda,
                      size_t payload_bytes) {
  double removed = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double v = src[y * stride + x], e = v - recon[size_t(y) * w + x];
      removed += v * v - e * e;
    }
  return lambda * removed < 8.0 * double(payload_bytes + 1);
}

bool all_zero(const int32_t* v, size_t n) {
  return std::all_of(v, v + n, [](int32_t x) { return x == 0; });
}

// What a stream's header records besides the payload size.
struct StreamFields {
  int64_t width, height;
  uint32_t tile_size;
  bool bound_max_error, wide_fraction;
  uint32_t step_q8, max_error;
  bool residual;
  bool phase;
  std::vector<uint8_t> phase_model;  // serialised PhaseModel (phase streams)
  int phase_lanes;                   // its rANS states per tile: 2 (format 8) or 1 (format 7)
};

// The second half of encoding, shared with splice_tiles: `body` holds the payloads of the non-empty
// tiles ([0, payload_end), raster order, sizes[i] bytes for tile i, 0 = empty); appends the tile
// index and the row CRCs to it, then writes header, body and stream CRC to dst.
Status finish_stream(const StreamFields& f, const StreamLayout& layout, const uint32_t* sizes,
                     std::vector<uint8_t>& body, size_t payload_end, uint8_t* dst, size_t dst_capacity,
                     size_t* bytes_written) {
  size_t pos = payload_end;
  const size_t tile_count = size_t(layout.tiles_x * layout.tiles_y);
  // Index records: size << 1 for a non-empty tile, (run - 1) << 1 | 1 for a run of empty tiles.
  for (size_t i = 0; i < tile_count;) {
    uint64_t record = uint64_t(sizes[i]) << 1;
    size_t next = i + 1;
    if (sizes[i] == 0) {
      while (next < tile_count && sizes[next] == 0) ++next;
      record = (uint64_t(next - i - 1) << 1) | 1;
    }
    if (body.size() < pos + terrain::bytes::kMaxVarintBytes) body.resize(2 * body.size() + 64);
    pos = size_t(put_varint(body.data() + pos, record) - body.data());
    i = next;
  }
  // A single tile row has no row CRC: the stream CRC covers its payloads.
  const bool single_row = layout.tiles_y == 1;
  size_t row_start = 0;
  for (int64_t ty = 0; ty < layout.tiles_y && !single_row; ++ty) {
    size_t row_bytes = 0;
    for (int64_t tx = 0; tx < layout.tiles_x; ++tx) row_bytes += sizes[size_t(ty * layout.tiles_x + tx)];
    if (row_bytes == 0) continue;
    if (body.size() < pos + 4) body.resize(2 * body.size() + 64);
    put_u32(body.data() + pos, crc32c(body.data() + row_start, row_bytes));
    pos += 4;
    row_start += row_bytes;
  }

  uint8_t header[kMaxHeaderSize];
  std::memcpy(header, kMagic, 4);
  put_u16(header + 4, uint16_t(f.phase      ? phase_version(f.phase_lanes)
                               : f.residual ? 5
                                            : kOldestFormatVersion));
  uint8_t* h = header + kFixedHeader;
  h = put_varint(h, uint64_t(f.width));
  h = put_varint(h, uint64_t(f.height));
  h = put_varint(h, f.tile_size / 16);
  h = put_varint(h, (f.bound_max_error ? kFlagBoundMaxError : 0) | (f.wide_fraction ? kFlagWideFraction : 0) |
                        (f.residual ? kFlagResidual : 0) | (f.phase ? kFlagPhase : 0));
  h = put_varint(h, f.step_q8);
  if (f.bound_max_error) h = put_varint(h, f.max_error);
  if (f.phase) {
    assert(f.phase_model.size() <= size_t(detail::kPhaseModelBytes));
    std::memcpy(h, f.phase_model.data(), f.phase_model.size());
    h += f.phase_model.size();
  }
  h = put_varint(h, payload_end);
  const size_t header_size = size_t(h - header);
  if (dst_capacity < header_size + 4 || dst_capacity - header_size - 4 < pos) return Status::BufferTooSmall;
  std::memcpy(dst, header, header_size);
  std::memcpy(dst + header_size, body.data(), pos);
  const size_t covered = single_row ? 0 : payload_end;
  const uint32_t crc = crc32c(body.data() + covered, pos - covered, crc32c(header, header_size));
  put_u32(dst + header_size + pos, crc);
  *bytes_written = header_size + pos + 4;
  return Status::Ok;
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
  unsigned __int128 total = kMaxHeaderSize + layout.index_bound;
  const auto add = [&](int64_t count, int w, int h) {
    if (count > 0 && w > 0 && h > 0) total += (unsigned __int128)count * detail::tile_payload_bound(w, h);
  };
  add(full_x * full_y, int(t), int(t));
  add(full_y, rest_x, int(t));
  add(full_x, int(t), rest_y);
  add(1, rest_x, rest_y);
  return total > SIZE_MAX ? 0 : size_t(total);
}

namespace {

// The first tile row of chunk c of n: an even split, so that every chunk and its bytes are a function
// of the image alone (the threads change only who codes them).
// First tile (raster order) of chunk c of n over `tiles` tiles.
int64_t chunk_first_tile(int64_t tiles, size_t c, size_t n) { return tiles * int64_t(c) / int64_t(n); }

// The phase statistics pass over tiles [k0, k1) (raster order): every non-empty tile coded in the phase mode
// for its token counts (whether or not the tile ends up in that mode), into the chunk's counts, from
// which the stream's model is fitted. With `record` (and recon, which then receives each tile's phase
// reconstruction) the pass also keeps every tile's levels in the chunk's record for the encoder to
// replay.
void phase_statistics_of_tiles(const int32_t* src, ptrdiff_t src_stride, int64_t width, int64_t height,
                               int64_t t, int64_t k0, int64_t k1, uint32_t bin_q8, int64_t empty_limit,
                               EncodeChunk& chunk, bool record, int32_t* recon, ptrdiff_t recon_stride) {
  detail::TileWork& work = chunk.work;
  if (!chunk.counts) chunk.counts = std::make_unique<detail::PhaseCounts>();
  *chunk.counts = detail::PhaseCounts{};
  const int64_t tiles_x = (width + t - 1) / t;
  if (record) chunk.phase_record.clear(size_t(tiles_x * ((height + t - 1) / t)));
  for (int64_t k = k0; k < k1; ++k) {
    const int64_t ty = k / tiles_x, tx = k % tiles_x;
    const int tw = tile_extent(width, t, tx), th = tile_extent(height, t, ty);
    const int32_t* tile_src = src + ty * t * src_stride + tx * t;
    if (within(tile_src, src_stride, tw, th, empty_limit)) continue;
    if (work.phase_recon.size() < size_t(tw) * th) work.phase_recon.resize(size_t(tw) * th);
    if (detail::phase_statistics(tile_src, src_stride, tw, th, bin_q8, work.phase_recon.data(),
                                 work.phase_work, chunk.counts.get(), record ? &chunk.phase_record : nullptr,
                                 size_t(k)) &&
        record)
      for (int y = 0; y < th; ++y)
        std::copy_n(work.phase_recon.data() + size_t(y) * tw, tw,
                    recon + (ty * t + y) * recon_stride + tx * t);
  }
}

// Whether [a, a + an) and [b, b + bn) share memory.
bool overlap(const int32_t* a, size_t an, const int32_t* b, size_t bn) {
  const auto pa = reinterpret_cast<uintptr_t>(a), pb = reinterpret_cast<uintptr_t>(b);
  return pa < pb + bn * sizeof(int32_t) && pb < pa + an * sizeof(int32_t);
}

}  // namespace

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
  const uint32_t step_q8 = uint32_t(std::lround(step * 256.0));
  detail::TileParams params;
  const bool lossless = step_q8 <= detail::kStepOne;
  const bool fine = hi <= detail::kFineRange && lo >= -detail::kFineRange;
  params.fraction_bits = lossless ? 0 : fine ? detail::kFineFractionBits : detail::kWideFractionBits;
  params.lifting = options.transform == Transform::Residual;
  scratch.impl().band_steps(step_q8, params.fraction_bits, params);
  params.lambda = 6.0 / (std::log(2.0) * step * step);
  params.bound_max_error = options.bound_max_error;
  params.max_error = options.bound_max_error ? options.max_error : 0;
  params.phase = options.phase_tiles;
  params.phase_bin_q8 = phase_bin_q8(options.bound_max_error, params.max_error, step_q8);
  // Tiles in chunks coded at once (EncodeOptions::threads), runs of whole tiles in raster order: a
  // band of one or two tile rows still splits into as many chunks as the runner has threads (split
  // by tile rows, a 16384-column band of 128 rows made two chunks, and a 16-thread build's rounds
  // idled while its finest bands ran on one thread each). Chunk 0 on this thread.
  const int64_t t = options.tile_size;
  const int64_t tile_total = layout.tiles_x * layout.tiles_y;
  const size_t chunk_count = size_t(std::clamp<int64_t>(int64_t(options.threads), 1, tile_total));
  std::vector<std::unique_ptr<EncodeChunk>>& chunks = scratch.impl().chunks;
  if (chunks.size() < chunk_count) chunks.resize(chunk_count);
  for (size_t c = 0; c < chunk_count; ++c)
    if (!chunks[c]) chunks[c] = std::make_unique<EncodeChunk>();
  const auto tiles_of = [&](size_t c) {
    return std::pair<int64_t, int64_t>{chunk_first_tile(tile_total, c, chunk_count),
                                       chunk_first_tile(tile_total, c + 1, chunk_count)};
  };
  detail::PhaseModel model;
  bool given_model = false;
  bool replay = false;
  if (params.phase) {
    HeaderInfo given;
    if (options.phase_model_stream &&
        read_header(options.phase_model_stream, options.phase_model_stream_size, &given) == Status::Ok) {
      given_model = given.phase_tiles;
      params.phase = given_model;  // spliceable into a stream without phase tiles: none either
      const uint8_t* p = given.phase_model.data();
      if (given_model && !detail::read_phase_model(p, p + given.phase_model.size(), &model))
        return Status::InvalidArgument;          // read_header checked it: cannot happen
      model.lanes = phase_lanes(given.version);  // a format-7 stream's tiles keep one state
    } else {
      // The replay writes each tile's phase reconstruction into recon during the statistics pass, so
      // it needs a recon that is not the source (a tile's other modes read the source afterwards).
      replay = recon && !overlap(src, size_t((height - 1) * src_stride + width), recon,
                                 size_t((height - 1) * recon_stride + width));
      terrain::fork_join(
          chunk_count,
          [&](size_t c) {
            const auto [k0, k1] = tiles_of(c);
            phase_statistics_of_tiles(src, src_stride, width, height, t, k0, k1, params.phase_bin_q8,
                                      params.max_error, *chunks[c], replay, recon, recon_stride);
          },
          options.part_runner);
      // Counts add up in any order (integers): the model is the one-pass model.
      detail::PhaseCounts& counts = *chunks[0]->counts;
      for (size_t c = 1; c < chunk_count; ++c)
        for (int k = 0; k < detail::kPhaseContexts; ++k)
          for (int s = 0; s < detail::kTokens; ++s) counts.counts[k][s] += chunks[c]->counts->counts[k][s];
      model = detail::fit_phase_model(counts);
    }
  }
  const detail::PhaseTables tables(model);
  params.phase_tables = &tables;
  // Tiles within +-empty_limit are empty outright: zeros meet the bound (lossless: 0, max-error: E).
  const int64_t empty_limit = params.max_error;
  const bool probe = !lossless && !options.bound_max_error;
  const int64_t probe_limit = int64_t(kEmptyProbeSteps * step);

  // Payloads first, then the index (its size depends on theirs), into scratch; then the header, which
  // records the payload size, and the body behind it into dst. (The copy costs far less than coding.)
  std::vector<uint32_t>& sizes = scratch.impl().tile_sizes;
  std::vector<uint8_t>& body = scratch.impl().body;
  const size_t tile_count = size_t(layout.tiles_x * layout.tiles_y);
  if (sizes.size() < tile_count) sizes.resize(tile_count);
  terrain::fork_join(
      chunk_count,
      [&](size_t c) {
        EncodeChunk& chunk = *chunks[c];
        // Chunk 0 codes into the stream's body (nothing to copy with one chunk).
        std::vector<uint8_t>& out = c == 0 ? body : chunk.body;
        detail::TileWork& work = chunk.work;
        size_t pos = 0;
        chunk.any_phase = false;
        chunk.status = Status::Ok;
        const auto [k0, k1] = tiles_of(c);
        for (int64_t k = k0; k < k1; ++k) {
          const int64_t ty = k / layout.tiles_x, tx = k % layout.tiles_x;
          const int tw = tile_extent(width, t, tx), th = tile_extent(height, t, ty);
          const int32_t* tile_src = src + ty * t * src_stride + tx * t;
          bool empty = within(tile_src, src_stride, tw, th, empty_limit);
          size_t size = 0;
          if (!empty) {
            const bool probing = probe && within(tile_src, src_stride, tw, th, probe_limit);
            const size_t bound = detail::tile_payload_bound(tw, th);
            if (out.size() < pos + bound) out.resize(std::max(pos + bound, out.size() * 2));
            const size_t tile = size_t(k);
            const detail::PhaseRecord& record = chunk.phase_record;
            detail::PhaseReplay rp;
            if (replay && record.tiles[tile].recorded)
              rp = detail::PhaseReplay{&record, tile, recon + ty * t * recon_stride + tx * t, recon_stride};
            size =
                detail::encode_tile(tile_src, src_stride, tw, th, params, work, out.data() + pos,
                                    out.size() - pos, recon != nullptr || probing, rp.record ? &rp : nullptr);
            if (size == 0) {
              chunk.status = Status::BufferTooSmall;
              return;
            }
            empty = probing && (all_zero(work.reconstruction.data(), size_t(tw) * th) ||
                                not_worth_coding(tile_src, src_stride, tw, th, work.reconstruction.data(),
                                                 params.lambda, size));
          }
          sizes[size_t(k)] = empty ? 0 : uint32_t(size);
          if (!empty) chunk.any_phase = chunk.any_phase || (params.phase && detail::is_phase_mode(out[pos]));
          if (!empty) pos += size;
          if (recon) {
            int32_t* dst_tile = recon + ty * t * recon_stride + tx * t;
            for (int y = 0; y < th; ++y) {
              if (empty)
                std::fill_n(dst_tile + y * recon_stride, tw, 0);
              else
                std::memcpy(dst_tile + y * recon_stride, work.reconstruction.data() + size_t(y) * tw,
                            size_t(tw) * sizeof(int32_t));
            }
          }
        }
        chunk.size = pos;
      },
      options.part_runner);
  size_t pos = 0;
  bool any_phase = false;
  for (size_t c = 0; c < chunk_count; ++c) {
    const EncodeChunk& chunk = *chunks[c];
    if (chunk.status != Status::Ok) return chunk.status;
    if (c > 0 && chunk.size > 0) {
      if (body.size() < pos + chunk.size) body.resize(std::max(pos + chunk.size, body.size() * 2));
      std::memcpy(body.data() + pos, chunk.body.data(), chunk.size);
    }
    pos += chunk.size;
    any_phase = any_phase || chunk.any_phase;
  }
  StreamFields fields{width,
                      height,
                      options.tile_size,
                      options.bound_max_error,
                      params.fraction_bits == detail::kWideFractionBits,
                      step_q8,
                      params.max_error,
                      params.lifting,
                      any_phase || given_model,
                      {},
                      model.lanes};
  // A stream without phase tiles is written as one that cannot have any (no model, version 5 or 4):
  // its other tiles do not depend on the flag. One that must splice into a phase stream keeps both.
  if (fields.phase) {
    uint8_t bytes[detail::kPhaseModelBytes];
    fields.phase_model.assign(bytes, bytes + detail::write_phase_model(model, bytes));
  }
  return finish_stream(fields, layout, sizes.data(), body, pos, dst, dst_capacity, bytes_written);
}

Status read_header(const uint8_t* data, size_t size, HeaderInfo* header) {
  assert(header);
  if (!data) return Status::InvalidArgument;
  if (std::memcmp(data, kMagic, std::min<size_t>(size, 4)) != 0) return Status::Corrupt;
  if (size < kFixedHeader) return Status::Truncated;
  const uint32_t version = get_u16(data + 4);
  // Version 6 (phase tiles with adaptive binary coding) was superseded by 7 within one release cycle.
  // 7 (one rANS state per phase tile) is still read: pyramid files of container 3.3 hold it.
  if (version < kOldestFormatVersion || version > kFormatVersion || version == 6)
    return Status::UnsupportedVersion;
  const uint8_t* p = data + kFixedHeader;
  const uint8_t* const end = data + size;
  uint64_t w = 0, h = 0, tile16 = 0, flags = 0, step_q8 = 0, max_error = 0, payload = 0;
  for (uint64_t* field : {&w, &h, &tile16, &flags, &step_q8})
    if (!get_varint(p, end, field)) return p == end ? Status::Truncated : Status::Corrupt;
  if ((flags & kFlagBoundMaxError) && !get_varint(p, end, &max_error))
    return p == end ? Status::Truncated : Status::Corrupt;
  const uint8_t* const model_begin = p;
  if (is_phase_version(version) && (flags & kFlagPhase)) {
    detail::PhaseModel model;
    if (!detail::read_phase_model(p, end, &model)) return p == end ? Status::Truncated : Status::Corrupt;
  }
  const uint8_t* const model_end = p;
  if (!get_varint(p, end, &payload)) return p == end ? Status::Truncated : Status::Corrupt;
  const size_t data_offset = size_t(p - data);
  // At least one index byte and the stream CRC follow the payloads.
  if (payload > size - data_offset || size - data_offset - payload < 5) return Status::Truncated;
  const size_t index_offset = data_offset + size_t(payload);
  // Streams of one tile row (height <= tile size) have no row CRC: the stream CRC covers the payloads.
  const bool single_row = tile16 != 0 && h <= tile16 * 16;
  const size_t covered = single_row ? data_offset : index_offset;
  if (crc32c(data + covered, size - 4 - covered, crc32c(data, data_offset)) != get_u32(end - 4))
    return Status::ChecksumMismatch;
  HeaderInfo info;
  info.version = version;
  if (w > uint64_t(kMaxSide) || h > uint64_t(kMaxSide) || tile16 > kMaxTile / 16) return Status::Corrupt;
  info.width = int64_t(w);
  info.height = int64_t(h);
  info.tile_size = uint32_t(tile16 * 16);
  StreamLayout layout;
  if (!layout_for(info.width, info.height, info.tile_size, &layout)) return Status::Corrupt;
  // Version 4 knows two flags; version 5 adds the residual transform, and a version-5 stream must use
  // it (encoders write 4 otherwise); versions 7 and 8 add phase tiles (one or two rANS states), which
  // they must allow (in any stream, with either transform). So every stream has exactly one valid
  // version, but for phase streams, whose version says how their tiles are coded.
  const uint64_t known = kFlagBoundMaxError | kFlagWideFraction | (version >= 5 ? kFlagResidual : 0) |
                         (is_phase_version(version) ? kFlagPhase : 0);
  const bool phase = (flags & kFlagPhase) != 0;
  if ((flags & ~known) != 0 || (version == 5) != ((flags & kFlagResidual) != 0 && !phase) ||
      is_phase_version(version) != phase || step_q8 < detail::kStepOne ||
      step_q8 > uint64_t(kMaxAbsSample) * 256u || max_error > uint64_t(kMaxAbsSample))
    return Status::Corrupt;
  // Lossless streams (step 1) have 0 fraction bits, lossy ones kFineFractionBits or kWideFractionBits.
  // (A decoder cannot tell whether the encoder's samples were fine-range; either value decodes safely.)
  const bool wide = (flags & kFlagWideFraction) != 0;
  if (step_q8 == detail::kStepOne && wide) return Status::Corrupt;
  info.bound_max_error = (flags & kFlagBoundMaxError) != 0;
  info.max_error = uint32_t(max_error);
  info.transform = (flags & kFlagResidual) ? Transform::Residual : Transform::Lapped;
  info.phase_tiles = phase;
  info.phase_model.assign(model_begin, model_end);
  info.fraction_bits = step_q8 == detail::kStepOne ? 0
                       : wide                      ? detail::kWideFractionBits
                                                   : detail::kFineFractionBits;
  info.step = double(step_q8) / 256.0;
  info.tiles_x = layout.tiles_x;
  info.tiles_y = layout.tiles_y;
  info.index_offset = index_offset;
  info.data_offset = data_offset;
  *header = info;
  return Status::Ok;
}

Status read_tile_index(const uint8_t* data, size_t size, const HeaderInfo& header,
                       std::vector<TileEntry>* entries, std::vector<RowChecksum>* rows) {
  assert(data && entries && rows);
  entries->clear();
  rows->clear();
  if (size < header.index_offset + 4) return Status::Truncated;
  const uint8_t* p = data + header.index_offset;
  const uint8_t* const end = data + size - 4;  // the stream CRC (read_header checked it)
  const int64_t t = header.tile_size, tiles = header.tile_count();
  uint64_t offset = header.data_offset;
  for (int64_t n = 0; n < tiles;) {
    uint64_t record = 0;
    if (!get_varint(p, end, &record)) return p == end ? Status::Truncated : Status::Corrupt;
    TileEntry entry;
    entry.first_tile = n;
    entry.offset = offset;
    if (record & 1) {
      // Runs are maximal: two in a row would be one longer run.
      if ((record >> 1) >= uint64_t(tiles - n) || (!entries->empty() && entries->back().size == 0))
        return Status::Corrupt;
      entry.count = int64_t(record >> 1) + 1;
    } else {
      const int64_t tx = n % header.tiles_x, ty = n / header.tiles_x;
      const uint64_t bound =
          detail::tile_payload_bound(tile_extent(header.width, t, tx), tile_extent(header.height, t, ty));
      entry.size = uint32_t(std::min<uint64_t>(record >> 1, UINT32_MAX));
      if (entry.size < 1 || (record >> 1) > bound || entry.size > header.index_offset - offset)
        return Status::Corrupt;
      if (rows->empty() || rows->back().tile_row != ty) rows->push_back({ty, offset, 0, 0});
      rows->back().size += entry.size;
      offset += entry.size;
    }
    n += entry.count;
    entries->push_back(entry);
  }
  if (offset != header.index_offset) return Status::Corrupt;  // payloads are back to back
  for (RowChecksum& row : *rows) {
    if (header.tiles_y == 1) break;  // covered by the stream CRC
    if (end - p < 4) return Status::Truncated;
    row.crc = get_u32(p);
    p += 4;
  }
  if (p != end) return Status::Corrupt;  // the index ends at the stream CRC
  return Status::Ok;
}

// One flag per tile row with payload: set once its CRC has matched.
struct Decoder::RowState {
  explicit RowState(size_t n) : checked(new std::atomic<bool>[n]) {
    for (size_t i = 0; i < n; ++i) checked[i].store(false, std::memory_order_relaxed);
  }
  std::unique_ptr<std::atomic<bool>[]> checked;
};

Decoder::Decoder() = default;
Decoder::~Decoder() = default;
Decoder::Decoder(Decoder&&) noexcept = default;
Decoder& Decoder::operator=(Decoder&&) noexcept = default;

Status Decoder::open(const uint8_t* data, size_t size) {
  data_ = nullptr;
  size_ = 0;
  index_.clear();
  rows_.clear();
  row_state_.reset();
  phase_tables_.reset();
  HeaderInfo header;
  Status s = read_header(data, size, &header);
  if (s != Status::Ok) return s;
  std::vector<TileEntry> index;
  std::vector<RowChecksum> rows;
  s = read_tile_index(data, size, header, &index, &rows);
  if (s != Status::Ok) return s;
  data_ = data;
  size_ = size;
  header_ = header;
  index_ = std::move(index);
  rows_ = std::move(rows);
  row_state_ = std::make_unique<RowState>(rows_.size());
  if (header_.phase_tiles) {
    detail::PhaseModel model;
    const uint8_t* p = header_.phase_model.data();
    detail::read_phase_model(p, p + header_.phase_model.size(), &model);  // read_header checked it
    model.lanes = phase_lanes(header_.version);
    phase_tables_ = std::make_unique<detail::PhaseTables>(model);
  }
  if (header_.tiles_y == 1 && !rows_.empty())  // read_header checked the payloads with the stream CRC
    row_state_->checked[0].store(true, std::memory_order_relaxed);
  return Status::Ok;
}

const TileEntry& Decoder::entry_of(int64_t tile) const {
  const auto it = std::upper_bound(index_.begin(), index_.end(), tile,
                                   [](int64_t n, const TileEntry& e) { return n < e.first_tile; });
  return *(it - 1);
}

// Two threads may both verify a row the first time; both get the same answer.
Status Decoder::check_row(int64_t tile_row) const {
  const auto it = std::lower_bound(rows_.begin(), rows_.end(), tile_row,
                                   [](const RowChecksum& r, int64_t ty) { return r.tile_row < ty; });
  assert(it != rows_.end() && it->tile_row == tile_row);
  std::atomic<bool>& checked = row_state_->checked[size_t(it - rows_.begin())];
  if (checked.load(std::memory_order_acquire)) return Status::Ok;
  if (crc32c(data_ + it->offset, size_t(it->size)) != it->crc) return Status::ChecksumMismatch;
  checked.store(true, std::memory_order_release);
  return Status::Ok;
}

Status Decoder::decode_region(const Rect& rect, int32_t* dst, ptrdiff_t dst_stride, Scratch& scratch) const {
  return decode_into(rect, dst, dst_stride, scratch, false);
}

Status Decoder::decode_region_add(const Rect& rect, int32_t* dst, ptrdiff_t dst_stride,
                                  Scratch& scratch) const {
  return decode_into(rect, dst, dst_stride, scratch, true);
}

Status Decoder::decode_into(const Rect& rect, int32_t* dst, ptrdiff_t dst_stride, Scratch& scratch,
                            bool add) const {
  assert(dst && dst_stride >= rect.width);
  if (!data_) return Status::InvalidArgument;
  if (rect.width < 1 || rect.height < 1 || rect.x0 < 0 || rect.y0 < 0 ||
      rect.x0 > header_.width - rect.width || rect.y0 > header_.height - rect.height)
    return Status::InvalidArgument;
  detail::TileParams params;
  params.fraction_bits = header_.fraction_bits;
  params.lifting = header_.transform == Transform::Residual;
  scratch.impl().band_steps(uint32_t(std::lround(header_.step * 256.0)), params.fraction_bits, params);
  params.bound_max_error = header_.bound_max_error;
  params.max_error = header_.max_error;
  params.phase = header_.phase_tiles;
  params.phase_tables = phase_tables_.get();
  params.phase_bin_q8 =
      phase_bin_q8(header_.bound_max_error, header_.max_error, uint32_t(std::lround(header_.step * 256.0)));
  detail::TileWork& work = scratch.impl().work;
  const int64_t t = header_.tile_size;
  const int64_t tx0 = rect.x0 / t, tx1 = (rect.x0 + rect.width - 1) / t;
  const int64_t ty0 = rect.y0 / t, ty1 = (rect.y0 + rect.height - 1) / t;
  for (int64_t ty = ty0; ty <= ty1; ++ty) {
    bool row_checked = false;
    for (int64_t tx = tx0; tx <= tx1; ++tx) {
      const TileEntry& entry = entry_of(ty * header_.tiles_x + tx);
      const int tw = tile_extent(header_.width, t, tx), th = tile_extent(header_.height, t, ty);
      const int64_t x0 = std::max(rect.x0, tx * t), x1 = std::min(rect.x0 + rect.width, tx * t + tw);
      const int64_t y0 = std::max(rect.y0, ty * t), y1 = std::min(rect.y0 + rect.height, ty * t + th);
      int32_t* out = dst + (y0 - rect.y0) * dst_stride + (x0 - rect.x0);
      if (entry.size == 0) {  // adds nothing
        if (!add)
          for (int64_t y = y0; y < y1; ++y) std::fill_n(out + (y - y0) * dst_stride, x1 - x0, 0);
        continue;
      }
      if (!row_checked) {
        const Status s = check_row(ty);
        if (s != Status::Ok) return s;
        row_checked = true;
      }
      const detail::TileWindow window{
          int(x0 - tx * t), int(y0 - ty * t), int(x1 - tx * t), int(y1 - ty * t), out, dst_stride, add};
      if (detail::decode_tile(data_ + entry.offset, entry.size, tw, th, params, work, window) !=
          detail::TileResult::Ok)
        return Status::Corrupt;
    }
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

namespace codec {
namespace {

// One side of a splice: its header and, per tile, the payload (null/0 = empty).
struct SpliceSource {
  bool present = false;
  HeaderInfo header;
  std::vector<const uint8_t*> tile_data;
  std::vector<uint32_t> tile_size;
};

Status open_splice_source(const uint8_t* data, size_t size, SpliceSource* src) {
  if (!data || size == 0) return Status::Ok;
  Status s = read_header(data, size, &src->header);
  if (s != Status::Ok) return s;
  std::vector<TileEntry> entries;
  std::vector<RowChecksum> rows;
  if ((s = read_tile_index(data, size, src->header, &entries, &rows)) != Status::Ok) return s;
  // Payloads are copied verbatim: check them first, so a damaged row is never carried forward.
  for (const RowChecksum& r : rows)
    if (src->header.tiles_y > 1 && crc32c(data + r.offset, size_t(r.size)) != r.crc)
      return Status::ChecksumMismatch;
  const size_t n = size_t(src->header.tile_count());
  src->tile_data.assign(n, nullptr);
  src->tile_size.assign(n, 0);
  for (const TileEntry& e : entries)
    if (e.size > 0) {
      src->tile_data[size_t(e.first_tile)] = data + e.offset;
      src->tile_size[size_t(e.first_tile)] = e.size;
    }
  src->present = true;
  return Status::Ok;
}

bool same_coding(const HeaderInfo& a, const HeaderInfo& b) {
  return a.width == b.width && a.height == b.height && a.tile_size == b.tile_size &&
         a.bound_max_error == b.bound_max_error && a.max_error == b.max_error && a.step == b.step &&
         a.fraction_bits == b.fraction_bits && a.transform == b.transform && a.phase_tiles == b.phase_tiles &&
         a.phase_model == b.phase_model && a.version == b.version;
}

}  // namespace

Status splice_tiles(const uint8_t* old_data, size_t old_size, const uint8_t* fresh_data, size_t fresh_size,
                    const std::vector<uint8_t>& take_fresh, std::vector<uint8_t>* out) {
  assert(out);
  out->clear();
  SpliceSource old_src, fresh_src;
  Status s = open_splice_source(old_data, old_size, &old_src);
  if (s != Status::Ok) return s;
  if ((s = open_splice_source(fresh_data, fresh_size, &fresh_src)) != Status::Ok) return s;
  if (!old_src.present && !fresh_src.present) return Status::InvalidArgument;
  if (old_src.present && fresh_src.present && !same_coding(old_src.header, fresh_src.header))
    return Status::InvalidArgument;
  const HeaderInfo& h = old_src.present ? old_src.header : fresh_src.header;
  const size_t n = size_t(h.tile_count());
  if (take_fresh.size() != n) return Status::InvalidArgument;
  StreamLayout layout;
  if (!layout_for(h.width, h.height, h.tile_size, &layout)) return Status::InvalidArgument;
  std::vector<uint32_t> sizes(n, 0);
  std::vector<uint8_t> body;
  size_t pos = 0;
  for (size_t i = 0; i < n; ++i) {
    const SpliceSource& src = take_fresh[i] ? fresh_src : old_src;
    if (!src.present || src.tile_size[i] == 0) continue;
    sizes[i] = src.tile_size[i];
    body.insert(body.end(), src.tile_data[i], src.tile_data[i] + sizes[i]);
    pos += sizes[i];
  }
  if (pos == 0) return Status::Ok;  // every tile empty: no stream
  const StreamFields fields{h.width,
                            h.height,
                            h.tile_size,
                            h.bound_max_error,
                            h.fraction_bits == detail::kWideFractionBits,
                            uint32_t(std::lround(h.step * 256.0)),
                            h.max_error,
                            h.transform == Transform::Residual,
                            h.phase_tiles,
                            h.phase_model,
                            phase_lanes(h.version)};
  out->resize(kMaxHeaderSize + 4 + pos + size_t(layout.index_bound));
  size_t written = 0;
  if ((s = finish_stream(fields, layout, sizes.data(), body, pos, out->data(), out->size(), &written)) !=
      Status::Ok)
    return s;
  out->resize(written);
  return Status::Ok;
}

}  // namespace codec
