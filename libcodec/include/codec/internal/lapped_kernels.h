// The lifting steps of the lapped transform (lapped_transform.h), written once for a scalar lane
// (int32_t, the reference) and for GCC/Clang vector types, plus the vectorised inverse.
//
// Everything here has internal linkage on purpose: lapped_transform_avx2.cpp includes this header
// under an AVX2 target pragma, and its copies must never replace the baseline copies at link time.
// For the same reason no std:: function template may be used in here.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>

#if (defined(__GNUC__) && __GNUC__ >= 12) || defined(__clang__)
#define CODEC_VECTOR_TRANSFORM 1  // vector extensions with __builtin_shufflevector
#endif

#define CODEC_INLINE inline __attribute__((always_inline))

namespace codec::detail {
namespace {

// Lifting steps (all designed here; see docs/codec.md for the derivation):
//  4-point core (DCT-II-like): two lifting butterflies (sums kept as floor-averages), an even
//  butterfly giving the block mean and the (x0+x3-x1-x2)/2 term, and for the odd pair a rotation by
//  pi/8 as three lifting shears with tan(pi/16) ~ 51/256 and sin(pi/8) ~ 98/256.
//  Overlap pre-filter on (a, b | c, d) across a block edge: butterflies into outer/inner sums and
//  differences, then one shear that widens the inner difference by a quarter of the outer one
//  (t2 += t3/4): on smooth data it flattens each block near the edge, pushing energy into the block DC;
//  the decoder's post-filter undoes it and so smooths quantisation steps across the edge.
constexpr int32_t kTanPi16 = 51;  // tan(pi/16) * 256 (0.1992 vs 0.1989)
constexpr int32_t kSinPi8 = 98;   // sin(pi/8) * 256 (0.3828 vs 0.3827)

// Lane types: T is int32_t or a vector of int32_t; Unsigned<T> its unsigned twin for wrapping.
#ifdef CODEC_VECTOR_TRANSFORM
typedef int32_t V4 __attribute__((vector_size(16)));
typedef uint32_t U4 __attribute__((vector_size(16)));
typedef int32_t V8 __attribute__((vector_size(32)));
typedef uint32_t U8 __attribute__((vector_size(32)));
typedef double D4 __attribute__((vector_size(32)));
typedef double D8 __attribute__((vector_size(64)));
typedef int32_t V16 __attribute__((vector_size(64)));
typedef uint32_t U16 __attribute__((vector_size(64)));
typedef double D16 __attribute__((vector_size(128)));
#endif
// clang-format off: one line per lane type reads as the table it is.
template <class T> struct UnsignedOf { using type = uint32_t; };
template <class T> struct DoublesOf {};
#ifdef CODEC_VECTOR_TRANSFORM
template <> struct UnsignedOf<V4> { using type = U4; };
template <> struct UnsignedOf<V8> { using type = U8; };
template <> struct DoublesOf<V4> { using type = D4; };
template <> struct DoublesOf<V8> { using type = D8; };
template <> struct UnsignedOf<V16> { using type = U16; };
template <> struct DoublesOf<V16> { using type = D16; };
#endif
template <class T> using Unsigned = typename UnsignedOf<T>::type;
// clang-format on

// Additions wrap instead of overflowing: valid streams never come near 2^31 (see the header), and
// wrapping keeps garbage coefficients from a corrupt stream free of undefined behaviour.
// v in every lane.
template <class T> CODEC_INLINE T splat(int32_t v) { return T{} + v; }
template <class T> CODEC_INLINE T add(T a, T b) { return (T)((Unsigned<T>)a + (Unsigned<T>)b); }
template <class T> CODEC_INLINE T sub(T a, T b) { return (T)((Unsigned<T>)a - (Unsigned<T>)b); }
template <class T> CODEC_INLINE T mul(T a, int32_t k) { return (T)((Unsigned<T>)a * uint32_t(k)); }
// (coefficient * v + 128) >> 8 exactly, in 32-bit arithmetic: with v = 256 h + l, that is
// coefficient * h + ((coefficient * l + 128) >> 8), and |coefficient * h| < 2^30 for every int32 v
// because coefficient < 128.
template <class T> CODEC_INLINE T shear(int32_t coefficient, T v) {
  const T high = v >> 8, low = v & 255;
  return high * coefficient + ((low * coefficient + 128) >> 8);
}

template <class T> CODEC_INLINE void fwd4(T& x0, T& x1, T& x2, T& x3) {
  const T d03 = sub(x0, x3), s03 = add(x3, d03 >> 1);
  const T d12 = sub(x1, x2), s12 = add(x2, d12 >> 1);
  const T even_diff = sub(s03, s12);
  const T mean = add(s12, even_diff >> 1);
  T a = d03, b = d12;
  a = add(a, shear(kTanPi16, b));
  b = sub(b, shear(kSinPi8, a));
  a = add(a, shear(kTanPi16, b));
  x0 = mean;
  x1 = a;
  x2 = even_diff;
  x3 = b;
}

template <class T> CODEC_INLINE void inv4(T& x0, T& x1, T& x2, T& x3) {
  T a = x1, b = x3;
  a = sub(a, shear(kTanPi16, b));
  b = add(b, shear(kSinPi8, a));
  a = sub(a, shear(kTanPi16, b));
  const T d03 = a, d12 = b;
  const T s12 = sub(x0, x2 >> 1);
  const T s03 = add(x2, s12);
  const T r2 = sub(s12, d12 >> 1), r1 = add(d12, r2);
  const T r3 = sub(s03, d03 >> 1), r0 = add(d03, r3);
  x0 = r0;
  x1 = r1;
  x2 = r2;
  x3 = r3;
}

// Pre- and post-filter differ only in the sign of the middle shear.
template <int Sign, class T> CODEC_INLINE void overlap4(T& a, T& b, T& c, T& d) {
  const T t3 = sub(a, d), t0 = add(d, t3 >> 1);
  T t2 = sub(b, c);
  const T t1 = add(c, t2 >> 1);
  const T widen = add(t3, splat<T>(2)) >> 2;
  t2 = Sign > 0 ? add(t2, widen) : sub(t2, widen);
  c = sub(t1, t2 >> 1);
  b = add(t2, c);
  d = sub(t0, t3 >> 1);
  a = add(t3, d);
}

// (k * v + 32) >> 6 for the lifting steps of the lossy filter; valid streams keep |v| < 2^25.
template <class T> CODEC_INLINE T lift64(int32_t k, T v) { return add(mul(v, k), splat<T>(32)) >> 6; }
// x -> x + round(x * K / 64): strictly increasing for K > 0, so exactly invertible.
template <int K, class T> CODEC_INLINE T expand(T x) { return add(x, lift64(K, x)); }
// The inverse of expand: the unique x with expand(x) == y is ceil((64 y - 32) / (64 + K)), i.e.
// floor(n / d) with d = 64 + K and n = 64 y - 32 + d - 1.
template <int K, class T> CODEC_INLINE T shrink(T y) {
  static_assert(K >= 1 && K <= 32, "the vector form needs d - 33 in 1..63");
  constexpr int64_t d = 64 + K;
  if constexpr (std::is_same_v<T, int32_t>) {
    const int64_t n = int64_t(y) * 64 - 32 + d - 1;
    const int64_t q = n / d;
    return int32_t(q - int64_t(q * d > n));  // C++ division truncates: fix up negative n
  } else {
    // Lanes have no integer division. In doubles, x = n + 1/2 is exact (|n| < 2^38) and x / d lies at
    // least 1/(2d) > 2^-8 from every integer, while x * fl(1/d) is within |x / d| 2^-52 < 2^-20 of
    // x / d: so truncating it gives trunc(x / d), and floor(n / d) is one less where n < 0, that is
    // where y < 0 (d - 33 lies in 1..63). Exact for every int32 y (checked exhaustively against the
    // scalar form).
    using D = typename DoublesOf<T>::type;
    const D x = __builtin_convertvector(y, D) * 64.0 + (double(d) - 33.0 + 0.5);
    const T truncated = __builtin_convertvector(x * (1.0 / double(d)), T);  // |x / d| < 2^31
    return truncated + (y >> 31);
  }
}

// Lossy overlap filter (biorthogonal, LBT structure butterfly / diag(I, V) / butterfly): both
// differences across the edge are expanded (inner by 90/64, outer by 85/64) and coupled by two
// lifting steps (-15/64, 33/64). Expansion is not volume preserving, so this filter is exactly
// invertible but wastes code space at step 1; lossless tiles keep overlap4. Constants tuned by
// measurement on SRTM tiles at equal rms (docs/codec.md).
constexpr int kExpandInner = 26, kExpandOuter = 21, kLiftOuter = -15, kLiftInner = 33;
template <class T> CODEC_INLINE void lossy_pre4(T& a, T& b, T& c, T& d) {
  T t3 = sub(a, d);
  const T t0 = add(d, t3 >> 1);
  T t2 = sub(b, c);
  const T t1 = add(c, t2 >> 1);
  t2 = expand<kExpandInner>(t2);
  t3 = expand<kExpandOuter>(t3);
  t3 = add(t3, lift64(kLiftOuter, t2));
  t2 = add(t2, lift64(kLiftInner, t3));
  c = sub(t1, t2 >> 1);
  b = add(t2, c);
  d = sub(t0, t3 >> 1);
  a = add(t3, d);
}
template <class T> CODEC_INLINE void lossy_post4(T& a, T& b, T& c, T& d) {
  T t3 = sub(a, d);
  const T t0 = add(d, t3 >> 1);
  T t2 = sub(b, c);
  const T t1 = add(c, t2 >> 1);
  t2 = sub(t2, lift64(kLiftInner, t3));
  t3 = sub(t3, lift64(kLiftOuter, t2));
  t2 = shrink<kExpandInner>(t2);
  t3 = shrink<kExpandOuter>(t3);
  c = sub(t1, t2 >> 1);
  b = add(t2, c);
  d = sub(t0, t3 >> 1);
  a = add(t3, d);
}

// The 4-point steps as types, so that one kernel template serves every lane type.
struct Fwd4 {
  template <class T> CODEC_INLINE static void apply(T& a, T& b, T& c, T& d) { fwd4(a, b, c, d); }
};
struct Inv4 {
  template <class T> CODEC_INLINE static void apply(T& a, T& b, T& c, T& d) { inv4(a, b, c, d); }
};
struct Pre4 {
  template <class T> CODEC_INLINE static void apply(T& a, T& b, T& c, T& d) { overlap4<1>(a, b, c, d); }
};
struct Post4 {
  template <class T> CODEC_INLINE static void apply(T& a, T& b, T& c, T& d) { overlap4<-1>(a, b, c, d); }
};
struct LossyPre4 {
  template <class T> CODEC_INLINE static void apply(T& a, T& b, T& c, T& d) { lossy_pre4(a, b, c, d); }
};
struct LossyPost4 {
  template <class T> CODEC_INLINE static void apply(T& a, T& b, T& c, T& d) { lossy_post4(a, b, c, d); }
};

// Op on the four samples p[0], p[step], p[2 step], p[3 step].
template <class Op> CODEC_INLINE void op_at(int32_t* p, ptrdiff_t step) {
  int32_t a = p[0], b = p[step], c = p[2 * step], d = p[3 * step];
  Op::apply(a, b, c, d);
  p[0] = a;
  p[step] = b;
  p[2 * step] = c;
  p[3 * step] = d;
}

// Op down four rows (r0..r3 apart by `stride`) for `count` columns spaced `step` apart; contiguous
// columns (step 1) vectorise.
template <class Op> CODEC_INLINE void down_rows(int32_t* top, ptrdiff_t stride, int count, int step) {
  for (int i = 0; i < count; ++i) op_at<Op>(top + ptrdiff_t(i) * step, stride);
}

// The inverse's stage 2 on the grid of block DCs (1/16 of the samples): scalar everywhere.
template <class Post, bool Two> void inverse_stage2(int32_t* tile, int width, int height) {
  for (int y = 0; y < height; y += 16)
    down_rows<Inv4>(tile + ptrdiff_t(y) * width, ptrdiff_t(4) * width, width / 4, 4);
  for (int y = 0; y < height; y += 4)
    for (int x = 0; x < width; x += 16) op_at<Inv4>(tile + ptrdiff_t(y) * width + x, 4);
  if (Two) {
    for (int edge = 16; edge < height; edge += 16)
      down_rows<Post>(tile + ptrdiff_t(edge - 8) * width, ptrdiff_t(4) * width, width / 4, 4);
    for (int y = 0; y < height; y += 4)
      for (int edge = 16; edge < width; edge += 16) op_at<Post>(tile + ptrdiff_t(y) * width + edge - 8, 4);
  }
}

#ifdef CODEC_VECTOR_TRANSFORM
// Vectors go through references only: a by-value vector wider than the baseline ISA changes the ABI.
template <class V> CODEC_INLINE void load(V& v, const int32_t* p) { std::memcpy(&v, p, sizeof(V)); }
template <class V> CODEC_INLINE void store(int32_t* p, const V& v) { std::memcpy(p, &v, sizeof(V)); }

// Transposes the 4x4 blocks held by four rows, each 128-bit lane on its own.
CODEC_INLINE void transpose4(V4& a, V4& b, V4& c, V4& d) {
  const V4 t0 = __builtin_shufflevector(a, b, 0, 4, 1, 5), t1 = __builtin_shufflevector(a, b, 2, 6, 3, 7);
  const V4 t2 = __builtin_shufflevector(c, d, 0, 4, 1, 5), t3 = __builtin_shufflevector(c, d, 2, 6, 3, 7);
  a = __builtin_shufflevector(t0, t2, 0, 1, 4, 5);
  b = __builtin_shufflevector(t0, t2, 2, 3, 6, 7);
  c = __builtin_shufflevector(t1, t3, 0, 1, 4, 5);
  d = __builtin_shufflevector(t1, t3, 2, 3, 6, 7);
}
CODEC_INLINE void transpose4(V8& a, V8& b, V8& c, V8& d) {
  const V8 t0 = __builtin_shufflevector(a, b, 0, 8, 1, 9, 4, 12, 5, 13);
  const V8 t1 = __builtin_shufflevector(a, b, 2, 10, 3, 11, 6, 14, 7, 15);
  const V8 t2 = __builtin_shufflevector(c, d, 0, 8, 1, 9, 4, 12, 5, 13);
  const V8 t3 = __builtin_shufflevector(c, d, 2, 10, 3, 11, 6, 14, 7, 15);
  a = __builtin_shufflevector(t0, t2, 0, 1, 8, 9, 4, 5, 12, 13);
  b = __builtin_shufflevector(t0, t2, 2, 3, 10, 11, 6, 7, 14, 15);
  c = __builtin_shufflevector(t1, t3, 0, 1, 8, 9, 4, 5, 12, 13);
  d = __builtin_shufflevector(t1, t3, 2, 3, 10, 11, 6, 7, 14, 15);
}
CODEC_INLINE void transpose4(V16& a, V16& b, V16& c, V16& d) {
  const V16 t0 = __builtin_shufflevector(a, b, 0, 16, 1, 17, 4, 20, 5, 21, 8, 24, 9, 25, 12, 28, 13, 29);
  const V16 t1 = __builtin_shufflevector(a, b, 2, 18, 3, 19, 6, 22, 7, 23, 10, 26, 11, 27, 14, 30, 15, 31);
  const V16 t2 = __builtin_shufflevector(c, d, 0, 16, 1, 17, 4, 20, 5, 21, 8, 24, 9, 25, 12, 28, 13, 29);
  const V16 t3 = __builtin_shufflevector(c, d, 2, 18, 3, 19, 6, 22, 7, 23, 10, 26, 11, 27, 14, 30, 15, 31);
  a = __builtin_shufflevector(t0, t2, 0, 1, 16, 17, 4, 5, 20, 21, 8, 9, 24, 25, 12, 13, 28, 29);
  b = __builtin_shufflevector(t0, t2, 2, 3, 18, 19, 6, 7, 22, 23, 10, 11, 26, 27, 14, 15, 30, 31);
  c = __builtin_shufflevector(t1, t3, 0, 1, 16, 17, 4, 5, 20, 21, 8, 9, 24, 25, 12, 13, 28, 29);
  d = __builtin_shufflevector(t1, t3, 2, 3, 18, 19, 6, 7, 22, 23, 10, 11, 26, 27, 14, 15, 30, 31);
}

// Op on the four rows at p (row stride `stride`), sizeof(V) / 4 columns.
template <class Op, class V> CODEC_INLINE void on_rows(int32_t* p, ptrdiff_t stride) {
  V a, b, c, d;
  load(a, p);
  load(b, p + stride);
  load(c, p + 2 * stride);
  load(d, p + 3 * stride);
  Op::apply(a, b, c, d);
  store(p, a);
  store(p + stride, b);
  store(p + 2 * stride, c);
  store(p + 3 * stride, d);
}
// Op along the rows of each 4x4 block held by four row vectors.
template <class Op> struct Transposed {
  template <class V> CODEC_INLINE static void apply(V& a, V& b, V& c, V& d) {
    transpose4(a, b, c, d);
    Op::apply(a, b, c, d);
    transpose4(a, b, c, d);
  }
};
// Stage 1 of the inverse on whole 4x4 blocks: columns, then rows (both stay inside the block).
struct InverseBlock {
  template <class V> CODEC_INLINE static void apply(V& a, V& b, V& c, V& d) {
    inv4(a, b, c, d);
    Transposed<Inv4>::apply(a, b, c, d);
  }
};

// inverse_stage2 with 4-lane vectors: the grid of block DCs (every 4th sample of every 4th row) is
// copied out into a compact (width / 4) x (height / 4) array, where the stage's steps have the shape
// of stage 1 (4-point steps inside 4x4 blocks, post-filters across every 4th row and column), and
// copied back. The same steps on the same values in the same order, so the same result; the scalar
// stage was about a quarter of a 32x32 tile's inverse. Tiles above 256x256 keep the scalar stage.
template <class Post, bool Two> void inverse_stage2_lanes(int32_t* tile, int width, int height) {
  const int cw = width / 4, ch = height / 4;
  constexpr int kMaxGrid = 64 * 64;
  if (cw * ch > kMaxGrid) {
    inverse_stage2<Post, Two>(tile, width, height);
    return;
  }
  int32_t grid[kMaxGrid];
  for (int j = 0; j < ch; ++j)
    for (int i = 0; i < cw; ++i) grid[j * cw + i] = tile[ptrdiff_t(4 * j) * width + 4 * i];
  for (int y = 0; y < ch; y += 4)
    for (int x = 0; x < cw; x += 4) on_rows<InverseBlock, V4>(grid + y * cw + x, cw);
  if (Two) {
    for (int edge = 4; edge < ch; edge += 4)
      for (int x = 0; x < cw; x += 4) on_rows<Post, V4>(grid + (edge - 2) * cw + x, cw);
    for (int y = 0; y < ch; y += 4)
      for (int edge = 4; edge < cw; edge += 4) on_rows<Transposed<Post>, V4>(grid + y * cw + edge - 2, cw);
  }
  for (int j = 0; j < ch; ++j)
    for (int i = 0; i < cw; ++i) tile[ptrdiff_t(4 * j) * width + 4 * i] = grid[j * cw + i];
}

// Same result as inverse_impl (lapped_transform.cpp) with lanes of type V.
template <class V, class Post, bool Two> void inverse_lanes(int32_t* tile, int width, int height) {
  constexpr int kLanes = int(sizeof(V) / sizeof(int32_t));
  inverse_stage2_lanes<Post, Two>(tile, width, height);
  for (int y = 0; y < height; y += 4)
    for (int x = 0; x < width; x += kLanes) on_rows<InverseBlock, V>(tile + ptrdiff_t(y) * width + x, width);
  for (int edge = 4; edge < height; edge += 4)
    for (int x = 0; x < width; x += kLanes) on_rows<Post, V>(tile + ptrdiff_t(edge - 2) * width + x, width);
  // Windows [edge - 2, edge + 2) across the vertical block edges, kLanes / 4 of them per step.
  for (int y = 0; y < height; y += 4) {
    int32_t* row = tile + ptrdiff_t(y) * width;
    int edge = 4;
    for (; edge + kLanes - 4 < width; edge += kLanes) on_rows<Transposed<Post>, V>(row + edge - 2, width);
    for (; edge < width; edge += 4) on_rows<Transposed<Post>, V4>(row + edge - 2, width);
  }
}

// inverse_lanes with the post-filter of a lossy or a lossless tile.
template <class V> void inverse_lanes(int32_t* tile, int width, int height, bool lossy) {
  if (lossy)
    inverse_lanes<V, LossyPost4, true>(tile, width, height);
  else
    inverse_lanes<V, Post4, false>(tile, width, height);
}
#endif

}  // namespace
}  // namespace codec::detail
