// libcodec: PTC-style lapped-transform coder for integer images (terrain residuals and DEM levels).
//
// Pipeline per tile: 4-point overlap pre-filter across internal block edges (a stronger, expanding
// one in lossy streams) -> reversible 4x4 integer lifting transform -> (lossy: overlap filter across
// macroblock edges on the block DCs) -> second 4x4 stage on the block DCs of each macroblock -> dead-zone
// quantiser with per-band steps -> adaptive run-length/Golomb-Rice (RLGR) coding of DC, LP and HP bands
// with separate backward-adaptive states. Tiles are independent (hard tile edges), so any rectangle
// decodes from the tiles it intersects. Bitstream: docs/codec.md.
//
// Supported input: int32 samples with |value| <= kMaxAbsSample (2^20); larger values make encode()
// return Status::ValueOutOfRange. Within that range no intermediate value overflows.
//
// What "step S" means: every band is quantised with step S / g_b, where g_b is the sample-domain
// (synthesis) norm of band b's basis functions, so each band adds the same error energy per unit step.
// For data whose coefficients are spread over many steps the sample-domain rms error is
//   rms ~= S * sqrt(1/12 + 1/64) ~= 0.315 * S           (predicted_rms(S))
// (the 1/64 comes from the dead zone: the quantiser rounds |c|/step + 3/8 down and reconstructs at
// (|q| + 1/16) * step, i.e. 1/16 step below the bin centre). Smooth data, where many coefficients fall in the
// dead zone, gets a lower rms. S = 1 is exactly lossless. Bands whose S / g_b is below 1 use step 1.
//
// Max-error mode guarantees |decoded - input| <= E at every sample: each tile is coded either by the
// transform at step S plus a sparse correction layer, or by spatial quantisation with step 2E+1 coded
// losslessly; the encoder keeps the smaller one per tile and records the choice.
//
// Errors: functions return a Status for bad data; caller mistakes (null pointers, bad strides) assert.
// Nothing throws except std::bad_alloc.
// Threads: all functions are reentrant; give each thread its own Scratch.
// Untrusted input: read_header, read_tile_index, Decoder and decode/decode_region are safe on any
// bytes, forged checksums included (every size and offset is checked before use; the index holds one
// entry per index record, not per tile, so its memory is bounded by the stream's size even when a
// few bytes announce 2^40 empty tiles; fuzz/fuzz_codec_decode.cpp): they return a Status.
// Empty tiles: a tile that decodes to all zeros (lossless: all-zero input; max-error mode: every
// |sample| <= E; otherwise a reconstruction that is all zero) is stored as a mark in the index, with
// no payload; runs of them cost one varint.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "codec/crc32c.h"
#include "core/fork_join.h"
#include "core/rect.h"

