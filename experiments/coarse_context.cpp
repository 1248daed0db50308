// Prototype (built as experiments/coarse_context, not installed): would a context taken from the coarser
// level, which the decoder holds before it decodes level l, predict the magnitude of level l's quantised
// coefficients well enough to save bits? Format unchanged: this program only counts ideal code lengths.
//
// The pyramid is built as pyramid-build builds an rms or step target with the wavelet D (the library's
// builder, DownsampleFilter::wavelet(), PtcResidualCoder with the given finest step and coarse step
// ratio, tile 32, its default bands; levels coded by libcodec format 5: per tile the residual lifting
// transform or the lapped transform, RLGR). The coded levels are then read back out of every band's
// real stream (read_header / read_tile_index, then each tile payload parsed with libcodec's own
// gamma_decode and rlgr_decode and its start states), so the coefficients are exactly the ones RLGR
// coded, dead zone and per-tile transform choice included (building and parsing: level_streams.h,
// shared with experiments/rlgr_start). Each tile is checked by dequantising and inverse-transforming
// the parsed levels: the result must equal the builder's reconstruction
// T^_l - U(T^_{l-1}) ("check" in the output counts the samples that differ: 0 expected).
//
// Every coefficient of level l >= 1 (the coarsest level, coded as values, is left as it is) gets:
//  * its group: residual transform LL, HL, LH, HH; lapped DC (MED residual), LP, HP;
//  * a neighbour class of |left| + |top| (already coded levels of the same band / position in the tile,
//    0 outside it): min(4, bit_width), 5 classes;
//  * two coarse classes from the reconstructed coarser level T^_{l-1} (coarse grid, where coefficient
//    (i, j) of a residual-transform band of the tile at (tx, ty) sits at coarse sample
//    (tx / 2 + i, ty / 2 + j); a lapped block or macroblock at the mean over its footprint), both as a
//    box mean over the (2 BOX + 1)^2 coarse samples around it (BOX=1 by default):
//      curv = |c(x-1, y) - 2 c(x, y) + c(x+1, y)| + |c(x, y-1) - 2 c(x, y) + c(x, y+1)| of T^_{l-1}
//             (U's point reflection at the edges: 0 across them),
//      par  = |R^_{l-1}| = |T^_{l-1} - U(T^_{l-2})|, the decoded coarser residual (level 1: none, class 0);
//    each quantised relative to the level's step S_l as min(5, bit_width(floor(4 a / S_l))), 6 classes
//    (a < S/4, < S/2, < S, < 2S, < 4S, >= 4S).
// Context variants (always within the group): none, curv, par, curv x par, nb, nb x curv, nb x par,
// nb x curv x par. Four model families, each with and without the coarse classes, so the comparison
// is within one family:
//  A  adaptive zero-inflated geometric ("Laplacian") per context, reset per tile as RLGR is: P(0) from
//     KT counts of zeros, |q| - 1 of non-zeros geometric with the running mean (prior 1), counts halved
//     at 128 (RLGR-like fast adaptation); sign 1 bit.
//  A2 the same, but each context starts every tile from the level's statistics of that context (16 and
//     8 pseudo-counts of its share of zeros and its mean), paying 16 bits per used context and level:
//     the tile-adaptive model that context classes can help without a learning cost per tile.
//  B  adaptive histogram of hybrid-integer tokens (experiments/token_model.h's token_of: m < 16 is m,
//     then exponent and the bit below the leading one, the rest raw) per context, KT (alpha 1/2, 40
//     tokens), carried over the whole level (one model per level: not tile-independent, what a
//     level-wide adaptive model could reach); raw bits and sign 1 bit.
//  C  static: the empirical conditional entropy of the tokens per context over the level (two-pass,
//     no table cost: a bound on what the context's information is worth), raw bits and sign.
// The result per variant is the change of the whole pyramid's coded bits, (bits(variant) -
// bits(none)) / (8 * the real pyramid's bytes), i.e. the saving of the model moved onto the real file;
// "none vs RLGR" is each model without context against RLGR's real payload of the same levels, also in
// whole-pyramid terms (no flush, table or tile-index cost on the model's side). RESULT line: DEM, step,
// ratio, the four "none vs RLGR" figures, then per variant (curv .. nb x curv x par) A/A2/B/C.
//
// Build: cd build && make -j2 coarse_context
// Run:   build/experiments/coarse_context DEM STEP [RATIO [TILE]]
//        STEP and RATIO: the finest step in level units and the coarse step ratio that
//        `pyramid-build DEM -o X.pyr --rms T --downsample wavelet --json -` reports (step_metres,
//        coarse_step_ratio; SRTM units are metres), STEP 1 RATIO 1 = lossless. Environment: BOX=r (box
//        radius of the coarse activities, default 1), LEVELS=1 (per-level lines).
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <vector>

