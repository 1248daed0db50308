// Phase-mode tiles (format 6): near-lossless coding of an interpolating pyramid's residual by its
// four polyphase components, with a bound E (0 = lossless). docs/codec.md "Phase tiles (format 6)".
//
// A residual R = T_l - U(T^_{l-1}) of a pyramid whose coarse level is the fine level's even-even
// samples (D = point sampling) is, at even-even positions, just the coarse level's own error, within
// +-E: those samples need no bits (the "even phase skipped" flag). The other three phases are coded
// in order (odd columns of even rows, even columns of odd rows, then odd-odd), each sample predicted
// from its decoded neighbours, quantised with bins of 2E + 1 and coded by a binary adaptive range
// coder whose contexts are the magnitudes of the decoded neighbours' levels. Tile origins must sit on
// even level coordinates for the skipped phase to be the coarse one; any other tile is still coded
// correctly (its even phase is then coded, not skipped).
#pragma once

#include <cstddef>
#include <cstdint>

namespace codec::detail {

// Largest payload (after the mode byte) a phase tile of w x h samples can produce.
size_t phase_payload_bound(int w, int h);
// Samples of the `levels` scratch that encode_phase and decode_phase need for a w x h tile.
size_t phase_levels_size(int w, int h);

// Codes the w x h samples at src (row stride `stride`) with |error| <= max_error into out[0 .. capacity).
// Returns the size in bytes (may be 0 for a tile whose levels are all zero and skipped), or SIZE_MAX
// when it does not fit or a sample cannot be represented. recon (w x h, row stride w) receives the
// decoder's output; levels (phase_levels_size) is scratch.
size_t encode_phase(const int32_t* src, ptrdiff_t stride, int w, int h, uint32_t max_error, uint8_t* out,
                    size_t capacity, int32_t* recon, int32_t* levels);

// Decodes a phase payload into recon (w x h, row stride w); levels (phase_levels_size) is scratch. False when
// the payload is damaged (a sample out of range, an impossible code).
bool decode_phase(const uint8_t* data, size_t size, int w, int h, uint32_t max_error, int32_t* recon,
                  int32_t* levels);

}  // namespace codec::detail