namespace codec {
namespace detail {
struct PhaseTables;
}

inline constexpr int32_t kMaxAbsSample = 1 << 20;  // largest |input sample| the coder accepts
// Stream format versions: 5 adds the residual transform (EncodeOptions::transform), 7 the phase tiles
// (EncodeOptions::phase_tiles) with static token tables and one rANS state per tile, 8 the same with
// two interleaved states (decoded about 1.1-1.8x faster); 6 held the first phase tiles (adaptive
// binary coding, never in a release) and is rejected as unsupported. An encoder writes the lowest
// version that holds what a stream uses (4 for lapped streams without phase tiles, 8 for phase
// streams, 7 only for tiles spliced into a format-7 stream), so those keep the bytes of earlier
// releases. Decoders read 4, 5, 7 and 8.
inline constexpr uint32_t kFormatVersion = 8;
inline constexpr uint32_t kOldestFormatVersion = 4;

// The transform of transform-mode tiles.
enum class Transform {
  Lapped = 0,    // two-stage lapped transform (4x4 blocks, 16x16 macroblocks): whole images, coarse levels
  Residual = 1,  // one level of the four-point lifting wavelet (format 5): closed-loop pyramid residuals,
                 // whose information is in the detail bands (measured: 8-17 % smaller pyramids)
};

enum class Status {
  Ok = 0,
  BufferTooSmall,      // the output buffer cannot hold the result
  Truncated,           // the stream ends before the data its header/index announce
  Corrupt,             // inconsistent header, index or bitstream
  ChecksumMismatch,    // a CRC32C (header + index, or a tile row's payloads) does not match
  UnsupportedVersion,  // right magic, unknown format version
  InvalidArgument,     // bad options or region (e.g. step < 1, rectangle outside the image)
  ValueOutOfRange,     // an input sample exceeds +-kMaxAbsSample
};
// A short lower-case description ("checksum mismatch"), static storage; "unknown status" for values
// outside the enum.
const char* status_name(Status status);

struct EncodeOptions {
  double step = 1.0;             // absolute quantiser step in sample units (>= 1; 1 = lossless);
                                 // in max-error mode a step of 0 or 1 (the default) picks
                                 // 2 * max_error, the measured best for the transform tiles
  bool bound_max_error = false;  // guarantee |error| <= max_error at every sample
  uint32_t max_error = 0;        // E for max-error mode (0 = lossless); at most kMaxAbsSample
  uint32_t tile_size = 64;       // tile side in samples: multiple of 16 in [16, 4096]
  Transform transform = Transform::Lapped;
  // Tiles coded by their four polyphase components, predicted from decoded neighbours (format 7). Made
  // for the residuals of a pyramid whose coarse levels are the fine levels' even-even samples: their
  // even phase is within the coarse level's error and costs no bits. Max-error streams (E may be 0:
  // lossless): bins of 2E + 1, and the encoder picks the smallest mode per tile. Other streams: every
  // tile is a phase tile with the step as a real-valued bin (errors within half a bin plus the
  // rounding of the output, rms about step / sqrt(12)). The stream's header names the static token
  // distribution of each context (about 40 bytes), fitted to all of its tiles.
  bool phase_tiles = false;
  // Phase tiles: code so that the tiles can be spliced into this stream (phase_model_stream_size
  // bytes; splice_tiles requires one model): with its token distributions instead of fitted ones
  // when it has phase tiles, without phase tiles when it has none. Untrusted input: a stream that
  // does not open (read_header) is ignored.
  const uint8_t* phase_model_stream = nullptr;
  size_t phase_model_stream_size = 0;
  // Experimental: threads that encode() codes the image's tiles on, the calling thread included (1,
  // the default: the calling thread alone; at most one per tile). The others are started and joined
  // within the call. The stream and the reconstruction are the same for any value (the tiles, in
  // raster order, are split into even runs and joined in order); the Scratch then keeps a coder
  // state and a payload buffer per thread.
  uint32_t threads = 1;
  // Experimental: runs those chunks of tiles (threads of them) on the runner's threads instead of
  // threads started within the call (null, the default). The stream does not depend on it.
  terrain::PartRunner* part_runner = nullptr;
};

// Step giving about `target_rms` sample-domain rms error (inverse of predicted_rms); never below 1.
double step_for_target_rms(double target_rms);
// Predicted sample-domain rms error of step S for data with spread-out coefficients (see above).
double predicted_rms(double step);

// Everything the stream header records.
struct HeaderInfo {
  uint32_t version = 0;  // kOldestFormatVersion .. kFormatVersion
  Transform transform = Transform::Lapped;
  int64_t width = 0, height = 0;     // samples, 1 .. 2^40
  uint32_t tile_size = 0;            // tile side in samples
  int64_t tiles_x = 0, tiles_y = 0;  // tiles per row and column (the last ones may be partial)
  double step = 1.0;                 // as recorded (1/256 resolution)
  bool bound_max_error = false;      // a max-error stream
  bool phase_tiles = false;          // formats 7 and 8: its tiles may use the phase mode
  std::vector<uint8_t> phase_model;  // format 7 and 8 phase streams: the token model (docs/codec.md)
  uint32_t max_error = 0;            // its E (0 otherwise)
  int fraction_bits = 0;             // extra sample precision of the transform (0 = lossless)
  size_t index_offset = 0;           // byte offset of the tile index (it follows the payloads)
  size_t data_offset = 0;            // byte offset of the first tile payload (end of the header)
  int64_t tile_count() const { return tiles_x * tiles_y; }
  // Every tile is empty (decodes to zeros): the stream has no payload bytes.
  bool empty() const { return index_offset == data_offset; }
};

// One index record: a non-empty tile (size > 0) or a run of `count` empty tiles (size 0).
struct TileEntry {
  int64_t first_tile = 0;  // raster number of its (first) tile
  int64_t count = 1;       // tiles it covers: 1 for a non-empty tile
  uint64_t offset = 0;     // payload offset from the start of the stream (where it would be, if empty)
  uint32_t size = 0;       // payload bytes; 0 = empty
};

// The payloads of one tile row, checked as a whole by one CRC32C (rows of empty tiles have none).
struct RowChecksum {
  int64_t tile_row = 0;
  uint64_t offset = 0, size = 0;  // the row's payload bytes (its tiles are back to back)
  uint32_t crc = 0;
};

// A rectangle of samples: columns x0 .. x0 + width - 1, rows y0 .. y0 + height - 1 (core/rect.h).
using Rect = terrain::Rect;

// Caller-owned working memory. Buffers grow on first use and are reused, so steady-state encode and
// decode calls do not allocate. One per thread (not thread-safe); any Scratch serves any stream.
class Scratch {
 public:
  Scratch();
  ~Scratch();
  Scratch(const Scratch&) = delete;
  Scratch& operator=(const Scratch&) = delete;
  struct Impl;
  Impl& impl() { return *impl_; }