#include "codec/internal/lapped_transform.h"
#include "codec/internal/lifting_transform.h"
#include "codec/internal/quantizer.h"
#include "codec/internal/tile_coder.h"
#include "level_streams.h"
#include "pyramid/upsample.h"
#include "token_model.h"

using namespace terrain;
using namespace codec::detail;
using experiments::kGroupDc;
using experiments::kGroupHp;
using experiments::kGroupLp;
using experiments::kGroups;

namespace {

constexpr int kNb = 5, kCoarse = 6;
constexpr int kVariants = 8;
const char* const kVariantName[kVariants] = {"none",    "curv",      "par",      "curv x par",
                                             "nb only", "nb x curv", "nb x par", "nb x curv x par"};
constexpr int kContexts = kNb * kCoarse * kCoarse;  // the largest variant
constexpr int kTokenCount = 40;

int context_of(int variant, int nb, int cc, int pc) {
  switch (variant) {
    case 0:
      return 0;
    case 1:
      return cc;
    case 2:
      return pc;
    case 3:
      return cc * kCoarse + pc;
    case 4:
      return nb;
    case 5:
      return nb * kCoarse + cc;
    case 6:
      return nb * kCoarse + pc;
    default:
      return (nb * kCoarse + cc) * kCoarse + pc;
  }
}

int nb_class(uint32_t a) { return std::min(kNb - 1, int(std::bit_width(a))); }
int coarse_class(double a, double step) {
  return std::min(kCoarse - 1, int(std::bit_width(uint64_t(std::max(0.0, 4 * a / step)))));
}

// A coarse-grid activity map with a summed-area table for box means.
struct Activity {
  int64_t w = 0, h = 0;
  std::vector<double> sat;  // (w + 1) x (h + 1)
  void build(const std::vector<double>& a, int64_t width, int64_t height) {
    w = width, h = height;
    sat.assign(size_t((w + 1) * (h + 1)), 0);
    for (int64_t y = 0; y < h; ++y)
      for (int64_t x = 0; x < w; ++x)
        sat[size_t((y + 1) * (w + 1) + x + 1)] = a[size_t(y * w + x)] + sat[size_t(y * (w + 1) + x + 1)] +
                                                 sat[size_t((y + 1) * (w + 1) + x)] -
                                                 sat[size_t(y * (w + 1) + x)];
  }
  // Mean over coarse samples [x0, x1) x [y0, y1), clamped to the grid.
  double mean(int64_t x0, int64_t y0, int64_t x1, int64_t y1) const {
    x0 = std::clamp<int64_t>(x0, 0, w - 1), y0 = std::clamp<int64_t>(y0, 0, h - 1);
    x1 = std::clamp<int64_t>(x1, x0 + 1, w), y1 = std::clamp<int64_t>(y1, y0 + 1, h);
    const double s = sat[size_t(y1 * (w + 1) + x1)] - sat[size_t(y0 * (w + 1) + x1)] -
                     sat[size_t(y1 * (w + 1) + x0)] + sat[size_t(y0 * (w + 1) + x0)];
    return s / double((x1 - x0) * (y1 - y0));
  }
};

// Model A: adaptive zero-inflated geometric, reset per tile (lazily, by generation).
struct LaplaceState {
  uint32_t generation = 0;
  double n = 0, zeros = 0, k = 0, sum = 0;
};
// A context's statistics over a level (model A2's starting state).
struct Prior {
  double n = 0, zeros = 0, k = 0, sum = 0;
};
constexpr double kPriorZeros = 16, kPriorNonzeros = 8;  // pseudo-counts of the prior
constexpr double kPriorBits = 16;                       // its cost per used context and level
double laplace_bits(LaplaceState& s, uint32_t generation, uint32_t m, const Prior* prior) {
  if (s.generation != generation) {
    s = LaplaceState{generation, 0, 0, 0, 0};
    if (prior && prior->n > 0) {
      s.n = kPriorZeros, s.zeros = kPriorZeros * prior->zeros / prior->n;
      if (prior->k > 0) s.k = kPriorNonzeros, s.sum = kPriorNonzeros * prior->sum / prior->k;
    }
  }
  const double p0 = (s.zeros + 0.5) / (s.n + 1);
  double bits;
  if (m == 0) {
    bits = -std::log2(p0);
  } else {
    const double mu = (s.sum + 1) / (s.k + 1), theta = mu / (1 + mu);
    bits = -std::log2(1 - p0) + 1 - std::log2(1 - theta) - double(m - 1) * std::log2(theta);
  }
  s.n += 1;
  if (m == 0)
    s.zeros += 1;
  else
    s.k += 1, s.sum += double(m - 1);
  if (s.n >= 128) s.n /= 2, s.zeros /= 2;
  if (s.k >= 128) s.k /= 2, s.sum /= 2;
  return bits;
}

// Model B: adaptive KT histogram of tokens over a level.
struct Histogram {
  std::array<uint32_t, kTokenCount> c{};
  uint32_t n = 0;
};
int token_with_raw(uint32_t m, int* raw) {
  int t = experiments::token_of(m, raw);
  if (t >= kTokenCount) {  // magnitudes >= 2^16: the last token, the rest raw (never on these data)
    *raw += t - (kTokenCount - 1);
    t = kTokenCount - 1;
  }
  return t;
}

struct VariantStats {
  double a = 0, a2 = 0, b = 0;                            // models A, A2 and B
  std::vector<std::array<uint64_t, kTokenCount>> counts;  // model C: [group * kContexts + ctx]
  double raw = 0;  // raw token bits + signs (the same for every variant)
  double c = 0;    // model C's bits (levels summed)
};

struct Coefficient {
  uint8_t group, nb, cc, pc;
  int32_t q;
};

double entropy_bits(const std::vector<std::array<uint64_t, kTokenCount>>& counts) {
  double bits = 0;
  for (const auto& h : counts) {
    uint64_t n = 0;
    for (auto c : h) n += c;
    for (auto c : h)
      if (c) bits -= double(c) * std::log2(double(c) / double(n));
  }
  return bits;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: coarse_context DEM STEP [RATIO [TILE]]\n");
    return 2;
  }
  const Heightmap map = read_heightmap(argv[1]);
  const PtcCoderOptions co = experiments::coder_options(argc, argv);
  const int box = std::getenv("BOX") ? std::atoi(std::getenv("BOX")) : 1;
  const bool per_level = std::getenv("LEVELS") != nullptr;

