// Prototype (built as experiments/phase_order, not installed): would another order of the phase tiles'
// phases code a lossless point-sampled pyramid in fewer bits? Today (docs/codec.md "Phase tiles") a
// tile codes phase 1 (odd x, even y) and phase 2 (even x, odd y) predicted from the even-even phase
// alone, which is 0 in a lossless pyramid, so both are coded as they are, and then phase 3 (odd, odd)
// predicted from the mean of its four direct neighbours (phases 1 and 2). Coded in the order 1, 3, 2
// instead, phase 3 sees only its two phase-1 neighbours (above and below) and phase 2 its two phase-3
// neighbours (left and right): this program measures which order leaves fewer bits.
//
// For every level of the pyramid (coarse level = the fine level's even-even samples, as pyramid-build's
// lossless default), R = T_l - U(T_{l-1}) with the product's U (pyramid/upsample.h). Each phase's
// prediction error is counted per context in 32 x 32 tiles as the coder sees them (neighbours outside
// the tile or not yet coded count as 0; predictions over the neighbours inside the tile), the context
// being the bit length (at most 11) of the decoded neighbours' level magnitudes in the coder's fashion
// (the same phase two rows up, and the neighbours at distance 1 that the order has coded). Bits =
// sum over contexts of the empirical entropy of the errors (an adaptive ideal, no model cost: the
// coder's static token family pays a little more on both sides). w scales the new orders' predictions.
// Build: cmake --build build --target phase_order
// Run:   build/experiments/phase_order DEM [TILE]
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <vector>

#include "pyramid/upsample.h"
#include "readers/heightmap.h"

using namespace terrain;

