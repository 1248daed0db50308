// Lifting steps (all designed here; see docs/codec.md for the derivation):
//  4-point core (DCT-II-like): two lifting butterflies (sums kept as floor-averages), an even
//  butterfly giving the block mean and the (x0+x3-x1-x2)/2 term, and for the odd pair a rotation by
//  pi/8 as three lifting shears with tan(pi/16) ~ 51/256 and sin(pi/8) ~ 98/256.
//  Overlap pre-filter on (a, b | c, d) across a block edge: butterflies into outer/inner sums and
//  differences, then one shear that widens the inner difference by a quarter of the outer one
//  (t2 += t3/4): on smooth data it flattens each block near the edge, pushing energy into the block DC;
//  the decoder's post-filter undoes it and so smooths quantisation steps across the edge.
#include "lapped_transform.h"

#include <algorithm>
#include <cstdint>

namespace codec::detail {
namespace {

constexpr int64_t kTanPi16 = 51;   // tan(pi/16) * 256 (0.1992 vs 0.1989)
constexpr int64_t kSinPi8 = 98;    // sin(pi/8) * 256 (0.3828 vs 0.3827)

inline int32_t saturate(int64_t v) {
  return int32_t(std::clamp<int64_t>(v, INT32_MIN, INT32_MAX));
}

inline int64_t shear(int64_t coefficient, int64_t v) { return (coefficient * v + 128) >> 8; }

inline void fwd4(int64_t& x0, int64_t& x1, int64_t& x2, int64_t& x3) {
  const int64_t d03 = x0 - x3, s03 = x3 + (d03 >> 1);
  const int64_t d12 = x1 - x2, s12 = x2 + (d12 >> 1);
  const int64_t even_diff = s03 - s12;
  const int64_t mean = s12 + (even_diff >> 1);
  int64_t a = d03, b = d12;
  a += shear(kTanPi16, b);
  b -= shear(kSinPi8, a);
  a += shear(kTanPi16, b);
  x0 = mean;
  x1 = a;
  x2 = even_diff;
  x3 = b;
}

inline void inv4(int64_t& x0, int64_t& x1, int64_t& x2, int64_t& x3) {
  int64_t a = x1, b = x3;
  a -= shear(kTanPi16, b);
  b += shear(kSinPi8, a);
  a -= shear(kTanPi16, b);
  const int64_t d03 = a, d12 = b;
  const int64_t s12 = x0 - (x2 >> 1);
  const int64_t s03 = x2 + s12;
  const int64_t r2 = s12 - (d12 >> 1), r1 = d12 + r2;
  const int64_t r3 = s03 - (d03 >> 1), r0 = d03 + r3;
  x0 = r0;
  x1 = r1;
  x2 = r2;
  x3 = r3;
}

inline void pre4(int64_t& a, int64_t& b, int64_t& c, int64_t& d) {
  const int64_t t3 = a - d, t0 = d + (t3 >> 1);
  int64_t t2 = b - c;
  const int64_t t1 = c + (t2 >> 1);
  t2 += (t3 + 2) >> 2;
  c = t1 - (t2 >> 1);
  b = t2 + c;
  d = t0 - (t3 >> 1);
  a = t3 + d;
}

inline void post4(int64_t& a, int64_t& b, int64_t& c, int64_t& d) {
  const int64_t t3 = a - d, t0 = d + (t3 >> 1);
  int64_t t2 = b - c;
  const int64_t t1 = c + (t2 >> 1);
  t2 -= (t3 + 2) >> 2;
  c = t1 - (t2 >> 1);
  b = t2 + c;
  d = t0 - (t3 >> 1);
  a = t3 + d;
}

template <void (*Op)(int64_t&, int64_t&, int64_t&, int64_t&)>
inline void apply4(int32_t* p, ptrdiff_t step) {
  int64_t a = p[0], b = p[step], c = p[2 * step], d = p[3 * step];
  Op(a, b, c, d);
  p[0] = saturate(a);
  p[step] = saturate(b);
  p[2 * step] = saturate(c);
  p[3 * step] = saturate(d);
}

// 4x4 block whose element (row r, column c) is p[r * row_step + c * col_step].
inline void forward_block(int32_t* p, ptrdiff_t col_step, ptrdiff_t row_step) {
  for (int r = 0; r < 4; ++r) apply4<fwd4>(p + r * row_step, col_step);
  for (int c = 0; c < 4; ++c) apply4<fwd4>(p + c * col_step, row_step);
}

inline void inverse_block(int32_t* p, ptrdiff_t col_step, ptrdiff_t row_step) {
  for (int c = 0; c < 4; ++c) apply4<inv4>(p + c * col_step, row_step);
  for (int r = 0; r < 4; ++r) apply4<inv4>(p + r * row_step, col_step);
}

template <void (*Op)(int64_t&, int64_t&, int64_t&, int64_t&)>
void filter_rows(int32_t* tile, int width, int height) {
  for (int y = 0; y < height; ++y) {
    int32_t* row = tile + ptrdiff_t(y) * width;
    for (int edge = 4; edge < width; edge += 4) apply4<Op>(row + edge - 2, 1);
  }
}

template <void (*Op)(int64_t&, int64_t&, int64_t&, int64_t&)>
void filter_columns(int32_t* tile, int width, int height) {
  for (int edge = 4; edge < height; edge += 4) {
    int32_t* top = tile + ptrdiff_t(edge - 2) * width;
    for (int x = 0; x < width; ++x) apply4<Op>(top + x, width);
  }
}

}  // namespace

void forward_lapped(int32_t* tile, int width, int height) {
  filter_rows<pre4>(tile, width, height);
  filter_columns<pre4>(tile, width, height);
  for (int by = 0; by < height; by += 4)
    for (int bx = 0; bx < width; bx += 4) forward_block(tile + ptrdiff_t(by) * width + bx, 1, width);
  for (int my = 0; my < height; my += 16)
    for (int mx = 0; mx < width; mx += 16)
      forward_block(tile + ptrdiff_t(my) * width + mx, 4, ptrdiff_t(4) * width);
}

void inverse_lapped(int32_t* tile, int width, int height) {
  for (int my = 0; my < height; my += 16)
    for (int mx = 0; mx < width; mx += 16)
      inverse_block(tile + ptrdiff_t(my) * width + mx, 4, ptrdiff_t(4) * width);
  for (int by = 0; by < height; by += 4)
    for (int bx = 0; bx < width; bx += 4) inverse_block(tile + ptrdiff_t(by) * width + bx, 1, width);
  filter_columns<post4>(tile, width, height);
  filter_rows<post4>(tile, width, height);
}

}  // namespace codec::detail
