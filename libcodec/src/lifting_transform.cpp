// The residual transform (lifting_transform.h). Both directions share predict() and update(), so the
// decoder recomputes exactly the encoder's rounded values and the lifting inverts bit for bit.
#include "codec/internal/lifting_transform.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <vector>

#include "core/clones.h"

namespace codec::detail {
namespace {

// Wrapping 32-bit arithmetic: a corrupt stream's sums may overflow. For valid streams (|x| < 2^26)
// nothing wraps, and encoder and decoder run these same functions.
inline int32_t add(int32_t a, int32_t b) { return int32_t(uint32_t(a) + uint32_t(b)); }
inline int32_t sub(int32_t a, int32_t b) { return int32_t(uint32_t(a) - uint32_t(b)); }
// (-a + 9 b + 9 c - d + round) >> shift
inline int32_t taps4(int32_t a, int32_t b, int32_t c, int32_t d, uint32_t round, int shift) {
  const uint32_t v = 9u * (uint32_t(b) + uint32_t(c)) - uint32_t(a) - uint32_t(d) + round;
  return int32_t(v) >> shift;
}
inline int32_t predict(int32_t a, int32_t b, int32_t c, int32_t d) { return taps4(a, b, c, d, 8, 4); }
inline int32_t update(int32_t a, int32_t b, int32_t c, int32_t d) { return taps4(a, b, c, d, 16, 5); }

// Even sample e of s[0..n), extended by repetition past the ends: residuals are noise-like, and the
// point reflection U uses for heights (2 s0 - s1) would double the noise at a tile edge (measured in
// experiments/wavelet_pyramid: constant extension 2.997 bits/sample on Rainier at rms 1 m and 64-sample
// tiles, mirroring 3.003, point reflection 3.034).
inline int even_index(int n, int e) { return std::clamp(e, 0, n - 1); }
// Detail i of d[0..n), n >= 1, mirrored about the half-sample points outside the ends.
inline int odd_index(int n, int i) {
  while (i < 0 || i >= n) i = i < 0 ? -i - 1 : 2 * n - 1 - i;
  return i;
}

// Both passes are cloned for AVX-512 and AVX2 (picked at load time, as tile_coder's row outputs).
#define LIFTING_CLONES TERRAIN_TARGET_CLONES("arch=x86-64-v4", "avx2", "default")

// Columns, a whole row of values at a time (the inner loops vectorise). Forward: in place, copy holds
// w * h values.
LIFTING_CLONES void columns_forward(int32_t* tile, int w, int h, int32_t* copy) {
  if (h < 2) return;
  const int ne = (h + 1) / 2, no = h / 2;
  const auto row = [&](int32_t* base, int r) { return base + size_t(r) * w; };
  // copy: the evens in rows [0, ne), the odds in rows [ne, h).
  int32_t* S = copy;
  int32_t* D = copy + size_t(ne) * w;
  for (int i = 0; i < ne; ++i) std::copy_n(row(tile, 2 * i), w, row(S, i));
  for (int i = 0; i < no; ++i) {
    const int32_t *a = row(S, even_index(ne, i - 1)), *b = row(S, i), *c = row(S, even_index(ne, i + 1)),
                  *e = row(S, even_index(ne, i + 2)), *o = row(tile, 2 * i + 1);
    int32_t* out = row(D, i);
    for (int x = 0; x < w; ++x) out[x] = sub(o[x], predict(a[x], b[x], c[x], e[x]));
  }
  for (int i = 0; i < ne; ++i) {
    const int32_t *a = row(D, odd_index(no, i - 2)), *b = row(D, odd_index(no, i - 1)),
                  *c = row(D, odd_index(no, i)), *e = row(D, odd_index(no, i + 1));
    int32_t* out = row(S, i);
    for (int x = 0; x < w; ++x) out[x] = add(out[x], update(a[x], b[x], c[x], e[x]));
  }
  std::copy_n(copy, size_t(w) * h, tile);
}

// The inverse of columns_forward from bands (evens in rows [0, ne), odds below) to samples in out (h
// >= 2): the update is undone in place in bands, the interleave writes out, so no pass copies the tile.
LIFTING_CLONES void columns_inverse(int32_t* bands, int w, int h, int32_t* out) {
  const int ne = (h + 1) / 2, no = h / 2;
  const auto row = [&](int32_t* base, int r) { return base + size_t(r) * w; };
  int32_t* S = bands;
  int32_t* D = bands + size_t(ne) * w;
  for (int i = 0; i < ne; ++i) {
    const int32_t *a = row(D, odd_index(no, i - 2)), *b = row(D, odd_index(no, i - 1)),
                  *c = row(D, odd_index(no, i)), *e = row(D, odd_index(no, i + 1));
    int32_t* s = row(S, i);
    for (int x = 0; x < w; ++x) s[x] = sub(s[x], update(a[x], b[x], c[x], e[x]));
  }
  for (int i = 0; i < ne; ++i) std::copy_n(row(S, i), w, row(out, 2 * i));
  for (int i = 0; i < no; ++i) {
    const int32_t *a = row(S, even_index(ne, i - 1)), *b = row(S, i), *c = row(S, even_index(ne, i + 1)),
                  *e = row(S, even_index(ne, i + 2)), *d = row(D, i);
    int32_t* o = row(out, 2 * i + 1);
    for (int x = 0; x < w; ++x) o[x] = add(d[x], predict(a[x], b[x], c[x], e[x]));
  }
}

constexpr int kProbeSide = 64;
constexpr int32_t kImpulse = 1 << 14;

std::array<double, kLiftingBandCount> measure_norms() {
  std::array<double, kLiftingBandCount> norms{};
  const LiftingBands b = lifting_bands(kProbeSide, kProbeSide);
  const int at[kLiftingBandCount][2] = {{b.even_w / 2, b.even_h / 2},
                                        {b.even_w + b.odd_w / 2, b.even_h / 2},
                                        {b.even_w / 2, b.even_h + b.odd_h / 2},
                                        {b.even_w + b.odd_w / 2, b.even_h + b.odd_h / 2}};
  std::vector<int32_t> tile(size_t(kProbeSide) * kProbeSide),
      scratch(lifting_scratch_size(kProbeSide, kProbeSide));
  for (int band = 0; band < kLiftingBandCount; ++band) {
    std::fill(tile.begin(), tile.end(), 0);
    tile[size_t(at[band][1]) * kProbeSide + size_t(at[band][0])] = kImpulse;
    inverse_lifting(tile.data(), kProbeSide, kProbeSide, scratch.data());
    double energy = 0;
    for (int32_t v : tile) energy += double(v) * double(v);
    norms[size_t(band)] = std::sqrt(energy) / kImpulse;
  }
  return norms;
}

// The row pass runs as a column pass on the transposed tile: the same steps on the same values (so
// the same results), with whole rows of the transposed tile per vector step. Measured on Rainier's
// finest level: the scalar row pass was 14 % of a whole-level decode.
typedef int32_t V8 __attribute__((vector_size(32)));

// The 8x8 block at from (row stride fs) into to (row stride ts) transposed: three rounds of
// interleaves (32-bit pairs, 64-bit pairs, 128-bit halves), 24 shuffles for 64 values.
[[gnu::always_inline]] inline void transpose8x8(const int32_t* from, size_t fs, int32_t* to, size_t ts) {
  V8 r[8], t[8], u[8];
  for (int i = 0; i < 8; ++i) std::memcpy(&r[i], from + size_t(i) * fs, sizeof(V8));
  for (int i = 0; i < 8; i += 2) {
    t[i] = __builtin_shufflevector(r[i], r[i + 1], 0, 8, 1, 9, 4, 12, 5, 13);
    t[i + 1] = __builtin_shufflevector(r[i], r[i + 1], 2, 10, 3, 11, 6, 14, 7, 15);
  }
  for (int i = 0; i < 8; i += 4)
    for (int j = 0; j < 2; ++j) {
      u[i + 2 * j] = __builtin_shufflevector(t[i + j], t[i + j + 2], 0, 1, 8, 9, 4, 5, 12, 13);
      u[i + 2 * j + 1] = __builtin_shufflevector(t[i + j], t[i + j + 2], 2, 3, 10, 11, 6, 7, 14, 15);
    }
  for (int j = 0; j < 4; ++j) {
    const V8 low = __builtin_shufflevector(u[j], u[j + 4], 0, 1, 2, 3, 8, 9, 10, 11);
    const V8 high = __builtin_shufflevector(u[j], u[j + 4], 4, 5, 6, 7, 12, 13, 14, 15);
    std::memcpy(to + size_t(j) * ts, &low, sizeof(V8));
    std::memcpy(to + size_t(j + 4) * ts, &high, sizeof(V8));
  }
}

LIFTING_CLONES void transpose(const int32_t* from, int w, int h, int32_t* to) {
  constexpr int kBlock = 8;
  if (w % kBlock == 0 && h % kBlock == 0) {  // whole tiles: vector blocks
    for (int y0 = 0; y0 < h; y0 += kBlock)
      for (int x0 = 0; x0 < w; x0 += kBlock)
        transpose8x8(from + size_t(y0) * w + x0, size_t(w), to + size_t(x0) * h + y0, size_t(h));
    return;
  }
  for (int y0 = 0; y0 < h; y0 += kBlock)
    for (int x0 = 0; x0 < w; x0 += kBlock)
      for (int y = y0; y < std::min(h, y0 + kBlock); ++y)
        for (int x = x0; x < std::min(w, x0 + kBlock); ++x) to[size_t(x) * h + y] = from[size_t(y) * w + x];
}

}  // namespace

void forward_lifting(int32_t* tile, int w, int h, int32_t* scratch) {
  if (w >= 2) {
    int32_t* t = scratch + size_t(w) * h;  // the transposed tile: h values per row, w rows
    transpose(tile, w, h, t);
    columns_forward(t, h, w, scratch);
    transpose(t, h, w, tile);
  }
  columns_forward(tile, w, h, scratch);
}

void inverse_lifting(int32_t* tile, int w, int h, int32_t* scratch) {
  const size_t n = size_t(w) * h;
  int32_t* samples = scratch;  // after the column pass
  int32_t* t = scratch + n;    // its transpose: h values per row, w rows
  if (h >= 2)
    columns_inverse(tile, w, h, samples);
  else
    std::copy_n(tile, n, samples);
  if (w < 2) {
    std::copy_n(samples, n, tile);
    return;
  }
  transpose(samples, w, h, t);
  columns_inverse(t, h, w, samples);
  transpose(samples, h, w, tile);
}

const double* lifting_synthesis_norms() {
  static const std::array<double, kLiftingBandCount> norms = measure_norms();
  return norms.data();
}

}  // namespace codec::detail