namespace {

// Empirical conditional entropy of values given a context.
struct Counts {
  std::map<std::pair<int, int64_t>, double> joint;
  std::map<int, double> per_context;
  void add(int context, int64_t v) {
    joint[{context, v}] += 1;
    per_context[context] += 1;
  }
  double bits() const {
    double s = 0;
    for (const auto& [k, n] : joint) s -= n * std::log2(n / per_context.at(k.first));
    return s;
  }
};

int context_class(uint64_t a) { return std::min(11, int(std::bit_width(a))); }

struct Level {
  int64_t w, h;
  std::vector<int64_t> r;  // the residual
};

// The new order's prediction weights tried.
constexpr double kWeights[] = {0.5, 0.75, 1.0};
constexpr int kWeightCount = 3;

// Bits of one level's phases 1-3 for the current order and the order 1, 3, 2 with each of kWeights.
struct LevelBits {
  double current = 0, swapped[kWeightCount] = {};
  double n = 0;
};

LevelBits measure(const Level& L, int tile) {
  Counts cur[3], swp[kWeightCount][3];
  const auto code = [&](int64_t tx0, int64_t ty0) {
    const int64_t tx1 = std::min(L.w, tx0 + tile), ty1 = std::min(L.h, ty0 + tile);
    const auto in = [&](int64_t x, int64_t y) { return x >= tx0 && x < tx1 && y >= ty0 && y < ty1; };
    const auto r = [&](int64_t x, int64_t y) -> int64_t { return in(x, y) ? L.r[size_t(y * L.w + x)] : 0; };
    const auto m = [&](int64_t x, int64_t y) -> uint64_t { return uint64_t(std::llabs(r(x, y))); };
    const auto up2 = [&](int64_t x, int64_t y) { return m(x - 2, y - 2) + m(x, y - 2) + m(x + 2, y - 2); };
    const auto mean = [&](std::initializer_list<std::pair<int64_t, int64_t>> at, double weight) {
      double s = 0;
      int k = 0;
      for (auto [x, y] : at)
        if (in(x, y)) s += double(r(x, y)), ++k;
      return k ? int64_t(std::floor(weight * s / k + 0.5)) : 0;
    };
    for (int64_t y = ty0; y < ty1; ++y)
      for (int64_t x = tx0; x < tx1; ++x) {
        const int phase = int(x & 1) + 2 * int(y & 1);
        if (phase == 0) continue;  // the coarse level's samples: 0 in a lossless pyramid, skipped
        const int64_t v = r(x, y);
        if (phase == 1) {  // the same in both orders: phase 0 beside it (0)
          const int c = context_class(up2(x, y));
          cur[0].add(c, v);
          for (Counts* s : swp) s[0].add(c, v);
        } else if (phase == 2) {
          // Today: second, from phases 0 and 1; new: last, also from the phase-3 samples beside it.
          const uint64_t a =
              up2(x, y) + m(x - 1, y - 1) + m(x + 1, y - 1) + m(x - 1, y + 1) + m(x + 1, y + 1);
          cur[1].add(context_class(a), v);
          for (int k = 0; k < kWeightCount; ++k)
            swp[k][2].add(context_class(a + m(x - 1, y) + m(x + 1, y)),
                          v - mean({{x - 1, y}, {x + 1, y}}, kWeights[k]));
        } else {
          // Today: last, the mean of its four neighbours (floor((2 S + n) / (2 n))); new: second, from
          // phase 1 above and below.
          const uint64_t a = up2(x, y) + m(x - 1, y - 1) + m(x + 1, y - 1) + m(x - 1, y + 1) +
                             m(x + 1, y + 1) + m(x, y - 1) + m(x, y + 1);
          int64_t s = 0, n = 0;
          for (auto [xx, yy] : {std::pair{x - 1, y}, {x, y - 1}, {x + 1, y}, {x, y + 1}})
            if (in(xx, yy)) s += r(xx, yy), ++n;
          const int64_t p = n ? int64_t(std::floor(double(2 * s + n) / double(2 * n))) : 0;
          cur[2].add(context_class(a + m(x - 1, y) + m(x + 1, y)), v - p);
          for (int k = 0; k < kWeightCount; ++k)
            swp[k][1].add(context_class(a), v - mean({{x, y - 1}, {x, y + 1}}, kWeights[k]));
        }
      }
  };
  for (int64_t ty = 0; ty < L.h; ty += tile)
    for (int64_t tx = 0; tx < L.w; tx += tile) code(tx, ty);
  LevelBits b;
  for (int p = 0; p < 3; ++p) {
    b.current += cur[p].bits();
    for (int k = 0; k < kWeightCount; ++k) b.swapped[k] += swp[k][p].bits();
  }
  b.n = double(L.w) * double(L.h);
  return b;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: phase_order DEM [TILE]\n");
    return 2;
  }
  const Heightmap map = read_heightmap(argv[1]);
  const int tile = argc > 2 ? std::atoi(argv[2]) : 32;
  std::vector<int32_t> fine(map.values.size());
  for (size_t i = 0; i < fine.size(); ++i) fine[i] = int32_t(std::lround(map.values[i]));
  GridSize size{map.info.width, map.info.height};
  std::vector<Level> levels;
  while (size.width >= 256 && size.height >= 256) {  // the coarsest keeps >= 128 samples a side
    const GridSize coarse{(size.width + 1) / 2, (size.height + 1) / 2};
    std::vector<int32_t> c(size_t(coarse.width * coarse.height)), u(fine.size());
    for (int64_t y = 0; y < coarse.height; ++y)
      for (int64_t x = 0; x < coarse.width; ++x)
        c[size_t(y * coarse.width + x)] = fine[size_t(2 * y * size.width + 2 * x)];
    upsample(c.data(), size, u.data());
    Level L{size.width, size.height, std::vector<int64_t>(fine.size())};
    for (size_t i = 0; i < fine.size(); ++i) L.r[i] = int64_t(fine[i]) - u[i];
    levels.push_back(std::move(L));
    fine = std::move(c);
    size = coarse;
  }
  std::vector<LevelBits> bits;
  for (const Level& L : levels) bits.push_back(measure(L, tile));
  for (int k = 0; k < kWeightCount; ++k) {
    const double w = kWeights[k];
    double cur = 0, swp = 0;
    for (size_t l = 0; l < levels.size(); ++l) {
      const LevelBits& b = bits[l];
      cur += b.current, swp += b.swapped[k];
      std::printf("w %.2f level %lldx%lld: bits/sample today %.4f, order 1-3-2 %.4f (%.4f)\n", w,
                  (long long)levels[l].w, (long long)levels[l].h, b.current / b.n, b.swapped[k] / b.n,
                  b.swapped[k] / b.current);
    }
    std::printf("w %.2f all residual levels: today %.0f bytes, order 1-3-2 %.0f bytes (%.4f)\n", w, cur / 8,
                swp / 8, swp / cur);
  }
  return 0;
}
