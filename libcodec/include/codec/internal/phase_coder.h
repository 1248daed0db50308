// Phase-mode tiles (format 7): coding of an interpolating pyramid's residual by its four polyphase
// components, with a bound E (0 = lossless) or a real-valued bin (rms streams). docs/codec.md "Phase
// tiles (format 7)".
//
// A residual R = T_l - U(T^_{l-1}) of a pyramid whose coarse level is the fine level's even-even
// samples (D = point sampling) is, at even-even positions, just the coarse level's own error, within
// the quantiser's largest error: those samples need no bits (the "even phase skipped" flag). The other
// three phases are coded in order (odd columns of even rows, even columns of odd rows, then odd-odd),
// each sample predicted from its decoded neighbours and quantised with bins of 2E + 1 or of the step. A
// level's context is its phase and the magnitude class of the decoded neighbours' levels; each context codes
// tokens with one static distribution of the stream (token_tables.h), chosen by the encoder from the whole
// stream's statistics and named in its header (PhaseModel), and the tokens and raw bits go through one rANS
// state (rans.h). Tile origins must sit on even level coordinates for the skipped phase to be the
// coarse one; any other tile is still coded correctly (its even phase is then coded, not skipped).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "codec/internal/rans.h"
#include "codec/internal/token_tables.h"

namespace codec::detail {

inline constexpr int kPhaseClasses = 12;                  // neighbour-activity classes per phase
inline constexpr int kPhaseContexts = 4 * kPhaseClasses;  // context = phase * kPhaseClasses + class
inline constexpr int kPhaseModelBytes = 6 + kPhaseContexts * 10 / 8;  // largest serialised model

// Which member of the token family each context uses (used[c] false: no tile of the stream reached c).
struct PhaseModel {
  bool used[kPhaseContexts] = {};
  uint16_t member[kPhaseContexts] = {};
  int lanes = 2;  // rANS states per tile: 2 in format 8, 1 in format 7 (the stream's version, not serialised)
  bool operator==(const PhaseModel&) const = default;
};

// Token counts per context, gathered by phase_statistics over a stream's tiles.
struct PhaseCounts {
  uint32_t counts[kPhaseContexts][kTokens] = {};
};

// The model that codes `counts` in the fewest bits.
PhaseModel fit_phase_model(const PhaseCounts& counts);
// Serialised model (the 48-bit used mask, then 10 bits per used context's member, MSB first, padded to
// a byte): writes at most kPhaseModelBytes to out and returns the size.
size_t write_phase_model(const PhaseModel& model, uint8_t* out);
// Parses a model at [p, end): advances p; false when it is truncated or names a member that does not exist.
bool read_phase_model(const uint8_t*& p, const uint8_t* end, PhaseModel* model);

// A model's tables, resolved for coding (unused contexts get member 0: a payload that reaches them
// is malformed, and decodes to something the tile's checks reject or to wrong but bounded samples).
struct PhaseTables {
  const TokenTable* table[kPhaseContexts] = {};
  // The decoder's two lookups per symbol, one load from the context away instead of two.
  const uint8_t* slots[kPhaseContexts] = {};
  const uint32_t* freq_cum[kPhaseContexts] = {};
  int lanes = 2;
  explicit PhaseTables(const PhaseModel& model);
};

// Working memory of the phase coder (grown as needed).
struct PhaseWork {
  std::vector<int32_t> levels;  // context scratch, (w + 4) x (h + 4)
  RansEncoder rans;
  std::vector<uint16_t> words;
  // Whether the last tile coded its even phase: some even sample was beyond the bound, so the tile
  // is not the residual of a point-sampled pyramid (or is its coarsest level).
  bool even_phase_coded = false;
};

// Largest payload (mode byte included) a phase tile of w x h samples can produce.
size_t phase_payload_bound(int w, int h);

// What the statistics pass found in each tile of one image, so that the encoder replays it instead
// of traversing the tile a second time (prediction, context and quantisation were half the phase
// encoder's time). The levels do not depend on the model, only their codes do, so the replay codes
// exactly what a second traversal would.
struct PhaseRecord {
  struct Tile {
    size_t first_symbol = 0, first_raw = 0;
    uint32_t symbols = 0;
    bool skip = false;      // the even phase was not coded
    bool recorded = false;  // false: the pass stopped early (a damaged value); encode it afresh
  };
  std::vector<uint16_t> symbols;  // context << 8 | symbol, in coding order
  std::vector<uint32_t> raws;     // the magnitude of each symbol with raw bits, in order
  std::vector<Tile> tiles;        // per tile of the image, raster order
  void clear(size_t tile_count) {
    symbols.clear();
    raws.clear();
    tiles.assign(tile_count, Tile{});
  }
};

// Bins: bin_q8 / 256 samples wide (>= 256). 256 (2E + 1) bounds every error by E (max-error streams;
// E = 0: lossless); any other width is a real-valued step (rms streams): errors within about half a bin.
// The even phase is skipped when each of its samples lies within the quantiser's largest error:
// +-floor(bin / 2) for a whole-number bin, +-floor(bin / 2 + 1/2) otherwise.

// Adds the token counts of coding the w x h samples at src (row stride `stride`) with bins of bin_q8
// to *counts; recon (w x h) is scratch. False when a sample cannot be represented.
// With `record`, also appends the tile's levels to it as tile `tile` (recorded when the pass ends
// normally).
bool phase_statistics(const int32_t* src, ptrdiff_t stride, int w, int h, uint32_t bin_q8, int32_t* recon,
                      PhaseWork& work, PhaseCounts* counts, PhaseRecord* record = nullptr, size_t tile = 0);
// Codes a recorded tile with `tables`: the payload encode_phase would produce for it (the caller
// supplies the reconstruction the statistics pass produced). Returns SIZE_MAX when it does not fit.
size_t encode_phase_recorded(const PhaseRecord& record, size_t tile, const PhaseTables& tables, uint8_t* out,
                             size_t capacity, PhaseWork& work);

// Codes the w x h samples at src with bins of bin_q8 into out[0 .. capacity), mode byte first.
// Returns the size in bytes, or SIZE_MAX when it does not fit or a sample cannot be represented.
// recon (w x h, row stride w) receives the decoder's output.
size_t encode_phase(const int32_t* src, ptrdiff_t stride, int w, int h, uint32_t bin_q8,
                    const PhaseTables& tables, uint8_t* out, size_t capacity, int32_t* recon,
                    PhaseWork& work);

// Whether a tile's mode byte is a phase tile's.
bool is_phase_mode(uint8_t mode);

// Decodes a phase payload (mode byte first) into recon (w x h, row stride w). False when the payload
// is damaged (a sample out of range, an impossible code, a final state other than 1).
bool decode_phase(const uint8_t* data, size_t size, int w, int h, uint32_t bin_q8, const PhaseTables& tables,
                  int32_t* recon, PhaseWork& work);

}  // namespace codec::detail
