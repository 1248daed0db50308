// One level of the four-point lifting wavelet on a tile, for pyramid residuals (format 5, the
// "residual" transform). The predict step is the pyramid's four-point U (-1, 9, 9, -1) / 16 and the
// update the same filter on the details, halved: (-1, 9, 9, -1) / 32 (the (4,4) interpolating
// wavelet). A closed-loop residual R_l = T_l - U(T^_{l-1}) has a low band close to the coarse level's
// quantisation error (small) and its information in the three detail bands, which this transform
// separates; the lapped transform's 4x4 / 16x16 bases do not (docs/codec.md "Residual transform").
// Integer lifting with rounding: exactly reversible, in place, rows then columns; the tile's edges are
// extended inside the tile (constant for the even samples, mirrored for the details), so tiles stay
// independent. Arithmetic wraps in 32 bits: garbage coefficients give garbage samples, never UB.
#pragma once

#include <cstddef>
#include <cstdint>

namespace codec::detail {

// Band sizes of one level on a w x h tile: evens (low) are the first ceil(n/2) of a line, odds behind.
struct LiftingBands {
  int even_w, even_h, odd_w, odd_h;
};
inline LiftingBands lifting_bands(int w, int h) { return {(w + 1) / 2, (h + 1) / 2, w / 2, h / 2}; }

// Bands in coding order: 0 = LL (even rows, even columns), 1 = HL (even rows, odd columns),
// 2 = LH (odd rows, even columns), 3 = HH. Mallat layout: LL at the top-left of the tile.
inline constexpr int kLiftingBandCount = 4;

// Values of scratch forward_lifting and inverse_lifting need for a w x h tile.
// (a copy of the tile for the column pass and the transposed tile for the row pass)
inline size_t lifting_scratch_size(int w, int h) { return 2 * size_t(w) * size_t(h); }
// In place on w x h samples with row stride w.
void forward_lifting(int32_t* tile, int w, int h, int32_t* scratch);
void inverse_lifting(int32_t* tile, int w, int h, int32_t* scratch);

// Synthesis norm of each band's basis (measured once on the integer inverse, as for the lapped bands).
const double* lifting_synthesis_norms();

}  // namespace codec::detail
