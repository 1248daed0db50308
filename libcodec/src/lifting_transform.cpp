// The residual transform (lifting_transform.h). Both directions share predict() and update(), so the
// decoder recomputes exactly the encoder's rounded values and the lifting inverts bit for bit.
#include "codec/internal/lifting_transform.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

namespace codec::detail {
namespace {

// Wrapping arithmetic: the sums of a corrupt stream may overflow int32.
inline int32_t wrap(int64_t v) { return int32_t(uint32_t(uint64_t(v))); }

// Even sample e of s[0..n), extended by repetition past the ends: residuals are noise-like, and the
// point reflection U uses for heights (2 s0 - s1) would double the noise at a tile edge (measured in
// experiments/wavelet_pyramid: constant extension 2.997 bits/sample on Rainier at rms 1 m and 64-sample
// tiles, mirroring 3.003, point reflection 3.034).
inline int64_t even_at(const int32_t* s, int n, int e) { return s[std::clamp(e, 0, n - 1)]; }
// Detail i of d[0..n), n >= 1, mirrored about the half-sample points outside the ends.
inline int64_t odd_at(const int32_t* d, int n, int i) {
  while (i < 0 || i >= n) i = i < 0 ? -i - 1 : 2 * n - 1 - i;
  return d[i];
}
inline int32_t predict(const int32_t* s, int ne, int i) {
  const int64_t p =
      -even_at(s, ne, i - 1) + 9 * even_at(s, ne, i) + 9 * even_at(s, ne, i + 1) - even_at(s, ne, i + 2);
  return wrap((p + 8) >> 4);
}
inline int32_t update(const int32_t* d, int no, int i) {
  const int64_t u =
      -odd_at(d, no, i - 2) + 9 * odd_at(d, no, i - 1) + 9 * odd_at(d, no, i) - odd_at(d, no, i + 1);
  return wrap((u + 16) >> 5);
}

// One line of n samples at x[0], x[stride], ...; line: n values of scratch.
void forward_line(int32_t* x, int n, int stride, int32_t* line) {
  if (n < 2) return;
  const int ne = (n + 1) / 2, no = n / 2;
  int32_t* s = line;
  int32_t* d = line + ne;
  for (int i = 0; i < ne; ++i) s[i] = x[size_t(2 * i) * stride];
  for (int i = 0; i < no; ++i) d[i] = wrap(int64_t(x[size_t(2 * i + 1) * stride]) - predict(s, ne, i));
  for (int i = 0; i < ne; ++i) s[i] = wrap(int64_t(s[i]) + update(d, no, i));
  for (int i = 0; i < n; ++i) x[size_t(i) * stride] = line[i];
}
void inverse_line(int32_t* x, int n, int stride, int32_t* line) {
  if (n < 2) return;
  const int ne = (n + 1) / 2, no = n / 2;
  for (int i = 0; i < n; ++i) line[i] = x[size_t(i) * stride];
  int32_t* s = line;
  const int32_t* d = line + ne;
  for (int i = 0; i < ne; ++i) s[i] = wrap(int64_t(s[i]) - update(d, no, i));
  for (int i = 0; i < ne; ++i) x[size_t(2 * i) * stride] = s[i];
  for (int i = 0; i < no; ++i) x[size_t(2 * i + 1) * stride] = wrap(int64_t(d[i]) + predict(s, ne, i));
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
  std::vector<int32_t> tile(size_t(kProbeSide) * kProbeSide), line(kProbeSide);
  for (int band = 0; band < kLiftingBandCount; ++band) {
    std::fill(tile.begin(), tile.end(), 0);
    tile[size_t(at[band][1]) * kProbeSide + size_t(at[band][0])] = kImpulse;
    inverse_lifting(tile.data(), kProbeSide, kProbeSide, line.data());
    double energy = 0;
    for (int32_t v : tile) energy += double(v) * double(v);
    norms[size_t(band)] = std::sqrt(energy) / kImpulse;
  }
  return norms;
}

}  // namespace

void forward_lifting(int32_t* tile, int w, int h, int32_t* line) {
  for (int y = 0; y < h; ++y) forward_line(tile + size_t(y) * w, w, 1, line);
  for (int x = 0; x < w; ++x) forward_line(tile + x, h, w, line);
}

void inverse_lifting(int32_t* tile, int w, int h, int32_t* line) {
  for (int x = 0; x < w; ++x) inverse_line(tile + x, h, w, line);
  for (int y = 0; y < h; ++y) inverse_line(tile + size_t(y) * w, w, 1, line);
}

const double* lifting_synthesis_norms() {
  static const std::array<double, kLiftingBandCount> norms = measure_norms();
  return norms.data();
}

}  // namespace codec::detail
