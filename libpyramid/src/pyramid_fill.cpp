// Push-pull nodata fill over tiles of a band (see pyramid_fill.h).
#include "pyramid/internal/pyramid_fill.h"

#include <algorithm>

namespace terrain::detail {
namespace {

int32_t rounded_mean(int64_t sum, int64_t count) {
  const int64_t q = sum >= 0 ? (2 * sum + count) / (2 * count) : -((-2 * sum + count) / (2 * count));
  return int32_t(q);
}

// Fills one tile (tw x th at `values`, row stride `stride`); returns false when it has no valid sample.
bool fill_tile(int32_t* values, const uint8_t* valid, int64_t stride, int64_t tw, int64_t th, int32_t* mean,
               PushPullScratch& s) {
  // Level sizes and offsets of the sum/count pyramid, finest first.
  struct Lvl {
    int64_t w, h, off;
  };
  std::vector<Lvl> lv;
  int64_t total = 0;
  for (int64_t w = tw, h = th;; w = (w + 1) / 2, h = (h + 1) / 2) {
    lv.push_back({w, h, total});
    total += w * h;
    if (w == 1 && h == 1) break;
  }
  s.sum.assign(size_t(total), 0);
  s.count.assign(size_t(total), 0);
  for (int64_t y = 0; y < th; ++y)
    for (int64_t x = 0; x < tw; ++x)
      if (valid[y * stride + x]) {
        s.sum[size_t(y * tw + x)] = values[y * stride + x];
        s.count[size_t(y * tw + x)] = 1;
      }
  for (size_t l = 1; l < lv.size(); ++l) {
    const Lvl &f = lv[l - 1], &c = lv[l];
    for (int64_t y = 0; y < f.h; ++y)
      for (int64_t x = 0; x < f.w; ++x) {
        const size_t src = size_t(f.off + y * f.w + x), dst = size_t(c.off + (y / 2) * c.w + x / 2);
        s.sum[dst] += s.sum[src];
        s.count[dst] += s.count[src];
      }
  }
  const Lvl& top = lv.back();
  if (s.count[size_t(top.off)] == 0) return false;
  *mean = rounded_mean(s.sum[size_t(top.off)], s.count[size_t(top.off)]);
  // Push: a block without valid samples inherits its parent's value (stored as sum with count 1).
  for (size_t l = lv.size() - 1; l-- > 0;) {
    const Lvl &f = lv[l], &c = lv[l + 1];
    for (int64_t y = 0; y < f.h; ++y)
      for (int64_t x = 0; x < f.w; ++x) {
        const size_t i = size_t(f.off + y * f.w + x), p = size_t(c.off + (y / 2) * c.w + x / 2);
        if (s.count[i] == 0) {
          s.sum[i] = rounded_mean(s.sum[p], s.count[p]);
          s.count[i] = 1;
        }
      }
  }
  for (int64_t y = 0; y < th; ++y)
    for (int64_t x = 0; x < tw; ++x)
      if (!valid[y * stride + x]) values[y * stride + x] = int32_t(s.sum[size_t(y * tw + x)]);
  return true;
}

}  // namespace

void fill_voids(int32_t* values, const uint8_t* valid, int64_t w, int64_t h, int64_t tile, int32_t* carry,
                PushPullScratch& scratch) {
  tile = std::max<int64_t>(tile, 1);
  std::vector<int64_t> empty_tiles;
  for (int64_t x0 = 0; x0 < w; x0 += tile) {
    const int64_t tw = std::min(tile, w - x0);
    bool any_void = false;
    for (int64_t y = 0; y < h && !any_void; ++y)
      for (int64_t x = 0; x < tw; ++x)
        if (!valid[y * w + x0 + x]) {
          any_void = true;
          break;
        }
    int32_t mean = *carry;
    if (!any_void) {
      // Still need the mean for the carry: it keeps empty tiles close to their surroundings.
      int64_t sum = 0;
      for (int64_t y = 0; y < h; ++y)
        for (int64_t x = 0; x < tw; ++x) sum += values[y * w + x0 + x];
      *carry = rounded_mean(sum, tw * h);
      continue;
    }
    if (fill_tile(values + x0, valid + x0, w, tw, h, &mean, scratch)) {
      *carry = mean;
    } else {
      for (int64_t y = 0; y < h; ++y) std::fill(values + y * w + x0, values + y * w + x0 + tw, *carry);
    }
  }
}

}  // namespace terrain::detail