 private:
  std::unique_ptr<Impl> impl_;
};

// Upper bound of the encoded size in bytes of a width x height image with these options: a dst of this
// capacity never gives BufferTooSmall. 0 when the size or the tile size is invalid (or the bound
// exceeds size_t).
size_t encode_bound(int64_t width, int64_t height, const EncodeOptions& options);

// Encodes width x height samples (row r starts at src + r * src_stride; strides count samples) into
// dst[0 .. dst_capacity). On Ok, *bytes_written holds the stream size. When recon is not null it
// receives exactly what decode() will return (for closed-loop residual pyramids).
// Returns InvalidArgument for a size outside 1 .. 2^40 a side, a bad tile size, step or max_error;
// ValueOutOfRange for a sample beyond +-kMaxAbsSample; BufferTooSmall when dst_capacity is short
// (size it with encode_bound). On any status but Ok, dst and recon hold unspecified data.
Status encode(const int32_t* src, ptrdiff_t src_stride, int64_t width, int64_t height,
              const EncodeOptions& options, uint8_t* dst, size_t dst_capacity, size_t* bytes_written,
              Scratch& scratch, int32_t* recon = nullptr, ptrdiff_t recon_stride = 0);

// Parses and checks the header (magic, version, the CRC that covers header and index, sizes) without
// decoding: Ok and *header filled, or Corrupt (wrong magic, inconsistent fields), Truncated,
// UnsupportedVersion (a version outside kOldestFormatVersion .. kFormatVersion, or 6), ChecksumMismatch;
// InvalidArgument for a null data. `size` must be the stream's exact size (the CRC is its last 4 bytes).
// *header is written only on Ok.
Status read_header(const uint8_t* data, size_t size, HeaderInfo* header);
// Reads the tile index: *entries gets its records in raster order (they cover every tile once), *rows
// the tile rows that have payload bytes, top to bottom, with their CRCs (not yet compared with the
// payloads: the Decoder does that when it first touches a row; a stream of one tile row stores no
// row CRC, crc is then 0: read_header's CRC covered its payloads). Checks that each size is at most the
// largest payload its tile can produce, that the payloads fill [data_offset, index_offset) back to
// back and that the index ends where the stream's CRC begins. Offsets are running sums of the stored
// sizes. `header` must come from read_header on the same bytes. Memory is bounded by the index size.
// Returns Ok, Truncated or Corrupt; on failure the vectors hold unspecified records.
Status read_tile_index(const uint8_t* data, size_t size, const HeaderInfo& header,
                       std::vector<TileEntry>* entries, std::vector<RowChecksum>* rows);

// Builds one stream from two streams of the same image and coding parameters (width, height, tile
// size, max-error flag and E, step, fraction bits): tile i's payload is copied byte for byte from
// `fresh` where take_fresh[i] is non-zero, else from `old`. Tiles are coded independently, so the
// result decodes every tile exactly as its source stream did. Either stream may be absent (null data,
// size 0: every tile of it is empty); then the other supplies the header. *out gets the stream, or
// stays empty when every tile of the result is empty (like an all-empty band). Returns Ok;
// InvalidArgument when both are absent, take_fresh does not have one flag per tile or the parameters
// differ; a read_header / read_tile_index status for a stream that does not open (checked fully,
// payload row CRCs included, so a damaged payload is never copied). Untrusted input: safe.
Status splice_tiles(const uint8_t* old_data, size_t old_size, const uint8_t* fresh_data, size_t fresh_size,
                    const std::vector<uint8_t>& take_fresh, std::vector<uint8_t>* out);

// A parsed stream: header and index are validated once, then any number of regions decode from it.
// The stream bytes must outlive the Decoder. After open, the const members may be called from any
// number of threads at once (each with its own Scratch).
class Decoder {
 public:
  Decoder();
  ~Decoder();
  Decoder(Decoder&&) noexcept;
  Decoder& operator=(Decoder&&) noexcept;
  // read_header + read_tile_index, with their statuses. A failed open leaves the decoder closed:
  // decode_region then returns InvalidArgument.
  Status open(const uint8_t* data, size_t size);
  const HeaderInfo& header() const { return header_; }
  const std::vector<TileEntry>& index() const { return index_; }
  // Decodes rect into dst (dst[0] = sample (rect.x, rect.y); stride in samples). Touches only the
  // tiles the rectangle intersects; each is decoded once (empty ones are zero-filled). The CRC of a
  // tile row's payloads is verified the first time any call touches a non-empty tile of the row
  // (once per Decoder; safe from several threads), so no payload byte is used unchecked. Returns
  // InvalidArgument for an empty rect or one outside the image, ChecksumMismatch or Corrupt for a
  // damaged tile row (dst then holds unspecified values).
  Status decode_region(const Rect& rect, int32_t* dst, ptrdiff_t dst_stride, Scratch& scratch) const;
  // The same, but adds each decoded sample to dst's (int32, saturating at the int32 range) instead
  // of storing it: what a caller that adds the samples to a prediction would do, without a buffer
  // and a second pass. On an error status the tiles before the damaged one (in row-major order)
  // have been added and the rest of dst is untouched (a tile is validated whole before any of it is
  // added; a tile row's CRC before any of that row), so a one-tile call leaves dst as it was.
  Status decode_region_add(const Rect& rect, int32_t* dst, ptrdiff_t dst_stride, Scratch& scratch) const;

 private:
  Status decode_into(const Rect& rect, int32_t* dst, ptrdiff_t dst_stride, Scratch& scratch, bool add) const;
  const TileEntry& entry_of(int64_t tile) const;
  Status check_row(int64_t tile_row) const;
  const uint8_t* data_ = nullptr;
  size_t size_ = 0;
  HeaderInfo header_;
  std::vector<TileEntry> index_;
  std::vector<RowChecksum> rows_;
  struct RowState;
  std::unique_ptr<RowState> row_state_;                      // which rows' CRCs have been verified
  std::unique_ptr<const detail::PhaseTables> phase_tables_;  // phase streams: the model's tables
};

// Whole-image and one-shot region decodes (open + decode_region), with their statuses. decode
// writes header.width x header.height samples: the caller must know the size (read_header).
Status decode(const uint8_t* data, size_t size, int32_t* dst, ptrdiff_t dst_stride, Scratch& scratch);
Status decode_region(const uint8_t* data, size_t size, const Rect& rect, int32_t* dst, ptrdiff_t dst_stride,
                     Scratch& scratch);

}  // namespace codec
