// Lifting steps (all designed here; see docs/codec.md for the derivation):
//  4-point core (DCT-II-like): two lifting butterflies (sums kept as floor-averages), an even
//  butterfly giving the block mean and the (x0+x3-x1-x2)/2 term, and for the odd pair a rotation by
//  pi/8 as three lifting shears with tan(pi/16) ~ 51/256 and sin(pi/8) ~ 98/256.
//  Overlap pre-filter on (a, b | c, d) across a block edge: butterflies into outer/inner sums and
//  differences, then one shear that widens the inner difference by a quarter of the outer one
//  (t2 += t3/4): on smooth data it flattens each block near the edge, pushing energy into the block DC;
//  the decoder's post-filter undoes it and so smooths quantisation steps across the edge.
#include "lapped_transform.h"

#include <cstdint>

namespace codec::detail {
namespace {

constexpr int32_t kTanPi16 = 51;   // tan(pi/16) * 256 (0.1992 vs 0.1989)
constexpr int32_t kSinPi8 = 98;    // sin(pi/8) * 256 (0.3828 vs 0.3827)

// Additions wrap instead of overflowing: valid streams never come near 2^31 (see the header), and
// wrapping keeps garbage coefficients from a corrupt stream free of undefined behaviour.
inline int32_t add(int32_t a, int32_t b) { return int32_t(uint32_t(a) + uint32_t(b)); }
inline int32_t sub(int32_t a, int32_t b) { return int32_t(uint32_t(a) - uint32_t(b)); }
// (coefficient * v + 128) >> 8 exactly, in 32-bit arithmetic so that it vectorises: with
// v = 256 h + l, that is coefficient * h + ((coefficient * l + 128) >> 8), and |coefficient * h| < 2^30
// for every int32 v because coefficient < 128.
inline int32_t shear(int32_t coefficient, int32_t v) {
  const int32_t high = v >> 8, low = v & 255;
  return coefficient * high + ((coefficient * low + 128) >> 8);
}

#define CODEC_INLINE inline __attribute__((always_inline))

CODEC_INLINE void fwd4(int32_t& x0, int32_t& x1, int32_t& x2, int32_t& x3) {
  const int32_t d03 = sub(x0, x3), s03 = add(x3, d03 >> 1);
  const int32_t d12 = sub(x1, x2), s12 = add(x2, d12 >> 1);
  const int32_t even_diff = sub(s03, s12);
  const int32_t mean = add(s12, even_diff >> 1);
  int32_t a = d03, b = d12;
  a = add(a, shear(kTanPi16, b));
  b = sub(b, shear(kSinPi8, a));
  a = add(a, shear(kTanPi16, b));
  x0 = mean;
  x1 = a;
  x2 = even_diff;
  x3 = b;
}

CODEC_INLINE void inv4(int32_t& x0, int32_t& x1, int32_t& x2, int32_t& x3) {
  int32_t a = x1, b = x3;
  a = sub(a, shear(kTanPi16, b));
  b = add(b, shear(kSinPi8, a));
  a = sub(a, shear(kTanPi16, b));
  const int32_t d03 = a, d12 = b;
  const int32_t s12 = sub(x0, x2 >> 1);
  const int32_t s03 = add(x2, s12);
  const int32_t r2 = sub(s12, d12 >> 1), r1 = add(d12, r2);
  const int32_t r3 = sub(s03, d03 >> 1), r0 = add(d03, r3);
  x0 = r0;
  x1 = r1;
  x2 = r2;
  x3 = r3;
}

// Pre- and post-filter differ only in the sign of the middle shear.
template <int Sign>
CODEC_INLINE void overlap4(int32_t& a, int32_t& b, int32_t& c, int32_t& d) {
  const int32_t t3 = sub(a, d), t0 = add(d, t3 >> 1);
  int32_t t2 = sub(b, c);
  const int32_t t1 = add(c, t2 >> 1);
  const int32_t widen = add(t3, 2) >> 2;
  t2 = Sign > 0 ? add(t2, widen) : sub(t2, widen);
  c = sub(t1, t2 >> 1);
  b = add(t2, c);
  d = sub(t0, t3 >> 1);
  a = add(t3, d);
}
CODEC_INLINE void pre4(int32_t& a, int32_t& b, int32_t& c, int32_t& d) { overlap4<1>(a, b, c, d); }
CODEC_INLINE void post4(int32_t& a, int32_t& b, int32_t& c, int32_t& d) { overlap4<-1>(a, b, c, d); }

inline int32_t mul(int32_t a, int32_t k) { return int32_t(uint32_t(a) * uint32_t(k)); }
// (k * v + 32) >> 6 for the lifting steps of the lossy filter; valid streams keep |v| < 2^25.
inline int32_t lift64(int32_t k, int32_t v) { return add(mul(v, k), 32) >> 6; }
// x -> x + round(x * K / 64): strictly increasing for K > 0, so exactly invertible.
template <int K>
CODEC_INLINE int32_t expand(int32_t x) { return add(x, lift64(K, x)); }
// The inverse of expand: the unique x with expand(x) == y is ceil((64 y - 32) / (64 + K)).
template <int K>
CODEC_INLINE int32_t shrink(int32_t y) {
  constexpr int64_t d = 64 + K;
  const int64_t n = int64_t(y) * 64 - 32 + d - 1;  // ceil(a / d) = floor((a + d - 1) / d)
  const int64_t q = n / d;
  return int32_t(q - int64_t(q * d > n));  // C++ division truncates: fix up negative n
}

// Lossy overlap filter (biorthogonal, LBT structure butterfly / diag(I, V) / butterfly): both
// differences across the edge are expanded (inner by 90/64, outer by 85/64) and coupled by two
// lifting steps (-15/64, 33/64). Expansion is not volume preserving, so this filter is exactly
// invertible but wastes code space at step 1; lossless tiles keep overlap4. Constants tuned by
// measurement on SRTM tiles at equal rms (docs/codec.md).
constexpr int kExpandInner = 26, kExpandOuter = 21, kLiftOuter = -15, kLiftInner = 33;
CODEC_INLINE void lossy_pre4(int32_t& a, int32_t& b, int32_t& c, int32_t& d) {
  int32_t t3 = sub(a, d);
  const int32_t t0 = add(d, t3 >> 1);
  int32_t t2 = sub(b, c);
  const int32_t t1 = add(c, t2 >> 1);
  t2 = expand<kExpandInner>(t2);
  t3 = expand<kExpandOuter>(t3);
  t3 = add(t3, lift64(kLiftOuter, t2));
  t2 = add(t2, lift64(kLiftInner, t3));
  c = sub(t1, t2 >> 1);
  b = add(t2, c);
  d = sub(t0, t3 >> 1);
  a = add(t3, d);
}
CODEC_INLINE void lossy_post4(int32_t& a, int32_t& b, int32_t& c, int32_t& d) {
  int32_t t3 = sub(a, d);
  const int32_t t0 = add(d, t3 >> 1);
  int32_t t2 = sub(b, c);
  const int32_t t1 = add(c, t2 >> 1);
  t2 = sub(t2, lift64(kLiftInner, t3));
  t3 = sub(t3, lift64(kLiftOuter, t2));
  t2 = shrink<kExpandInner>(t2);
  t3 = shrink<kExpandOuter>(t3);
  c = sub(t1, t2 >> 1);
  b = add(t2, c);
  d = sub(t0, t3 >> 1);
  a = add(t3, d);
}

// Op on four consecutive samples of a row.
template <void (*Op)(int32_t&, int32_t&, int32_t&, int32_t&)>
CODEC_INLINE void along_row(int32_t* p) {
  int32_t a = p[0], b = p[1], c = p[2], d = p[3];
  Op(a, b, c, d);
  p[0] = a;
  p[1] = b;
  p[2] = c;
  p[3] = d;
}

// Op down four rows (r0..r3 apart by `stride`) for `count` columns spaced `step` apart; contiguous
// columns (step 1) vectorise.
template <void (*Op)(int32_t&, int32_t&, int32_t&, int32_t&)>
CODEC_INLINE void down_rows(int32_t* top, ptrdiff_t stride, int count, int step) {
  int32_t* r0 = top;
  int32_t* r1 = top + stride;
  int32_t* r2 = top + 2 * stride;
  int32_t* r3 = top + 3 * stride;
  for (int i = 0; i < count; ++i) {
    const ptrdiff_t x = ptrdiff_t(i) * step;
    int32_t a = r0[x], b = r1[x], c = r2[x], d = r3[x];
    Op(a, b, c, d);
    r0[x] = a;
    r1[x] = b;
    r2[x] = c;
    r3[x] = d;
  }
}

template <void (*Pre)(int32_t&, int32_t&, int32_t&, int32_t&), bool Two>
void forward_impl(int32_t* tile, int width, int height) {
  for (int y = 0; y < height; ++y) {
    int32_t* row = tile + ptrdiff_t(y) * width;
    for (int edge = 4; edge < width; edge += 4) along_row<Pre>(row + edge - 2);
  }
  for (int edge = 4; edge < height; edge += 4) down_rows<Pre>(tile + ptrdiff_t(edge - 2) * width, width, width, 1);
  // Stage 1: rows of every block, then columns of every block.
  for (int y = 0; y < height; ++y) {
    int32_t* row = tile + ptrdiff_t(y) * width;
    for (int x = 0; x < width; x += 4) along_row<fwd4>(row + x);
  }
  for (int y = 0; y < height; y += 4) down_rows<fwd4>(tile + ptrdiff_t(y) * width, width, width, 1);
  if (Two) {
    // Stage-2 overlap across macroblock edges, on the grid of block DCs.
    for (int y = 0; y < height; y += 4) {
      int32_t* row = tile + ptrdiff_t(y) * width;
      for (int edge = 16; edge < width; edge += 16) {
        int32_t a = row[edge - 8], b = row[edge - 4], c = row[edge], d = row[edge + 4];
        Pre(a, b, c, d);
        row[edge - 8] = a;
        row[edge - 4] = b;
        row[edge] = c;
        row[edge + 4] = d;
      }
    }
    for (int edge = 16; edge < height; edge += 16)
      down_rows<Pre>(tile + ptrdiff_t(edge - 8) * width, ptrdiff_t(4) * width, width / 4, 4);
  }
  // Stage 2 on the block DCs (every 4th sample of every 4th row).
  for (int y = 0; y < height; y += 4) {
    int32_t* row = tile + ptrdiff_t(y) * width;
    for (int x = 0; x < width; x += 16) {
      int32_t a = row[x], b = row[x + 4], c = row[x + 8], d = row[x + 12];
      fwd4(a, b, c, d);
      row[x] = a;
      row[x + 4] = b;
      row[x + 8] = c;
      row[x + 12] = d;
    }
  }
  for (int y = 0; y < height; y += 16) down_rows<fwd4>(tile + ptrdiff_t(y) * width, ptrdiff_t(4) * width, width / 4, 4);
}

template <void (*Post)(int32_t&, int32_t&, int32_t&, int32_t&), bool Two>
void inverse_impl(int32_t* tile, int width, int height) {
  for (int y = 0; y < height; y += 16) down_rows<inv4>(tile + ptrdiff_t(y) * width, ptrdiff_t(4) * width, width / 4, 4);
  for (int y = 0; y < height; y += 4) {
    int32_t* row = tile + ptrdiff_t(y) * width;
    for (int x = 0; x < width; x += 16) {
      int32_t a = row[x], b = row[x + 4], c = row[x + 8], d = row[x + 12];
      inv4(a, b, c, d);
      row[x] = a;
      row[x + 4] = b;
      row[x + 8] = c;
      row[x + 12] = d;
    }
  }
  if (Two) {
    for (int edge = 16; edge < height; edge += 16)
      down_rows<Post>(tile + ptrdiff_t(edge - 8) * width, ptrdiff_t(4) * width, width / 4, 4);
    for (int y = 0; y < height; y += 4) {
      int32_t* row = tile + ptrdiff_t(y) * width;
      for (int edge = 16; edge < width; edge += 16) {
        int32_t a = row[edge - 8], b = row[edge - 4], c = row[edge], d = row[edge + 4];
        Post(a, b, c, d);
        row[edge - 8] = a;
        row[edge - 4] = b;
        row[edge] = c;
        row[edge + 4] = d;
      }
    }
  }
  for (int y = 0; y < height; y += 4) down_rows<inv4>(tile + ptrdiff_t(y) * width, width, width, 1);
  for (int y = 0; y < height; ++y) {
    int32_t* row = tile + ptrdiff_t(y) * width;
    for (int x = 0; x < width; x += 4) along_row<inv4>(row + x);
  }
  for (int edge = 4; edge < height; edge += 4) down_rows<Post>(tile + ptrdiff_t(edge - 2) * width, width, width, 1);
  for (int y = 0; y < height; ++y) {
    int32_t* row = tile + ptrdiff_t(y) * width;
    for (int edge = 4; edge < width; edge += 4) along_row<Post>(row + edge - 2);
  }
}

}  // namespace

void forward_lapped(int32_t* tile, int width, int height, bool lossy) {
  if (lossy) forward_impl<lossy_pre4, true>(tile, width, height);
  else forward_impl<pre4, false>(tile, width, height);
}
void inverse_lapped(int32_t* tile, int width, int height, bool lossy) {
  if (lossy) inverse_impl<lossy_post4, true>(tile, width, height);
  else inverse_impl<post4, false>(tile, width, height);
}

}  // namespace codec::detail