  MemoryPyramid mem;
  mem.keep_reconstruction = true;
  const BuildResult built = experiments::build_wavelet_pyramid(map, co, mem);
  const uint64_t total_bytes = mem.total_bytes();
  const int levels = int(mem.header.levels.size());
  const double finest_n = double(map.info.width) * double(map.info.height);

  std::vector<VariantStats> stats(kVariants);
  for (auto& s : stats) s.counts.assign(size_t(kGroups * kContexts), {});
  double rlgr_bits = 0;  // payload bits of the parsed tiles (levels >= 1)
  uint64_t lifting_tiles = 0, lapped_tiles = 0, mismatches = 0;
  uint64_t level0_bytes = 0;
  for (const auto& b : mem.bands[0]) level0_bytes += b.bytes.size();

  codec::Scratch scratch;
  std::vector<int32_t> lift_scratch;
  uint32_t generation = 0;
  std::vector<LaplaceState> laplace(size_t(kVariants * kGroups * kContexts)), laplace2(laplace.size());

  for (int l = 1; l < levels; ++l) {
    const GridSize fine = mem.header.levels[size_t(l)], coarse = mem.header.levels[size_t(l - 1)];
    const std::vector<int32_t>& tc = mem.recon[size_t(l - 1)];
    // R^_l = T^_l - U(T^_{l-1}) for the check; R^_{l-1} for the parent activity.
    std::vector<int32_t> up(size_t(fine.width * fine.height));
    upsample(tc.data(), fine, up.data());
    std::vector<double> curv(size_t(coarse.width * coarse.height)), par(curv.size(), 0.0);
    const auto c = [&](int64_t x, int64_t y) { return double(tc[size_t(y * coarse.width + x)]); };
    for (int64_t y = 0; y < coarse.height; ++y)
      for (int64_t x = 0; x < coarse.width; ++x) {
        double a = 0;
        if (x > 0 && x + 1 < coarse.width) a += std::fabs(c(x - 1, y) - 2 * c(x, y) + c(x + 1, y));
        if (y > 0 && y + 1 < coarse.height) a += std::fabs(c(x, y - 1) - 2 * c(x, y) + c(x, y + 1));
        curv[size_t(y * coarse.width + x)] = a;
      }
    if (l >= 2) {
      std::vector<int32_t> up2(size_t(coarse.width * coarse.height));
      upsample(mem.recon[size_t(l - 2)].data(), coarse, up2.data());
      for (size_t i = 0; i < par.size(); ++i) par[i] = std::fabs(double(tc[i]) - double(up2[i]));
    }
    Activity curv_map, par_map;
    curv_map.build(curv, coarse.width, coarse.height);
    par_map.build(par, coarse.width, coarse.height);

    std::vector<VariantStats> level_stats(kVariants);
    for (auto& s : level_stats) s.counts.assign(size_t(kGroups * kContexts), {});
    std::vector<Histogram> hist(size_t(kVariants * kGroups * kContexts));
    std::vector<std::vector<Coefficient>> level_tiles;
    double level_rlgr = 0;

    const bool parsed = experiments::for_each_tile(
        mem, l,
        [&](const codec::HeaderInfo& hi, const codec::TileEntry& e, const experiments::LevelTile& pt) {
          const uint32_t step_q8 = uint32_t(std::lround(hi.step * 256));
          const int F = hi.fraction_bits;
          const double step = hi.step;
          const BandSteps lift_steps = stream_band_steps(step_q8, F, true);
          const BandSteps lap_steps = stream_band_steps(step_q8, F, false);
          const int tx = pt.tx, w = pt.w, h = pt.h;
          const int64_t fy0 = pt.y0;  // the tile's first row in the level
          level_rlgr += 8.0 * e.size;
          std::vector<Coefficient> coefs;
          std::vector<int32_t> recon;  // the tile's decoded residual (check)
          const auto coarse_classes = [&](int64_t x0, int64_t y0, int64_t x1, int64_t y1, Coefficient& k) {
            k.cc = uint8_t(coarse_class(curv_map.mean(x0 - box, y0 - box, x1 + box, y1 + box), step));
            k.pc = uint8_t(l >= 2 ? coarse_class(par_map.mean(x0 - box, y0 - box, x1 + box, y1 + box), step)
                                  : 0);
          };
          if (pt.lifting) {
            ++lifting_tiles;
            std::vector<int32_t> tile(size_t(w) * h, 0);
            for (const experiments::TileBand& b : pt.bands) {
              const int k = b.group, x0 = b.x0, y0 = b.y0, bw = b.w, bh = b.h;
              const std::vector<int32_t>& v = b.values;
              for (int j = 0; j < bh; ++j)
                for (int i = 0; i < bw; ++i) {
                  const int32_t q = v[size_t(j) * bw + i];
                  Coefficient cf{uint8_t(k), 0, 0, 0, q};
                  const uint32_t left = i > 0 ? uint32_t(std::abs(v[size_t(j) * bw + i - 1])) : 0;
                  const uint32_t top = j > 0 ? uint32_t(std::abs(v[size_t(j - 1) * bw + i])) : 0;
                  cf.nb = uint8_t(nb_class(left + top));
                  const int64_t cx = tx / 2 + i, cy = fy0 / 2 + j;
                  coarse_classes(cx, cy, cx + 1, cy + 1, cf);
                  coefs.push_back(cf);
                  tile[size_t(y0 + j) * w + x0 + i] = int32_t(dequantize(q, lift_steps.q8[k]));
                }
            }
            lift_scratch.resize(lifting_scratch_size(w, h));
            inverse_lifting(tile.data(), w, h, lift_scratch.data());
            recon = std::move(tile);
          } else {
            ++lapped_tiles;
            const int pw = pt.pw, ph = pt.ph, mbx = pt.mbx, mby = pt.mby;
            // The parsed DC residuals after the first, LP and HP; dc[0] the gamma-coded first DC.
            std::vector<int32_t> dc{pt.dc0};
            dc.insert(dc.end(), pt.bands[0].values.begin(), pt.bands[0].values.end());
            const std::vector<int32_t>&lp = pt.bands[1].values, &hp = pt.bands[2].values;
            std::vector<int32_t> tile(size_t(pw) * ph, 0);
            // DC: MED residuals in macroblock raster order.
            for (int my = 0, i = 0; my < mby; ++my)
              for (int mx = 0; mx < mbx; ++mx, ++i) {
                Coefficient cf{kGroupDc, 0, 0, 0, dc[size_t(i)]};
                const uint32_t left = mx > 0 ? uint32_t(std::abs(dc[size_t(i - 1)])) : 0;
                const uint32_t top = my > 0 ? uint32_t(std::abs(dc[size_t(i - mbx)])) : 0;
                cf.nb = uint8_t(nb_class(left + top));
                coarse_classes(tx / 2 + 8 * mx, fy0 / 2 + 8 * my, tx / 2 + 8 * mx + 8, fy0 / 2 + 8 * my + 8,
                               cf);
                coefs.push_back(cf);
                tile[size_t(my) * 16 * pw + size_t(mx) * 16] =
                    int32_t(experiments::dc_prediction(tile.data(), pw, mx, my) + dc[size_t(i)]);
              }
            for (int my = 0; my < mby; ++my)
              for (int mx = 0; mx < mbx; ++mx) {
                int32_t& d = tile[size_t(my) * 16 * pw + size_t(mx) * 16];
                d = int32_t(dequantize(d, lap_steps.q8[0]));
              }
            // LP: per scan position, macroblocks in raster order.
            size_t n = 0;
            for (int s = 0; s < 15; ++s) {
              const experiments::Pos pos = experiments::kScan[s];
              for (int my = 0; my < mby; ++my)
                for (int mx = 0; mx < mbx; ++mx, ++n) {
                  Coefficient cf{kGroupLp, 0, 0, 0, lp[n]};
                  const uint32_t left = mx > 0 ? uint32_t(std::abs(lp[n - 1])) : 0;
                  const uint32_t top = my > 0 ? uint32_t(std::abs(lp[n - size_t(mbx)])) : 0;
                  cf.nb = uint8_t(nb_class(left + top));
                  coarse_classes(tx / 2 + 8 * mx, fy0 / 2 + 8 * my, tx / 2 + 8 * mx + 8, fy0 / 2 + 8 * my + 8,
                                 cf);
                  coefs.push_back(cf);
                  tile[size_t(16 * my + 4 * pos.v) * pw + 16 * mx + 4 * pos.u] =
                      int32_t(dequantize(lp[n], lap_steps.q8[lp_band(pos.v * 4 + pos.u)]));
                }
            }
            // HP: per scan position, macroblocks in raster order, their 16 blocks in raster order.
            n = 0;
            const int bxn = pw / 4;
            std::vector<int32_t> plane(size_t(bxn) * (ph / 4));
            for (int s = 0; s < 15; ++s) {
              const experiments::Pos pos = experiments::kScan[s];
              for (int my = 0; my < mby; ++my)
                for (int mx = 0; mx < mbx; ++mx)
                  for (int by = 0; by < 4; ++by)
                    for (int bx = 0; bx < 4; ++bx, ++n) {
                      const int gx = 4 * mx + bx, gy = 4 * my + by;
                      Coefficient cf{kGroupHp, 0, 0, 0, hp[n]};
                      // left / top block at this position (coded before it in this order)
                      const uint32_t left = gx > 0 ? uint32_t(std::abs(plane[size_t(gy) * bxn + gx - 1])) : 0;
                      const uint32_t top = gy > 0 ? uint32_t(std::abs(plane[size_t(gy - 1) * bxn + gx])) : 0;
                      plane[size_t(gy) * bxn + gx] = hp[n];
                      cf.nb = uint8_t(nb_class(left + top));
                      coarse_classes(tx / 2 + 2 * gx, fy0 / 2 + 2 * gy, tx / 2 + 2 * gx + 2,
                                     fy0 / 2 + 2 * gy + 2, cf);
                      coefs.push_back(cf);
                      tile[size_t(4 * gy + pos.v) * pw + 4 * gx + pos.u] =
                          int32_t(dequantize(hp[n], lap_steps.q8[hp_band(pos.v * 4 + pos.u)]));
                    }
            }
            inverse_lapped(tile.data(), pw, ph, F > 0);
            recon.assign(size_t(w) * h, 0);
            for (int y = 0; y < h; ++y)
              for (int x = 0; x < w; ++x) recon[size_t(y) * w + x] = tile[size_t(y) * pw + x];
          }
          // Check: the parsed levels reconstruct the builder's residual exactly.
          for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
              const int32_t v = recon[size_t(y) * w + x];
              const int32_t r = F ? int32_t(uint32_t(v) + (1u << (F - 1))) >> F : v;
              const size_t at = size_t((fy0 + y) * fine.width + tx + x);
              if (r != mem.recon[size_t(l)][at] - up[at]) ++mismatches;
            }
          level_tiles.push_back(std::move(coefs));
        });
    if (!parsed) return 1;
    // Model A2's priors: each context's share of zeros and mean |q| - 1 of non-zeros over the level.
    std::vector<Prior> prior(size_t(kVariants * kGroups * kContexts));
    for (const auto& coefs : level_tiles)
      for (const Coefficient& k : coefs)
        for (int v = 0; v < kVariants; ++v) {
          Prior& p = prior[size_t(v) * kGroups * kContexts + size_t(k.group) * kContexts +
                           size_t(context_of(v, k.nb, k.cc, k.pc))];
          const uint32_t m = uint32_t(std::abs(k.q));
          p.n += 1, p.zeros += m == 0, p.k += m != 0, p.sum += m ? double(m - 1) : 0.0;
        }
    for (int v = 0; v < kVariants; ++v)
      for (int i = 0; i < kGroups * kContexts; ++i)
        if (prior[size_t(v * kGroups * kContexts + i)].n > 0) level_stats[size_t(v)].a2 += kPriorBits;
    for (const auto& coefs : level_tiles) {
      ++generation;
      for (const Coefficient& k : coefs) {
        const uint32_t m = uint32_t(std::abs(k.q));
        int raw = 0;
        const int token = token_with_raw(m, &raw);
        const double raw_bits = raw + (m ? 1 : 0);
        for (int v = 0; v < kVariants; ++v) {
          const size_t ctx = size_t(k.group) * kContexts + size_t(context_of(v, k.nb, k.cc, k.pc));
          const size_t at = size_t(v) * kGroups * kContexts + ctx;
          VariantStats& s = level_stats[size_t(v)];
          s.a += laplace_bits(laplace[at], generation, m, nullptr);
          s.a2 += laplace_bits(laplace2[at], generation, m, &prior[at]);
          Histogram& hg = hist[at];
          s.b += -std::log2((hg.c[size_t(token)] + 0.5) / (hg.n + 0.5 * kTokenCount)) + raw_bits;
          ++hg.c[size_t(token)], ++hg.n;
          ++s.counts[ctx][size_t(token)];
          s.raw += raw_bits;
        }
      }
    }
    rlgr_bits += level_rlgr;
    for (int v = 0; v < kVariants; ++v) {
      VariantStats& s = stats[size_t(v)];
      const VariantStats& ls = level_stats[size_t(v)];
      s.a += ls.a, s.a2 += ls.a2, s.b += ls.b;
      const double c_bits = entropy_bits(ls.counts) + ls.raw;
      s.c += c_bits;
    }
    if (per_level) {
      const double n = double(fine.width) * double(fine.height);
      std::printf("level %d %lldx%lld: RLGR %.4f b/s, A none %.4f, A2 none %.4f, B none %.4f, C none %.4f", l,
                  (long long)fine.width, (long long)fine.height, level_rlgr / n, level_stats[0].a / n,
                  level_stats[0].a2 / n, level_stats[0].b / n,
                  (entropy_bits(level_stats[0].counts) + level_stats[0].raw) / n);
      for (int v = 1; v < kVariants; ++v)
        std::printf(" | %s A %+.2f%% A2 %+.2f%% B %+.2f%% C %+.2f%%", kVariantName[v],
                    100 * (level_stats[size_t(v)].a / level_stats[0].a - 1),
                    100 * (level_stats[size_t(v)].a2 / level_stats[0].a2 - 1),
                    100 * (level_stats[size_t(v)].b / level_stats[0].b - 1),
                    100 * ((entropy_bits(level_stats[size_t(v)].counts) + level_stats[size_t(v)].raw) /
                               (entropy_bits(level_stats[0].counts) + level_stats[0].raw) -
                           1));
      std::printf("\n");
    }
  }

  const double total_bits = 8.0 * double(total_bytes);
  std::printf(
      "%s step %.4f ratio %.3g tile %u box %d: pyramid %llu bytes (%.4f b/s, level 0 %llu), finest rms %.4f, "
      "%d levels; tiles lifting %llu lapped %llu; check %llu samples differ\n",
      argv[1], co.step, co.coarse_step_ratio, co.tile_size, box, (unsigned long long)total_bytes,
      total_bits / finest_n, (unsigned long long)level0_bytes, built.levels.back().error_rms, levels,
      (unsigned long long)lifting_tiles, (unsigned long long)lapped_tiles, (unsigned long long)mismatches);
  std::printf(
      "levels >= 1: RLGR payload %.0f bits; models without context: A %.0f (%.3fx RLGR), A2 %.0f (%.3fx), "
      "B %.0f (%.3fx), C %.0f (%.3fx)\n",
      rlgr_bits, stats[0].a, stats[0].a / rlgr_bits, stats[0].a2, stats[0].a2 / rlgr_bits, stats[0].b,
      stats[0].b / rlgr_bits, stats[0].c, stats[0].c / rlgr_bits);
  std::printf("%-16s %9s %9s %9s %9s   (whole-pyramid change: (bits - bits none) / pyramid bits)\n",
              "context", "A", "A2", "B", "C");
  const auto change = [&](int v, double VariantStats::*m) {
    return 100 * (stats[size_t(v)].*m - stats[0].*m) / total_bits;
  };
  for (int v = 0; v < kVariants; ++v)
    std::printf("%-16s %+8.2f%% %+8.2f%% %+8.2f%% %+8.2f%%\n", kVariantName[v], change(v, &VariantStats::a),
                change(v, &VariantStats::a2), change(v, &VariantStats::b), change(v, &VariantStats::c));
  // Each model without context in place of RLGR on levels >= 1 (the same levels; no flush or table cost).
  const auto against_rlgr = [&](double VariantStats::*m) {
    return 100 * (stats[0].*m - rlgr_bits) / total_bits;
  };
  std::printf("%-16s %+8.2f%% %+8.2f%% %+8.2f%% %+8.2f%%\n", "none vs RLGR", against_rlgr(&VariantStats::a),
              against_rlgr(&VariantStats::a2), against_rlgr(&VariantStats::b),
              against_rlgr(&VariantStats::c));
  std::printf("RESULT %s %.4f %.3g %.2f/%.2f/%.2f/%.2f", argv[1], co.step, co.coarse_step_ratio,
              against_rlgr(&VariantStats::a), against_rlgr(&VariantStats::a2), against_rlgr(&VariantStats::b),
              against_rlgr(&VariantStats::c));
  for (int v = 1; v < kVariants; ++v)
    std::printf(" %.2f/%.2f/%.2f/%.2f", change(v, &VariantStats::a), change(v, &VariantStats::a2),
                change(v, &VariantStats::b), change(v, &VariantStats::c));
  std::printf("\n");
  return 0;
}
