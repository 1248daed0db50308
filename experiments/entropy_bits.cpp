// Prototype (built as experiments/entropy_bits, not installed): bits of a static-table context coder for
// libcodec's tile coefficients against the real RLGR stream (codec::encode), on one SRTM .hgt (1201 x 1201)
// at one step and tile size. Same transform, band steps and reconstruction as libcodec; the levels are
// quantised with a dead-zone offset per context class (fixed 3/8 by default), so the comparison is
// made at equal rms: the prototype's step is bisected until its rms matches RLGR's.
// Model: every coefficient is one token of the hybrid-integer alphabet (m < 16: m; else 16 + 2(n - 4)
// + the bit below the leading one, n = floor(log2 m), n - 1 raw bits) plus a raw sign bit (LP/HP);
// DC: the MED residual, zig-zag mapped, one context. LP/HP: context (position, class of
// |left| + |top| + (sum of the same block's earlier positions) / 2), 30 x 10 contexts, histograms
// normalised to 2^12 and clustered greedily with an estimated table cost (8 bits + 9 per used token),
// i.e. the ideal cost of a static rANS coder with tables stored once per stream. Per tile: the index
// entry (5.5 bytes, both coders) and PER_TILE_BITS (default 36: one 32-bit rANS state + padding).
// Build: cmake --build build --target entropy_bits
// Run:   [PER_TILE_BITS=N] build/experiments/entropy_bits DEM.hgt STEP TILE [CONTEXT [OFFSET_QUIET
// OFFSET_BUSY [RAMP]]]
//        CONTEXT 0: l + t + acc/2 (default), 1: l + t, 2: acc, 3: l + t + acc/2 rounded; the dead-zone
//        offset goes linearly from OFFSET_QUIET (class 0) to OFFSET_BUSY (class >= RAMP, default 4).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "codec/codec.h"
#include "codec/internal/lapped_transform.h"
#include "codec/internal/quantizer.h"
#include "token_model.h"

using namespace codec::detail;
using namespace experiments;

