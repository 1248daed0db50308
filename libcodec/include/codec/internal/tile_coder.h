// Coding of one tile: padding to whole macroblocks, transform, quantisation, band ordering, RLGR, and
// the max-error layer. A tile payload is one mode byte followed by one bitstream (docs/codec.md).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "codec/internal/phase_coder.h"
#include "codec/internal/quantizer.h"

namespace codec::detail {

enum class TileMode : uint8_t {
  Transform = 0,         // lapped transform at the stream's band steps (+ corrections if bounded)
  SpatialQuantized = 1,  // max-error mode only: samples quantised with step 2E+1, coded losslessly
  Phase = 2,             // format 7 streams with the phase flag: polyphase coding (phase_coder.h);
                         // modes 2 .. 6 are all phase tiles (the mode carries the rANS state's size)
};

struct TileParams {
  BandSteps steps;          // lapped transform-mode tiles
  BandSteps lifting_steps;  // residual-transform tiles (q8[0..3])
  // Format 5: every transform-mode tile starts with one bit, 0 = residual transform
  // (lifting_transform.h), 1 = lapped; the encoder keeps the one with the lower rate-distortion cost.
  bool lifting = false;
  double lambda = 0;      // format 5, lossy: the choice's bits per squared sample unit (encoder only)
  int fraction_bits = 0;  // extra sample precision of transform-mode tiles (0 = lossless)
  bool bound_max_error = false;
  uint32_t max_error = 0;
  // Format 7: tiles may use TileMode::Phase; in max-error streams beside the other modes, in other
  // streams every tile is a phase tile.
  bool phase = false;
  const PhaseTables* phase_tables = nullptr;  // the stream's model (set whenever phase is)
  uint32_t phase_bin_q8 = 256;                // phase tiles' bin: 256 (2E + 1), or the step * 256
};

// Where the LP and HP values of a padded_width x padded_height tile land, in coding order: tile
// offset in the low kSlotOffsetBits, band above. Lets the decoder write each non-zero value straight
// to its place instead of scattering whole bands.
inline constexpr int kSlotOffsetBits = 24;  // padded tiles hold at most 4096 x 4096 samples
struct BandLayout {
  int padded_width = 0, padded_height = 0;
  std::vector<uint32_t> slots;
};

// Working buffers for one tile, owned by the caller's Scratch and grown as needed.
struct TileWork {
  // A stream has at most four padded tile shapes (interior, right edge, bottom edge, corner).
  std::array<BandLayout, 4> layouts;
  size_t next_layout = 0;
  std::vector<int32_t> coefficients;     // padded tile
  std::vector<int32_t> sequence;         // one band's values in coding order
  std::vector<int32_t> reconstruction;   // width x height
  std::vector<uint8_t> alternative;      // second candidate payload in max-error mode
  std::vector<int32_t> lifting_scratch;  // the residual transform's copies (lifting_scratch_size)
  std::vector<int32_t> candidate;        // the first transform's reconstruction while the second is tried
  std::vector<uint8_t> second;           // the second transform's payload
  std::vector<uint8_t> phase_payload;    // a phase tile that codes its even phase, while the others are tried
  std::vector<int32_t> phase_recon;      // its reconstruction (width x height); the decoder's phase output
  PhaseWork phase_work;                  // the phase coder's scratch
  // reconstruction_samples: the encoder's width x height; the decoder writes into the caller's
  // window and needs none.
  void reserve(int padded_width, int padded_height, size_t reconstruction_samples, size_t payload_bound);
};

inline int padded_side(int side) { return (side + 15) & ~15; }
// Largest payload a tile of width x height can produce (any data, any mode).
size_t tile_payload_bound(int width, int height);

// A phase tile the statistics pass recorded: replayed instead of coded afresh (phase_coder.h
// PhaseRecord), with the reconstruction that pass wrote at recon (row stride recon_stride).
struct PhaseReplay {
  const PhaseRecord* record = nullptr;
  size_t tile = 0;
  const int32_t* recon = nullptr;
  ptrdiff_t recon_stride = 0;
};
// Encodes the width x height samples at src (row stride src_stride) into out[0 .. capacity). Returns
// the payload size, or 0 when it does not fit. With want_reconstruction, work.reconstruction then
// holds the decoder's output (row stride = width). With replay, a phase tile is coded from its record.
size_t encode_tile(const int32_t* src, ptrdiff_t src_stride, int width, int height, const TileParams& params,
                   TileWork& work, uint8_t* out, size_t capacity, bool want_reconstruction,
                   const PhaseReplay* replay = nullptr);

enum class TileResult { Ok, Corrupt };
// The part of a decoded tile the caller wants: samples [x0, x1) x [y0, y1) of the tile (inside
// width x height), written to dst (the sample at (x0, y0)) with row stride `stride`, or added to
// dst's samples (saturating) when `add`.
struct TileWindow {
  int x0, y0, x1, y1;
  int32_t* dst;
  ptrdiff_t stride;
  bool add = false;
};
// Decodes a width x height payload and writes `window` of it. On Corrupt the window is untouched
// (the whole payload is decoded and checked before the first sample is written).
TileResult decode_tile(const uint8_t* payload, size_t size, int width, int height, const TileParams& params,
                       TileWork& work, const TileWindow& window);

}  // namespace codec::detail
