// U: tensor-product four-point interpolatory subdivision (Dyn et al. 1987, Kobbelt 1996), in exact
// integer arithmetic for the pyramid and in double for filter design. One implementation serves
// both the encoder and the runtime region decoder, so prediction is bit-identical on both sides.
#include <algorithm>
#include <cstddef>
#include <limits>
#include <stdexcept>
#include <string>

#include "core/clones.h"
#include "pyramid/pyramid.h"

namespace terrain {
namespace {

// An extended coarse index (-1 .. n+1) as a combination of at most two real samples. Point
// reflection about the edge sample keeps linear ramps exact across the edge.
struct Combo {
  int64_t index[2];
  int64_t weight[2];
  int terms;
};

Combo extension(int64_t e, int64_t n) {
  if (n == 1) return {{0, 0}, {1, 0}, 1};
  if (e >= 0 && e < n) return {{e, 0}, {1, 0}, 1};
  if (e == -1) return {{0, 1}, {2, -1}, 2};
  if (e == n) return {{n - 1, n - 2}, {2, -1}, 2};
  // e == n + 1: 2c[n-1] - c[n-3], where for n == 2 c[-1] = 2c[0] - c[1] gives 3c[1] - 2c[0].
  if (n >= 3) return {{n - 1, n - 3}, {2, -1}, 2};
  return {{1, 0}, {3, -2}, 2};
}

// Coarse index range [lo, hi] (extended) that fine samples [f0, f1) may read along one axis: odd
// sample 2i+1 reads i-1..i+2, even sample 2i reads i. Kept simple and conservative (one sample more
// than strictly needed at some ends) so windows are easy to reason about.
void extended_span(int64_t f0, int64_t f1, int64_t* lo, int64_t* hi) {
  *lo = f0 / 2 - 1;
  *hi = (f1 - 1) / 2 + 2;
}

// Real coarse samples [lo, hi] that the extended span needs.
void real_span(int64_t f0, int64_t f1, int64_t n, int64_t* lo, int64_t* hi) {
  int64_t elo, ehi;
  extended_span(f0, f1, &elo, &ehi);
  int64_t rlo = std::numeric_limits<int64_t>::max(), rhi = std::numeric_limits<int64_t>::min();
  for (int64_t e : {elo, std::max<int64_t>(elo, 0), std::min(ehi, n - 1), ehi}) {
    Combo c = extension(e, n);
    for (int t = 0; t < c.terms; ++t) {
      rlo = std::min(rlo, c.index[t]);
      rhi = std::max(rhi, c.index[t]);
    }
  }
  // Interior extended indices map to themselves, so the four probes above bound the whole span.
  *lo = std::clamp<int64_t>(std::min(rlo, std::max<int64_t>(elo, 0)), 0, n - 1);
  *hi = std::clamp<int64_t>(std::max(rhi, std::min(ehi, n - 1)), 0, n - 1);
}

// Horizontal pass on one coarse row: h[x - fx0] = 16 * U_x(row)(x), exact in Acc (int32 only when
// the caller has bounded the values, int64 or double otherwise). `row` points at coarse column `col0`.
// Samples whose stencil stays inside the row take a branch-free loop over even/odd pairs (the one
// that vectorises); the few near either edge go through extension().
template <class In, class Acc>
void horizontal_row(const In* row, int64_t col0, int64_t n, int64_t fx0, int64_t fw, Acc* h) {
  auto at = [&](int64_t e) -> Acc {
    if (e >= 0 && e < n) return Acc(row[e - col0]);
    Combo c = extension(e, n);
    Acc v = 0;
    for (int t = 0; t < c.terms; ++t) v += Acc(c.weight[t]) * Acc(row[c.index[t] - col0]);
    return v;
  };
  auto edge_sample = [&](int64_t k) {
    int64_t x = fx0 + k;
    int64_t i = x >> 1;
    h[k] = (x & 1) == 0 ? Acc(16) * at(i) : Acc(9) * (at(i) + at(i + 1)) - at(i - 1) - at(i + 2);
  };
  // Fine x = 2i or 2i+1 reads only real samples i-1..i+2 when 1 <= i <= n-3, i.e. 2 <= x < 2n-4.
  const int64_t k_lo = std::clamp<int64_t>(2 - fx0, 0, fw);
  const int64_t k_hi = std::clamp<int64_t>(2 * n - 4 - fx0, k_lo, fw);
  for (int64_t k = 0; k < k_lo; ++k) edge_sample(k);
  int64_t k = k_lo;
  if (k < k_hi && ((fx0 + k) & 1) != 0) {
    const In* p = row + (((fx0 + k) >> 1) - 1 - col0);
    h[k] = Acc(9) * (Acc(p[1]) + Acc(p[2])) - Acc(p[0]) - Acc(p[3]);
    ++k;
  }
  if (k < k_hi) {
    // Pairs (2i, 2i+1) from coarse samples i-1..i+2; p points at i-1 of the first pair.
    const int64_t pairs = (k_hi - k) / 2;
    const In* p = row + (((fx0 + k) >> 1) - 1 - col0);
    Acc* hp = h + k;
    for (int64_t q = 0; q < pairs; ++q) {
      hp[2 * q] = Acc(16) * Acc(p[q + 1]);
      hp[2 * q + 1] = Acc(9) * (Acc(p[q + 1]) + Acc(p[q + 2])) - Acc(p[q]) - Acc(p[q + 3]);
    }
    k += 2 * pairs;
    if (k < k_hi) h[k++] = Acc(16) * Acc(p[pairs + 1]);
  }
  for (; k < fw; ++k) edge_sample(k);
}

inline int32_t saturate_int32(int64_t v) {
  return int32_t(
      std::clamp<int64_t>(v, std::numeric_limits<int32_t>::min(), std::numeric_limits<int32_t>::max()));
}

struct IntegerFinish {
  // s is 16 * value (even rows) or 256 * value (odd rows): round half up, once.
  static int32_t even(int64_t s) { return saturate_int32((s + 8) >> 4); }
  static int32_t odd(int64_t s) { return saturate_int32((s + 128) >> 8); }
};
// For the int32 path: the caller's bound keeps s + 128 inside int32 and the result needs no clamp.
struct Int32Finish {
  static int32_t even(int32_t s) { return (s + 8) >> 4; }
  static int32_t odd(int32_t s) { return (s + 128) >> 8; }
};
struct RealFinish {
  static double even(double s) { return s / 16.0; }
  static double odd(double s) { return s / 256.0; }
};

// Extended coarse rows [*lo, *hi] whose horizontal pass upsample_generic keeps.
void horizontal_rows(const Rect& fine, GridSize clevel, int64_t* lo, int64_t* hi) {
  int64_t ely0, ely1, rly0, rly1;
  extended_span(fine.y0, fine.y0 + fine.height, &ely0, &ely1);
  real_span(fine.y0, fine.y0 + fine.height, clevel.height, &rly0, &rly1);
  // Extended rows near an edge combine real rows that may lie outside the extended span itself.
  *lo = std::min(ely0, rly0);
  *hi = std::max(ely1, rly1);
}

// `scratch` holds (row_hi - row_lo + 1) * fine.width values (horizontal_rows).
template <class In, class Acc, class Out, class Finish>
void upsample_generic(const In* data, int64_t stride, const Rect& have, GridSize clevel, const Rect& fine,
                      Out* out, int64_t out_stride, Acc* scratch) {
  if (fine.width <= 0 || fine.height <= 0) return;
  int64_t ely0, ely1, row_lo, row_hi;
  extended_span(fine.y0, fine.y0 + fine.height, &ely0, &ely1);
  horizontal_rows(fine, clevel, &row_lo, &row_hi);
  const int64_t fw = fine.width;
  auto hrow = [&](int64_t e) { return scratch + (e - row_lo) * fw; };
  // Real rows first, then extended rows as combinations of real ones (U is linear).
  for (int64_t e = row_lo; e <= row_hi; ++e) {
    if (e < 0 || e >= clevel.height) continue;
    const In* row = data + (e - have.y0) * stride;
    horizontal_row<In, Acc>(row, have.x0, clevel.width, fine.x0, fw, hrow(e));
  }
  for (int64_t e = ely0; e <= ely1; ++e) {
    if (e >= 0 && e < clevel.height) continue;
    Combo c = extension(e, clevel.height);
    Acc* dst = hrow(e);
    const Acc* a = hrow(c.index[0]);
    if (c.terms == 1) {
      std::copy(a, a + fw, dst);
    } else {
      const Acc* b = hrow(c.index[1]);
      const Acc wa = Acc(c.weight[0]), wb = Acc(c.weight[1]);
      for (int64_t k = 0; k < fw; ++k) dst[k] = wa * a[k] + wb * b[k];
    }
  }
  for (int64_t r = 0; r < fine.height; ++r) {
    const int64_t y = fine.y0 + r;
    const int64_t j = y >> 1;
    Out* o = out + r * out_stride;
    // The output is usually cold (a whole level is larger than the caches): ask for the row after
    // next while this one is computed, so that its stores do not wait for each line.
    if (r + 2 < fine.height)
      for (int64_t k = 0; k < fw; k += int64_t(64 / sizeof(Out)))
        __builtin_prefetch(o + 2 * out_stride + k, 1, 3);
    if ((y & 1) == 0) {
      const Acc* a = hrow(j);
      for (int64_t k = 0; k < fw; ++k) o[k] = Finish::even(a[k]);
    } else {
      const Acc *a = hrow(j - 1), *b = hrow(j), *c = hrow(j + 1), *d = hrow(j + 2);
      for (int64_t k = 0; k < fw; ++k) o[k] = Finish::odd(Acc(9) * (b[k] + c[k]) - a[k] - d[k]);
    }
  }
}

void check_window(const CoarseWindow& coarse, GridSize fine_level, const Rect& fine) {
  GridSize expect{coarse_extent(fine_level.width), coarse_extent(fine_level.height)};
  if (!(expect == coarse.level))
    throw std::invalid_argument("upsample_region: coarse level size does not match the fine level");
  if (fine.x0 < 0 || fine.y0 < 0 || fine.x0 + fine.width > fine_level.width ||
      fine.y0 + fine.height > fine_level.height)
    throw std::invalid_argument("upsample_region: fine rectangle outside the level");
  Rect need = upsample_required_window(fine, fine_level);
  const Rect& h = coarse.rect;
  if (need.x0 < h.x0 || need.y0 < h.y0 || need.x0 + need.width > h.x0 + h.width ||
      need.y0 + need.height > h.y0 + h.height || coarse.data == nullptr || coarse.stride < h.width)
    throw std::invalid_argument("upsample_region: coarse window does not cover the required samples");
}

// Largest |coarse value| for which no intermediate of the int32 path overflows. Along one axis a
// 16x-scaled sample combines coarse values with absolute weights summing to at most 20 when its
// stencil stays inside the level, and to at most 9*(1+3)+3+5 = 44 where extension() takes part
// (extended values weigh 3 or 5: 2a-b, 3a-2b); an extended row of the vertical pass (5x at most)
// feeds that same bound. The vertical pass multiplies the two gains; 128 is the rounding bias.
int32_t int32_path_limit(const Rect& fine, GridSize clevel) {
  // Fine samples [f0, f1) read only real coarse samples when 2 <= f0 and f1 <= 2n-4 (see horizontal_row).
  auto gain = [](int64_t f0, int64_t f1, int64_t n) -> int64_t {
    return f0 >= 2 && f1 <= 2 * n - 4 ? 20 : 44;
  };
  const int64_t g =
      gain(fine.x0, fine.x0 + fine.width, clevel.width) * gain(fine.y0, fine.y0 + fine.height, clevel.height);
  return int32_t((int64_t(std::numeric_limits<int32_t>::max()) - 128) / g);
}

// Whether all width x height values lie in [-limit, limit] (one min/max pass, vectorisable).
bool within(const int32_t* data, int64_t stride, int64_t width, int64_t height, int32_t limit) {
  int32_t lo = 0, hi = 0;
  for (int64_t y = 0; y < height; ++y) {
    const int32_t* row = data + y * stride;
    for (int64_t x = 0; x < width; ++x) {
      lo = std::min(lo, row[x]);
      hi = std::max(hi, row[x]);
    }
  }
  return lo >= -limit && hi <= limit;
}

// The int32 path (the decoder's and the encoder's prediction), with the bound check, compiled for
// AVX-512 and AVX2 as well as the baseline and picked at load time (target_clones; GCC's flatten
// compiles the templates into each clone; clang does not combine the two): the baseline's SSE2 has
// no 32-bit min/max and 4 lanes.
#if defined(__clang__)
TERRAIN_TARGET_CLONES("arch=x86-64-v4", "avx2", "default")
#else
__attribute__((flatten)) TERRAIN_TARGET_CLONES("arch=x86-64-v4", "avx2", "default")
#endif
bool upsample_int32(const CoarseWindow& coarse, const Rect& need, int32_t limit, const Rect& fine,
                    int32_t* out, int64_t out_stride, int32_t* scratch) {
  const int32_t* need_data =
      coarse.data + (need.y0 - coarse.rect.y0) * coarse.stride + (need.x0 - coarse.rect.x0);
  if (!within(need_data, coarse.stride, need.width, need.height, limit)) return false;
  upsample_generic<int32_t, int32_t, int32_t, Int32Finish>(coarse.data, coarse.stride, coarse.rect,
                                                           coarse.level, fine, out, out_stride, scratch);
  return true;
}

}  // namespace

std::vector<GridSize> pyramid_level_sizes(GridSize finest, int level_count, int64_t min_coarsest_side) {
  if (finest.width <= 0 || finest.height <= 0) throw std::invalid_argument("pyramid: empty grid");
  std::vector<GridSize> sizes{finest};
  for (;;) {
    GridSize cur = sizes.back();
    if (cur.width == 1 && cur.height == 1) break;
    GridSize next{coarse_extent(cur.width), coarse_extent(cur.height)};
    if (level_count > 0) {
      if (int(sizes.size()) >= level_count) break;
    } else if (std::max(next.width, next.height) < min_coarsest_side) {
      break;
    }
    sizes.push_back(next);
  }
  std::reverse(sizes.begin(), sizes.end());
  return sizes;
}

Rect upsample_required_window(const Rect& fine, GridSize fine_level) {
  GridSize c{coarse_extent(fine_level.width), coarse_extent(fine_level.height)};
  if (fine.width <= 0 || fine.height <= 0) return {0, 0, 0, 0};
  int64_t x0, x1, y0, y1;
  real_span(fine.x0, fine.x0 + fine.width, c.width, &x0, &x1);
  real_span(fine.y0, fine.y0 + fine.height, c.height, &y0, &y1);
  return {x0, y0, x1 - x0 + 1, y1 - y0 + 1};
}

void upsample_region(const CoarseWindow& coarse, GridSize fine_level, const Rect& fine, int32_t* out,
                     int64_t out_stride, UpsampleScratch& scratch) {
  if (fine.width <= 0 || fine.height <= 0) return;
  check_window(coarse, fine_level, fine);
  int64_t row_lo, row_hi;
  horizontal_rows(fine, coarse.level, &row_lo, &row_hi);
  const size_t count = size_t((row_hi - row_lo + 1) * fine.width);
  const Rect need = upsample_required_window(fine, fine_level);
  scratch.rows32.resize(count);
  if (!upsample_int32(coarse, need, int32_path_limit(fine, coarse.level), fine, out, out_stride,
                      scratch.rows32.data())) {
    scratch.rows.resize(count);
    upsample_generic<int32_t, int64_t, int32_t, IntegerFinish>(
        coarse.data, coarse.stride, coarse.rect, coarse.level, fine, out, out_stride, scratch.rows.data());
  }
}

void upsample(const int32_t* coarse, GridSize fine_level, int32_t* fine) {
  GridSize c{coarse_extent(fine_level.width), coarse_extent(fine_level.height)};
  CoarseWindow w{coarse, c.width, Rect{0, 0, c.width, c.height}, c};
  UpsampleScratch scratch;
  upsample_region(w, fine_level, Rect{0, 0, fine_level.width, fine_level.height}, fine, fine_level.width,
                  scratch);
}

void upsample_real(const double* coarse, GridSize fine_level, double* fine) {
  GridSize c{coarse_extent(fine_level.width), coarse_extent(fine_level.height)};
  const Rect all{0, 0, fine_level.width, fine_level.height};
  int64_t row_lo, row_hi;
  horizontal_rows(all, c, &row_lo, &row_hi);
  std::vector<double> scratch(size_t((row_hi - row_lo + 1) * all.width));
  upsample_generic<double, double, double, RealFinish>(coarse, c.width, Rect{0, 0, c.width, c.height}, c, all,
                                                       fine, fine_level.width, scratch.data());
}

}  // namespace terrain