namespace {
int variant = 0;
int kRamp = 4;

int ctx_class(uint32_t a) {
  static const uint32_t kEdges[kClasses - 1] = {1, 2, 3, 4, 6, 9, 14, 22, 36};
  int c = 0;
  while (c < kClasses - 1 && a >= kEdges[c]) ++c;
  return c;
}

struct Stats {
  // contexts: 0 = DC, 1 + g * kClasses + c for g = 0..29 (LP positions then HP positions)
  std::vector<std::vector<uint64_t>> hist =
      std::vector<std::vector<uint64_t>>(1 + 30 * kClasses, std::vector<uint64_t>(kTokens));
  double raw = 0;  // raw bits + sign bits
  void add(int ctx, uint32_t m, bool with_sign) {
    int rb;
    const int t = token_of(m, &rb);
    ++hist[ctx][t];
    raw += rb + (with_sign && m ? 1 : 0);
  }
};

// Bits of the clustered tables: data at 12-bit precision plus the tables.
double clustered_bits(const std::vector<std::vector<uint64_t>>& hist, int* clusters_out) {
  std::vector<std::vector<uint64_t>> tables;
  double total = 0;
  cluster(hist, 12, tables, &total);
  for (const auto& t : tables) total += coded_bits(t, 12);
  *clusters_out = int(tables.size());
  return total;
}

bool lossy_ref(double step) { return std::lround(step * 256) > 256; }
}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) return 1;
  const double step = atof(argv[2]);
  const int T = atoi(argv[3]);
  if (argc > 4) variant = atoi(argv[4]);
  if (argc > 7) kRamp = atoi(argv[7]);
  const double dz_lo = argc > 5 ? atof(argv[5]) : 0.375, dz_hi = argc > 6 ? atof(argv[6]) : 0.375;
  const int W = 1201, H = 1201;
  std::vector<int32_t> src;
  if (!read_srtm3(argv[1], src)) return 1;

  // Reference: the real codec (RLGR).
  codec::Scratch scratch;
  std::vector<uint8_t> stream;
  std::vector<int32_t> recon;
  const size_t written = encode_rlgr(src, W, H, step, T, stream, recon, scratch);
  double se = 0;
  for (size_t i = 0; i < src.size(); ++i) se += double(src[i] - recon[i]) * (src[i] - recon[i]);
  const double rlgr_bits = 8.0 * double(written), rlgr_rms = std::sqrt(se / double(src.size()));

  const double n = double(W) * H;
  const double header = 8.0 * 56;
  // Per tile, both coders: the index entry (estimated 5.5 bytes). The new coder adds a 32-bit rANS
  // state flush per lane (1 lane counted) and the byte padding (~4 bits).
  const double index_bits = 8.0 * 5.5;
  const double per_tile = getenv("PER_TILE_BITS") ? atof(getenv("PER_TILE_BITS")) : 32 + 4;
  int clusters = 0;
  double raw_bits = 0, tiles_n = 0;
  const auto run = [&](double new_step, double* rms) {
    const uint32_t step_q8 = uint32_t(std::lround(new_step * 256));
    const bool lossy = step_q8 > 256;
    const int F = lossy ? 4 : 0;
    const BandSteps steps = lossy ? band_steps_for(step_q8, F) : unit_band_steps();
    Stats st;
    double se2 = 0;
    size_t tiles = 0;
    std::vector<int32_t> tile, lev;
    for (int ty = 0; ty < H; ty += T)
      for (int tx = 0; tx < W; tx += T) {
        ++tiles;
        const int w = std::min(T, W - tx), h = std::min(T, H - ty), pw = (w + 15) & ~15, ph = (h + 15) & ~15;
        tile.assign(size_t(pw) * ph, 0);
        lev.assign(size_t(pw) * ph, 0);
        for (int y = 0; y < ph; ++y)
          for (int x = 0; x < pw; ++x)
            tile[size_t(y) * pw + x] =
                int32_t(uint32_t(src[size_t(ty + std::min(y, h - 1)) * W + tx + std::min(x, w - 1)]) << F);
        forward_lapped(tile.data(), pw, ph, lossy);
        const int mbx = pw / 16, mby = ph / 16;
        // DC
        for (int my = 0; my < mby; ++my)
          for (int mx = 0; mx < mbx; ++mx) {
            const size_t o0 = size_t(my) * 16 * pw + mx * 16;
            lev[o0] = quantize(tile[o0], 256.0 / steps.q8[0]);
          }
        for (int my = 0; my < mby; ++my)
          for (int mx = 0; mx < mbx; ++mx) {
            const int64_t p = dc_prediction(lev.data(), pw, mx, my);
            const int64_t r = int64_t(lev[size_t(my) * 16 * pw + size_t(mx) * 16]) - p;
            st.add(0, uint32_t(r >= 0 ? 2 * r : -2 * r - 1), false);
          }
        // LP then HP, position-major
        std::vector<uint32_t> acc_mb(size_t(mbx) * mby, 0), acc_blk(size_t(pw / 4) * (ph / 4), 0);
        for (int group = 0; group < 2; ++group)
          for (int s = 0; s < 15; ++s) {
            const Pos pos = kScan[s];
            const int band = group == 0 ? lp_band(pos.v * 4 + pos.u) : hp_band(pos.v * 4 + pos.u);
            const double inv = 256.0 / steps.q8[band];
            const int stride = group == 0 ? 16 : 4;
            const auto code = [&](size_t off, int bx, int by, uint32_t& acc) {
              const uint32_t l = bx > 0 ? uint32_t(std::abs(lev[off - stride])) : 0;
              const uint32_t t = by > 0 ? uint32_t(std::abs(lev[off - size_t(stride) * pw])) : 0;
              uint32_t a;
              if (variant == 0)
                a = l + t + acc / 2;
              else if (variant == 1)
                a = l + t;
              else if (variant == 2)
                a = acc;
              else
                a = (2 * (l + t) + acc + 1) / 2;
              const int cls = ctx_class(a);
              const double off_q = dz_lo + (dz_hi - dz_lo) * double(std::min(cls, kRamp)) / kRamp;
              const int32_t c = tile[off];
              const double mag = double(c < 0 ? -int64_t(c) : c) * inv + (lossy ? off_q : 0.375);
              const int32_t q = int32_t(mag);
              lev[off] = c < 0 ? -q : q;
              st.add(1 + (group * 15 + s) * kClasses + cls, uint32_t(q), true);
              acc += uint32_t(q);
            };
            for (int my = 0; my < mby; ++my)
              for (int mx = 0; mx < mbx; ++mx) {
                if (group == 0) {
                  code(size_t(16 * my + 4 * pos.v) * pw + 16 * mx + 4 * pos.u, mx, my,
                       acc_mb[size_t(my) * mbx + mx]);
                } else {
                  for (int by = 0; by < 4; ++by)
                    for (int bx = 0; bx < 4; ++bx) {
                      const int gx = mx * 4 + bx, gy = my * 4 + by;
                      code(size_t(4 * gy + pos.v) * pw + 4 * gx + pos.u, gx, gy,
                           acc_blk[size_t(gy) * (pw / 4) + gx]);
                    }
                }
              }
          }
        // Reconstruction
        for (int y = 0; y < ph; ++y)
          for (int x = 0; x < pw; ++x) {
            const int band = band_at(x, y);
            tile[size_t(y) * pw + x] = int32_t(dequantize(lev[size_t(y) * pw + x], steps.q8[band]));
          }
        inverse_lapped(tile.data(), pw, ph, lossy);
        for (int y = 0; y < h; ++y)
          for (int x = 0; x < w; ++x) {
            const int32_t r = F ? int32_t(uint32_t(tile[size_t(y) * pw + x]) + (1u << (F - 1))) >> F
                                : tile[size_t(y) * pw + x];
            const double d = double(src[size_t(ty + y) * W + tx + x] - r);
            se2 += d * d;
          }
      }

    const double model = clustered_bits(st.hist, &clusters);
    raw_bits = st.raw;
    tiles_n = double(tiles);
    *rms = std::sqrt(se2 / n);
    return model + st.raw + double(tiles) * (per_tile + index_bits) + header;
  };
  double rms_same = 0;
  const double bits_same = run(step, &rms_same);
  // Equal rms: bisection on the new coder's step (rms grows with the step).
  double lo = step * 0.7, hi = step * 1.4, bits_eq = 0, rms_eq = 0;
  for (int it = 0; it < (lossy_ref(step) ? 14 : 0); ++it) {
    const double mid = 0.5 * (lo + hi);
    bits_eq = run(mid, &rms_eq);
    (rms_eq < rlgr_rms ? lo : hi) = mid;
  }
  if (!lossy_ref(step)) {
    bits_eq = bits_same;
    rms_eq = rms_same;
  }
  const double rlgr_payload = rlgr_bits - header - tiles_n * index_bits;
  std::printf(
      "%s step %.2f tile %d: RLGR %.4f b/s rms %.3f | same step %.4f rms %.3f | equal rms %.4f b/s (%+.2f%% "
      "of the stream, %+.2f%% payload; %d tables; raw %.3f b/s)\n",
      argv[1], step, T, rlgr_bits / n, rlgr_rms, bits_same / n, rms_same, bits_eq / n,
      100.0 * (bits_eq / rlgr_bits - 1),
      100.0 * ((bits_eq - header - tiles_n * index_bits) / rlgr_payload - 1), clusters, raw_bits / n);
}
