// D: the 11x11 downsampling filter, its symmetric parametrisation and the streaming row engine.
#include "pyramid/internal/filter_downsample.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "pyramid/internal/pyramid_parallel.h"

namespace terrain {

bool DownsampleFilter::symmetric8() const {
  for (int dy = -kRadius; dy <= kRadius; ++dy)
    for (int dx = -kRadius; dx <= kRadius; ++dx) {
      const double v = tap(dx, dy);
      if (v != tap(-dx, dy) || v != tap(dx, -dy) || v != tap(dy, dx)) return false;
    }
  return true;
}

double DownsampleFilter::sum() const {
  double s = 0;
  for (double v : taps) s += v;
  return s;
}

const std::array<FilterOrbit, 21>& symmetric_orbits() {
  static const std::array<FilterOrbit, 21> orbits = [] {
    std::array<FilterOrbit, 21> o{};
    int k = 0;
    for (int a = 0; a <= DownsampleFilter::kRadius; ++a)
      for (int b = 0; b <= a; ++b) {
        const int count = (a == 0) ? 1 : (b == 0 || b == a) ? 4 : 8;
        o[size_t(k++)] = {a, b, count};
      }
    return o;
  }();
  return orbits;
}

DownsampleFilter DownsampleFilter::from_orbit_weights(const std::array<double, 21>& w, Kind kind) {
  DownsampleFilter f;
  f.kind = kind;
  const auto& orbits = symmetric_orbits();
  for (int dy = -kRadius; dy <= kRadius; ++dy)
    for (int dx = -kRadius; dx <= kRadius; ++dx) {
      const int a = std::max(std::abs(dx), std::abs(dy)), b = std::min(std::abs(dx), std::abs(dy));
      for (size_t k = 0; k < orbits.size(); ++k)
        if (orbits[k].a == a && orbits[k].b == b)
          f.taps[size_t((dy + kRadius) * kSize + dx + kRadius)] = w[k];
    }
  return f;
}

DownsampleFilter DownsampleFilter::default_filter() {
  std::array<double, 21> w{};
  w[0] = 0.25;    // (0,0)
  w[1] = 0.125;   // (1,0)
  w[2] = 0.0625;  // (1,1)
  return from_orbit_weights(w, Kind::Default);
}

namespace {

// The wavelet D's 1-D taps (x 514), centre at index 5.
constexpr double kWaveletTaps[DownsampleFilter::kSize] = {0, 18, -16, -63, 144, 348, 144, -63, -16, 18, 0};
constexpr double kWaveletSum = 514;

// The wavelet D's fused passes (DownsampleEngine::compute_row): each output in one pass with the
// taps as constants (the outer taps are zero), the sums in the order of the per-tap loops they
// replaced, so the doubles are the same to the bit (16384^2 at one thread, alternated: the D cascade
// 1.08-1.18 -> 0.91-0.98 s). An AVX2 clone of the two (no FMA: the same doubles) measured within noise
// of this. The row pointers below assume radius 5.
static_assert(DownsampleFilter::kRadius == 5 && kWaveletTaps[0] == 0 && kWaveletTaps[10] == 0,
              "the fused wavelet D reads rows 2j - 4 .. 2j + 4 (the outer taps are zero)");
constexpr double kH0 = kWaveletTaps[5] / kWaveletSum, kH1 = kWaveletTaps[6] / kWaveletSum,
                 kH2 = kWaveletTaps[7] / kWaveletSum, kH3 = kWaveletTaps[8] / kWaveletSum,
                 kH4 = kWaveletTaps[9] / kWaveletSum;

// v[p] = the column taps over rows rp[1 .. 9] (rp[5] the centre), p in [0, w). kIntPairs: the
// samples are known to lie below 2^30 in magnitude, so each symmetric pair is added as int32 and converted
// once: the same doubles (both sums are exact), four conversions and adds fewer per sample.
template <bool kIntPairs> void wavelet_columns(const int32_t* const* rp, int64_t w, double* v) {
  const int32_t *c0 = rp[5], *u1 = rp[4], *d1 = rp[6], *u2 = rp[3], *d2 = rp[7], *u3 = rp[2], *d3 = rp[8],
                *u4 = rp[1], *d4 = rp[9];
  const auto pair = [](int32_t a, int32_t b) {
    if constexpr (kIntPairs)
      return double(a + b);
    else
      return double(a) + double(b);
  };
  for (int64_t p = 0; p < w; ++p) {
    double x = kH0 * double(c0[p]);
    x += kH1 * pair(u1[p], d1[p]);
    x += kH2 * pair(u2[p], d2[p]);
    x += kH3 * pair(u3[p], d3[p]);
    x += kH4 * pair(u4[p], d4[p]);
    v[p] = x;
  }
}

// round_to_int32(x) for |x| below 2^30, in double arithmetic only, so that loops over it vectorise:
// x + 1.5 2^52 - 1.5 2^52 is x rounded to nearest, ties to even (exact below 2^51), and a tie that
// went towards zero steps away from it.
inline double round_half_away_small(double x) {
  constexpr double kMagic = 6755399441055744.0;  // 1.5 2^52
  const double r = (x + kMagic) - kMagic;
  const double d = x - r;
  const double up = ((d == 0.5) & (x > 0)) ? 1.0 : 0.0;
  const double down = ((d == -0.5) & (x < 0)) ? 1.0 : 0.0;
  return r + up - down;
}

// out[i] = the row taps centred on padded position 2i + 5 of `padded`, read at stride 2 where they
// lie (no split of the row into its even and odd samples, no copy out of a scratch row).
// kRound: rounded as round_row's fast path does, for outputs known to lie below 2^30 in magnitude
// (no range check; the rounding was a third of the engine's instructions as a pass of its own).
template <bool kRound> void wavelet_rows(const double* padded, int64_t cw, double* out) {
  for (int64_t i = 0; i < cw; ++i) {
    const double* c = padded + 2 * i + 5;
    double x = kH0 * c[0];
    x += kH1 * (c[1] + c[-1]);
    x += kH2 * (c[2] + c[-2]);
    x += kH3 * (c[3] + c[-3]);
    x += kH4 * (c[4] + c[-4]);
    out[i] = kRound ? round_half_away_small(x) : x;
  }
}

}  // namespace

DownsampleFilter DownsampleFilter::wavelet() {
  const double* h = kWaveletTaps;
  const double sum = kWaveletSum;
  DownsampleFilter f;
  f.kind = Kind::Wavelet;
  for (int y = 0; y < kSize; ++y)
    for (int x = 0; x < kSize; ++x) f.taps[size_t(y * kSize + x)] = h[y] * h[x] / (sum * sum);
  return f;
}

bool DownsampleFilter::is_wavelet() const { return taps == wavelet().taps; }

bool DownsampleFilter::is_point() const { return taps == impulse().taps; }

DownsampleFilter DownsampleFilter::impulse() {
  std::array<double, 21> w{};
  w[0] = 1.0;
  return from_orbit_weights(w, Kind::Impulse);
}

DownsampleFilter DownsampleFilter::box2x2() {
  DownsampleFilter f;
  f.kind = Kind::Box2x2;
  for (int dy = 0; dy <= 1; ++dy)
    for (int dx = 0; dx <= 1; ++dx) f.taps[size_t((dy + kRadius) * kSize + dx + kRadius)] = 0.25;
  return f;
}

namespace detail {

void round_row(double* out, int64_t n) {
  // Every |x| below 2^30 (always, for D of int16 levels): the exponent fields, read as integers,
  // checked in one pass the compiler vectorises (a bit set at 2^63 where a biased exponent reaches
  // 1053; NaN and infinities too).
  uint64_t far = 0;
  for (int64_t i = 0; i < n; ++i) {
    uint64_t b;
    std::memcpy(&b, out + i, sizeof b);
    far |= (b & 0x7ff0000000000000ull) + (uint64_t(2048 - 1053) << 52);
  }
  if (far >> 63) {
    for (int64_t i = 0; i < n; ++i) out[i] = double(round_to_int32(out[i]));
    return;
  }
  // Then the same rule vectorised (it was a call and two branches per sample, a third of the D
  // engine's time).
  for (int64_t i = 0; i < n; ++i) out[i] = round_half_away_small(out[i]);
}

int32_t round_to_int32(double x) {
  // std::round(x), saturated, without the libm call std::round is without SSE4.1 (the D engine alone
  // on 8192^2: 0.195-0.200 -> 0.175-0.181 s): truncate, then step away from zero when the dropped
  // part is at least a half. Below 2^31 in magnitude x - t is exact. Checked equal to the std::round form
  // on 2.1e8 values (random, halves, the int32 limits and their neighbours, infinities, NaN: INT32_MIN).
  if (!(x > -2147483647.5)) return std::numeric_limits<int32_t>::min();  // and NaN
  if (x >= 2147483646.5) return std::numeric_limits<int32_t>::max();
  const int64_t t = int64_t(x);
  const double f = x - double(t);
  return int32_t(t + (f >= 0.5) - (f <= -0.5));
}

DownsampleEngine::DownsampleEngine(const DownsampleFilter& filter, GridSize fine, int threads,
                                   int64_t batch_rows, bool rounded, int64_t max_abs)
    : filter_(filter),
      symmetric_(filter.symmetric8()),
      separable_(filter.is_wavelet()),
      int_pairs_(max_abs > 0 && max_abs < (int64_t(1) << 30)),
      rounded_(rounded),
      fine_(fine),
      coarse_{coarse_extent(fine.width), coarse_extent(fine.height)},
      threads_(std::max(1, threads)),
      batch_(std::max<int64_t>(1, batch_rows)),
      padded_width_(fine.width + 2 * DownsampleFilter::kRadius) {
  if (fine.width <= 0 || fine.height <= 0) throw std::invalid_argument("downsample: empty grid");
  capacity_ = std::min(fine.height, 2 * batch_ + 16);
  rows_.resize(size_t(capacity_ * fine.width));
  scratch_.resize(size_t(threads_));
  const int64_t out_bound = coarse_bound(filter, max_abs);
  fused_round_ = separable_ && rounded_ && int_pairs_ && out_bound > 0 && out_bound < (int64_t(1) << 30);
}

int64_t DownsampleEngine::coarse_bound(const DownsampleFilter& filter, int64_t max_abs) {
  if (max_abs <= 0) return 0;
  double gain = 0;
  for (double t : filter.taps) gain += std::fabs(t);
  // |D(x)| <= gain * max_abs; 1e-9 of it and 1 more cover the sum's rounding and round_to_int32.
  const double bound = std::ceil(gain * double(max_abs) * (1 + 1e-9)) + 1;
  return bound <= std::ldexp(1.0, 40) ? int64_t(bound) : 0;
}

const int32_t* DownsampleEngine::fine_row(int64_t row) const {
  if (block_ && row >= block_first_) return block_ + (row - block_first_) * fine_.width;
  return rows_.data() + (row - base_) * fine_.width;
}

void DownsampleEngine::reflect_padding(double* dst) const {
  const int64_t r = DownsampleFilter::kRadius, w = fine_.width;
  for (int64_t p = 0; p < r; ++p) {
    dst[p] = dst[r + reflect_index(p - r, w)];
    dst[w + r + p] = dst[r + reflect_index(w + p, w)];
  }
}

void DownsampleEngine::pad_row(const int32_t* row, double* dst) const {
  const int64_t r = DownsampleFilter::kRadius;
  for (int64_t x = 0; x < fine_.width; ++x) dst[x + r] = double(row[x]);
  reflect_padding(dst);
}

int64_t DownsampleEngine::min_row_needed(int64_t j) const {
  // Small grids fold the reflection several times: keep everything (they fit the buffer).
  if (fine_.height < 16 || j >= coarse_.height) return fine_.height < 16 ? 0 : base_ + count_;
  int64_t lo = fine_.height;
  for (int dy = -DownsampleFilter::kRadius; dy <= DownsampleFilter::kRadius; ++dy)
    lo = std::min(lo, reflect_index(2 * j + dy, fine_.height));
  return lo;
}

int64_t DownsampleEngine::rows_needed_through(int64_t j_end) {
  if (needed_from_ == next_coarse_ && needed_to_ == j_end) return needed_rows_;
  needed_from_ = next_coarse_;
  needed_to_ = j_end;
  int64_t hi = -1;
  for (int64_t j = next_coarse_; j < j_end; ++j)
    for (int dy = -DownsampleFilter::kRadius; dy <= DownsampleFilter::kRadius; ++dy)
      hi = std::max(hi, reflect_index(2 * j + dy, fine_.height));
  needed_rows_ = hi + 1;
  return needed_rows_;
}

void DownsampleEngine::push_rows(const int32_t* rows, int64_t count, const Emit& emit) {
  if (count <= 0) return;
  if (count > fine_.height - pushed_)
    throw std::invalid_argument("downsample: more rows than the grid height");
  // The batches read the caller's rows where they are, during this call; only the rows later batches
  // still need are copied (D's halo, or rows short of a batch). Copying every row in was serial work
  // beside the workers' batches: 18 % of the engine's samples at one thread (experiments/d_engine).
  block_ = rows;
  block_first_ = pushed_;
  pushed_ += count;
  for (;;) {
    const int64_t j_end = std::min(coarse_.height, next_coarse_ + batch_);
    if (next_coarse_ >= coarse_.height || pushed_ < rows_needed_through(j_end)) break;
    compute(next_coarse_, j_end, emit);
    next_coarse_ = j_end;
  }
  const int64_t keep_from = next_coarse_ >= coarse_.height
                                ? pushed_
                                : std::max(base_, std::min(min_row_needed(next_coarse_), pushed_));
  // The held rows end where the block starts (base_ + count_ == block_first_).
  const int64_t drop = std::min(count_, keep_from - base_);
  if (drop > 0) {
    std::memmove(rows_.data(), rows_.data() + drop * fine_.width,
                 size_t((count_ - drop) * fine_.width) * sizeof(int32_t));
    count_ -= drop;
  }
  base_ = count_ > 0 ? base_ + drop : keep_from;
  const int64_t from = std::max(keep_from, block_first_);
  if (count_ + (pushed_ - from) > capacity_) throw std::logic_error("downsample engine: row buffer overflow");
  std::memcpy(rows_.data() + count_ * fine_.width, rows + (from - block_first_) * fine_.width,
              size_t((pushed_ - from) * fine_.width) * sizeof(int32_t));
  count_ += pushed_ - from;
  block_ = nullptr;
}

void DownsampleEngine::finish(const Emit& emit) {
  if (pushed_ != fine_.height) throw std::invalid_argument("downsample: fewer rows than the grid height");
  while (next_coarse_ < coarse_.height) {
    const int64_t j_end = std::min(coarse_.height, next_coarse_ + batch_);
    compute(next_coarse_, j_end, emit);
    next_coarse_ = j_end;
  }
}

void DownsampleEngine::compute(int64_t j0, int64_t j1, const Emit& emit) {
  const int64_t cw = coarse_.width;
  out_.resize(size_t((j1 - j0) * cw));
  // Threads only pay for themselves on wide batches.
  const int workers = ((j1 - j0) * fine_.width >= (int64_t(1) << 16)) ? threads_ : 1;
  // Rows are claimed one at a time: the batch waits for the rows being computed, not for every
  // worker to be scheduled among the coding threads (parallel_items).
  parallel_items(workers, j1 - j0, [&](int slot, int64_t j) {
    double* out = out_.data() + j * cw;
    compute_row(j0 + j, scratch_[size_t(slot)], out);
    if (rounded_ && !fused_round_) round_row(out, cw);
  });
  emit(j0, j1 - j0, out_.data());
}

void DownsampleEngine::compute_row(int64_t j, Scratch& s, double* out) const {
  const int R = DownsampleFilter::kRadius;
  const int64_t cw = coarse_.width, pw = padded_width_, w = fine_.width;
  const int64_t half_even = (pw + 1) / 2, half_odd = pw / 2;
  const int32_t* rp[DownsampleFilter::kSize];
  for (int dy = -R; dy <= R; ++dy) rp[dy + R] = fine_row(reflect_index(2 * j + dy, fine_.height));
  s.fold.resize(size_t(pw));
  double* fold = s.fold.data();
  if (separable_) {
    // Columns first (the fold of rows 2j +- k), then the same taps along the row, into the output.
    // Columns are independent: combining rows and then padding the result gives the padded result.
    if (int_pairs_)
      wavelet_columns<true>(rp, w, fold + R);
    else
      wavelet_columns<false>(rp, w, fold + R);
    reflect_padding(fold);
    if (fused_round_)
      wavelet_rows<true>(fold, cw, out);
    else
      wavelet_rows<false>(fold, cw, out);
    return;
  }
  // The other paths accumulate into zeros, from the padded rows split into even and odd samples.
  s.acc.assign(size_t(cw), 0.0);
  s.even.resize(size_t(half_even));
  s.odd.resize(size_t(std::max<int64_t>(half_odd, 1)));
  double* acc = s.acc.data();
  const double* E = s.even.data();
  const double* O = s.odd.data();
  // Sample at padded position 2i + 5 + d lives in E[i + (5+d)/2] (5+d even) or O[i + (4+d)/2].
  auto source = [&](int d) -> const double* {
    return ((5 + d) % 2 == 0) ? E + (5 + d) / 2 : O + (4 + d) / 2;
  };
  auto split = [&](const double* row) {
    for (int64_t t = 0; t < half_even; ++t) s.even[size_t(t)] = row[2 * t];
    for (int64_t t = 0; t < half_odd; ++t) s.odd[size_t(t)] = row[2 * t + 1];
  };
  // Columns are independent: combining rows and then padding the result gives the padded result.
  if (symmetric_) {
    for (int k = 0; k <= R; ++k) {
      const int32_t* row = rp[R + k];
      if (k > 0) {
        const int32_t* up = rp[R - k];
        for (int64_t p = 0; p < w; ++p) fold[R + p] = double(row[p]) + double(up[p]);
        reflect_padding(fold);
      } else {
        pad_row(row, fold);
      }
      split(fold);
      for (int m = 0; m <= R; ++m) {
        const double c = filter_.tap(m, k);
        if (c == 0.0) continue;
        const double* a = source(m);
        if (m == 0) {
          for (int64_t i = 0; i < cw; ++i) acc[i] += c * a[i];
        } else {
          const double* b = source(-m);
          for (int64_t i = 0; i < cw; ++i) acc[i] += c * (a[i] + b[i]);
        }
      }
    }
  } else {
    for (int dy = -R; dy <= R; ++dy) {
      pad_row(rp[dy + R], fold);
      split(fold);
      for (int dx = -R; dx <= R; ++dx) {
        const double c = filter_.tap(dx, dy);
        if (c == 0.0) continue;
        const double* a = source(dx);
        for (int64_t i = 0; i < cw; ++i) acc[i] += c * a[i];
      }
    }
  }
  std::copy(acc, acc + cw, out);
}

void downsample_real(const DownsampleFilter& filter, const int32_t* fine, GridSize fine_level, double* coarse,
                     int threads) {
  DownsampleEngine engine(filter, fine_level, threads);
  const int64_t cw = engine.coarse().width;
  auto emit = [&](int64_t j0, int64_t n, const double* rows) {
    std::copy(rows, rows + n * cw, coarse + j0 * cw);
  };
  engine.push_rows(fine, fine_level.height, emit);
  engine.finish(emit);
}

}  // namespace detail

void downsample(const DownsampleFilter& filter, const int32_t* fine, GridSize fine_level, int32_t* coarse,
                int threads) {
  detail::DownsampleEngine engine(filter, fine_level, threads);
  const int64_t cw = engine.coarse().width;
  auto emit = [&](int64_t j0, int64_t n, const double* rows) {
    for (int64_t k = 0; k < n * cw; ++k) coarse[j0 * cw + k] = detail::round_to_int32(rows[k]);
  };
  engine.push_rows(fine, fine_level.height, emit);
  engine.finish(emit);
}

double prediction_rms(const DownsampleFilter& filter, const int32_t* grid, GridSize level, int threads) {
  GridSize c{coarse_extent(level.width), coarse_extent(level.height)};
  std::vector<int32_t> coarse(size_t(c.width * c.height)), pred(size_t(level.width * level.height));
  downsample(filter, grid, level, coarse.data(), threads);
  upsample(coarse.data(), level, pred.data());
  double sum = 0;
  for (size_t k = 0; k < pred.size(); ++k) {
    const double d = double(grid[k]) - double(pred[k]);
    sum += d * d;
  }
  return std::sqrt(sum / double(pred.size()));
}

}  // namespace terrain
