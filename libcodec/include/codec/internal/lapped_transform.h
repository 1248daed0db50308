// Reversible integer lapped transform on one tile (PTC / JPEG XR family, own lifting design):
//  1. overlap pre-filter: a 4-point lifting filter straddling every internal 4x4 block edge, rows then
//     columns; it stops at the tile edge (hard tile boundaries);
//  2. stage 1: separable 4-point DCT-like lifting transform on every 4x4 block;
//  3. stage 2: the same 4x4 transform on the 16 block DCs of every 16x16 macroblock.
// Coefficients stay in place: HP at (4bx+u, 4by+v) with (u,v) != (0,0), LP at (16mx+4u, 16my+4v) with
// (u,v) != (0,0), macroblock DC at (16mx, 16my). Every step is integer lifting, so inverse(forward(x))
// == x exactly. Arithmetic is 32-bit with wrapping adds (shear products cannot overflow): for
// inputs within +-2^22 (samples +-2^20 with 2 fraction bits) every intermediate value stays below
// 2^28, so nothing wraps; garbage coefficients from a corrupt stream give garbage, never UB.
#pragma once

#include <cstddef>
#include <cstdint>

namespace codec::detail {

// tile: width x height samples, row stride = width; width and height are multiples of 16.
void forward_lapped(int32_t* tile, int width, int height, bool lossy);
// Picks the widest implementation the CPU runs; all give identical results.
void inverse_lapped(int32_t* tile, int width, int height, bool lossy);

// The implementations behind inverse_lapped, for tests: the scalar reference, 4-lane vectors
// (SSE2 on x86-64), 8-lane AVX2 and 16-lane AVX-512 (call only where the CPU has them). The last
// three return false when the compiler does not provide them.
void inverse_lapped_scalar(int32_t* tile, int width, int height, bool lossy);
bool inverse_lapped_vector(int32_t* tile, int width, int height, bool lossy);
bool inverse_lapped_avx2(int32_t* tile, int width, int height, bool lossy);
bool inverse_lapped_avx512(int32_t* tile, int width, int height, bool lossy);
// Whether the CPU runs inverse_lapped_avx2 / inverse_lapped_avx512 (the ISA subsets they are built for).
bool cpu_has_avx2();
bool cpu_has_avx512();

}  // namespace codec::detail
