// Prototype (built as experiments/rans_decode, not installed): how fast a static-table entropy code
// decodes libcodec's tile coefficients, against the real RLGR decoder on the same image. The open
// question left by entropy_bits.cpp (which measured the bits of such a coder, not its speed).
// Coefficients: libcodec's transform, band steps and a fixed 3/8 rounding offset (entropy_bits'
// model): DC as the MED residual, LP/HP position-major, every value one hybrid-integer token
// (m < 16: m; else 16 + 2 (n - 4) + the bit below the leading one, n - 1 raw bits) and a raw sign.
// Contexts: DC one; LP/HP (position, class of |left| + |top| + in-block sum / 2), 30 x 10,
// histograms clustered greedily (entropy_bits' cost model), one table of 2^11 slots per cluster.
// Coding: per tile, two interleaved 32-bit rANS lanes (16-bit renormalisation) for the tokens, the raw
// bits in a separate forward bit stream. Decoding is timed over all tiles (the levels written back in
// place, as the real decoder's sink does before dequantisation), and checked against the encoder's.
// Reported: bits/sample (tokens + raw + tables, per-tile flush of 2 x 32 bits), entropy decode Ms/s
// of this coder, and codec::decode (RLGR + dequantisation + inverse transform) Ms/s of the real stream,
// plus the inverse transform + dequantisation alone, so the entropy stages compare.
// Build: cmake --build build --target rans_decode
// Run:   build/experiments/rans_decode DEM.hgt STEP TILE [REPEATS]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#ifndef PROB_BITS
#define PROB_BITS 10
#endif

#include "codec/codec.h"
#include "codec/internal/lapped_transform.h"
#include "codec/internal/quantizer.h"
#include "token_model.h"

using namespace codec::detail;
using namespace experiments;

namespace {

constexpr int kContexts = 1 + 30 * kClasses;
constexpr int kProbBits = PROB_BITS;
constexpr uint32_t kProbScale = 1u << kProbBits;
constexpr uint32_t kRansL = 1u << 16;

// Class of a context sum: a table for small sums (the common case), a search above.
inline int ctx_class(uint32_t a) {
  static const uint8_t kSmall[36] = {0, 1, 2, 3, 4, 4, 5, 5, 5, 6, 6, 6, 6, 6, 7, 7, 7, 7,
                                     7, 7, 7, 7, 8, 8, 8, 8, 8, 8, 8, 8, 8, 8, 8, 8, 8, 8};
  return a < 36 ? kSmall[a] : 9;
}

// One tile's quantised levels (pw x ph, in place of the coefficients) and its size.
struct Tile {
  int w, h, pw, ph;
  std::vector<int32_t> lev;
};

// Visits a tile's coded values in coding order: visit(context, value_as_unsigned, with_sign, offset).
// The context of LP/HP needs the levels already visited, which both sides have (encoder: all; decoder:
// the ones decoded so far, written by visit before the next call reads them).
template <class Visit> void for_values(int32_t* lev, int pw, int ph, Visit&& visit) {
  const int mbx = pw / 16, mby = ph / 16;
  for (int my = 0; my < mby; ++my)
    for (int mx = 0; mx < mbx; ++mx) {
      const int64_t p = dc_prediction(lev, pw, mx, my);
      visit(0, p, size_t(my) * 16 * pw + size_t(mx) * 16, /*dc=*/true);
    }
  uint32_t acc_mb[64 * 64];
  static thread_local std::vector<uint32_t> acc_blk;
  std::fill(acc_mb, acc_mb + mbx * mby, 0u);
  acc_blk.assign(size_t(pw / 4) * (ph / 4), 0u);
  for (int group = 0; group < 2; ++group)
    for (int s = 0; s < 15; ++s) {
      const Pos pos = kScan[s];
      const int stride = group == 0 ? 16 : 4;
      const int base = 1 + (group * 15 + s) * kClasses;
      const auto one = [&](size_t off, int bx, int by, uint32_t& acc) {
        const uint32_t l = bx > 0 ? uint32_t(std::abs(lev[off - size_t(stride)])) : 0;
        const uint32_t t = by > 0 ? uint32_t(std::abs(lev[off - size_t(stride) * pw])) : 0;
        const int ctx = base + ctx_class(l + t + acc / 2);
        acc += uint32_t(visit(ctx, 0, off, false));
      };
      if (group == 0) {
        for (int my = 0; my < mby; ++my)
          for (int mx = 0; mx < mbx; ++mx)
            one(size_t(16 * my + 4 * pos.v) * pw + 16 * mx + 4 * pos.u, mx, my, acc_mb[my * mbx + mx]);
      } else {
        const int bw = pw / 4, bh = ph / 4;
        for (int gy = 0; gy < bh; ++gy)
          for (int gx = 0; gx < bw; ++gx)
            one(size_t(4 * gy + pos.v) * pw + 4 * gx + pos.u, gx, gy, acc_blk[size_t(gy) * bw + gx]);
      }
    }
}

// Frequencies normalised to kProbScale, every used token at least 1.
std::vector<uint32_t> normalise(const std::vector<uint64_t>& h) {
  std::vector<uint32_t> f(kTokens, 0);
  uint64_t total = 0;
  for (auto c : h) total += c;
  if (!total) {
    f[0] = kProbScale;
    return f;
  }
  int64_t sum = 0, biggest = 0;
  for (int t = 0; t < kTokens; ++t)
    if (h[size_t(t)]) {
      f[size_t(t)] = uint32_t(
          std::max<int64_t>(1, std::llround(double(kProbScale) * double(h[size_t(t)]) / double(total))));
      sum += f[size_t(t)];
      if (f[size_t(t)] > f[size_t(biggest)]) biggest = t;
    }
  // Fix the total on the largest entries.
  while (sum != int64_t(kProbScale)) {
    int best = -1;
    for (int t = 0; t < kTokens; ++t)
      if (f[size_t(t)] > 1 && (best < 0 || f[size_t(t)] > f[size_t(best)])) best = t;
    if (sum > int64_t(kProbScale))
      --f[size_t(best)], --sum;
    else
      ++f[size_t(best)], ++sum;
  }
  return f;
}

// slot[]: token (7 bits) | freq (12 bits) << 7 | (slot - start) << 19.
struct Table {
  uint32_t freq[kTokens], start[kTokens];
  uint32_t slot[kProbScale];
};

struct BitWriter {
  std::vector<uint64_t> words;
  uint64_t cur = 0;
  int n = 0;
  void put(uint32_t v, int bits) {
    if (!bits) return;
    cur |= uint64_t(v) << n;
    n += bits;
    if (n >= 64) {
      words.push_back(cur);
      n -= 64;
      cur = n ? uint64_t(v) >> (bits - n) : 0;
    }
  }
  void flush() {
    if (n) words.push_back(cur);
    cur = 0, n = 0;
  }
};

struct CodedTile {
  std::vector<uint16_t> rans;  // forward order for the decoder
  std::vector<uint64_t> raw;
};

}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: rans_decode DEM.hgt STEP TILE [REPEATS]\n");
    return 2;
  }
  const double step = std::atof(argv[2]);
  const int T = std::atoi(argv[3]);
  const int repeats = argc > 4 ? std::atoi(argv[4]) : 5;
  const int W = 1201, H = 1201;
  std::vector<int32_t> src;
  if (!read_srtm3(argv[1], src)) return 2;
  const double samples = double(W) * H;

  // The real codec: stream, decode time.
  codec::Scratch scratch;
  std::vector<uint8_t> stream;
  std::vector<int32_t> recon, out(src.size());
  const size_t written = encode_rlgr(src, W, H, step, T, stream, recon, scratch);
  using clock = std::chrono::steady_clock;
  auto best_of = [&](auto&& fn) {
    double best = 1e30;
    for (int r = 0; r < repeats; ++r) {
      const auto t0 = clock::now();
      fn();
      best = std::min(best, std::chrono::duration<double>(clock::now() - t0).count());
    }
    return best;
  };
  const double t_rlgr = best_of([&] { codec::decode(stream.data(), written, out.data(), W, scratch); });

  // Levels per tile.
  const uint32_t step_q8 = uint32_t(std::lround(step * 256));
  const bool lossy = step_q8 > 256;
  const int F = lossy ? 4 : 0;
  const BandSteps steps = lossy ? band_steps_for(step_q8, F) : unit_band_steps();
  std::vector<Tile> tiles;
  for (int ty = 0; ty < H; ty += T)
    for (int tx = 0; tx < W; tx += T) {
      Tile t;
      t.w = std::min(T, W - tx), t.h = std::min(T, H - ty), t.pw = (t.w + 15) & ~15, t.ph = (t.h + 15) & ~15;
      t.lev.assign(size_t(t.pw) * t.ph, 0);
      for (int y = 0; y < t.ph; ++y)
        for (int x = 0; x < t.pw; ++x)
          t.lev[size_t(y) * t.pw + x] =
              int32_t(uint32_t(src[size_t(ty + std::min(y, t.h - 1)) * W + tx + std::min(x, t.w - 1)]) << F);
      forward_lapped(t.lev.data(), t.pw, t.ph, lossy);
      for (int y = 0; y < t.ph; ++y)
        for (int x = 0; x < t.pw; ++x) {
          const int band = band_at(x, y);
          int32_t& c = t.lev[size_t(y) * t.pw + x];
          c = quantize(c, 256.0 / steps.q8[band]);
        }
      tiles.push_back(std::move(t));
    }

  // Histograms, clusters, tables.
  std::vector<std::vector<uint64_t>> hist(kContexts, std::vector<uint64_t>(kTokens, 0));
  for (Tile& t : tiles)
    for_values(t.lev.data(), t.pw, t.ph, [&](int ctx, int64_t pred, size_t off, bool dc) -> int32_t {
      const int64_t v = t.lev[off];
      const int64_t r = dc ? v - pred : v;
      const uint32_t m = dc ? uint32_t(r >= 0 ? 2 * r : -2 * r - 1) : uint32_t(r < 0 ? -r : r);
      int rb;
      ++hist[size_t(ctx)][size_t(token_of(m, &rb))];
      return dc ? 0 : int32_t(m);
    });
  std::vector<std::vector<uint64_t>> clusters;
  double table_cost = 0;
  const std::vector<int> ctx_table = cluster(hist, kProbBits, clusters, &table_cost);
  std::vector<Table> tables(clusters.size());
  for (size_t k = 0; k < clusters.size(); ++k) {
    const std::vector<uint32_t> fr = normalise(clusters[k]);
    uint32_t start = 0;
    for (int s = 0; s < kTokens; ++s) {
      tables[k].freq[s] = fr[size_t(s)], tables[k].start[s] = start;
      for (uint32_t i = 0; i < fr[size_t(s)]; ++i)
        tables[k].slot[start + i] = uint32_t(s) | (fr[size_t(s)] << 7) | (i << 19);
      start += fr[size_t(s)];
    }
  }

  // Encode each tile: symbols collected forward, rANS run backward over two lanes.
  std::vector<CodedTile> coded(tiles.size());
  uint64_t total_bits = uint64_t(table_cost);
  struct Sym {
    uint16_t table, token;
  };
  std::vector<Sym> syms;
  for (size_t ti = 0; ti < tiles.size(); ++ti) {
    Tile& t = tiles[ti];
    BitWriter raw;
    syms.clear();
    for_values(t.lev.data(), t.pw, t.ph, [&](int ctx, int64_t pred, size_t off, bool dc) -> int32_t {
      const int64_t v = t.lev[off];
      const int64_t r = dc ? v - pred : v;
      const uint32_t m = dc ? uint32_t(r >= 0 ? 2 * r : -2 * r - 1) : uint32_t(r < 0 ? -r : r);
      int rb;
      const int tok = token_of(m, &rb);
      syms.push_back({uint16_t(ctx_table[size_t(ctx)]), uint16_t(tok)});
      raw.put(m & ((1u << rb) - 1), rb);
      if (!dc && m) raw.put(v < 0 ? 1 : 0, 1);
      return dc ? 0 : int32_t(m);
    });
    raw.flush();
    std::vector<uint16_t> rev;
    uint32_t x[2] = {kRansL, kRansL};
    for (size_t i = syms.size(); i-- > 0;) {
      const Table& tb = tables[syms[i].table];
      const uint32_t fq = tb.freq[syms[i].token], st = tb.start[syms[i].token];
      uint32_t& s = x[i & 1];
      const uint64_t x_max = (uint64_t(kRansL >> kProbBits) << 16) * fq;
      while (s >= x_max) {
        rev.push_back(uint16_t(s));
        s >>= 16;
      }
      s = ((s / fq) << kProbBits) + (s % fq) + st;
    }
    for (int lane = 1; lane >= 0; --lane) {
      rev.push_back(uint16_t(x[lane]));
      rev.push_back(uint16_t(x[lane] >> 16));
    }
    coded[ti].rans.assign(rev.rbegin(), rev.rend());
    coded[ti].raw = std::move(raw.words);
    total_bits += 16 * coded[ti].rans.size() + 64 * coded[ti].raw.size();
  }

  // Decode: the same visit order; each value decoded where the encoder read it.
  std::vector<std::vector<int32_t>> decoded(tiles.size());
  for (size_t ti = 0; ti < tiles.size(); ++ti) decoded[ti].assign(tiles[ti].lev.size(), 0);
  const double t_rans = best_of([&] {
    for (size_t ti = 0; ti < tiles.size(); ++ti) {
      const Tile& t = tiles[ti];
      int32_t* lev = decoded[ti].data();
      const uint16_t* in = coded[ti].rans.data();
      // The current lane's state and the other's, swapped after each value (the lanes alternate), so
      // both stay in registers.
      uint32_t s = uint32_t(in[0]) << 16 | in[1], other = uint32_t(in[2]) << 16 | in[3];
      in += 4;
      const uint64_t* rw = coded[ti].raw.data();
      uint64_t bitbuf = coded[ti].raw.empty() ? 0 : rw[0];
      int bitpos = 0;
      size_t word = 0;
      const size_t words = coded[ti].raw.size();
      auto raw_bits = [&](int n) -> uint32_t {
        if (!n) return 0;
        uint64_t v = bitbuf >> bitpos;
        if (bitpos + n > 64) {
          const uint64_t next = word + 1 < words ? rw[word + 1] : 0;
          v |= next << (64 - bitpos);
        }
        bitpos += n;
        if (bitpos >= 64) {
          ++word;
          bitpos -= 64;
          bitbuf = word < words ? rw[word] : 0;
        }
        return uint32_t(v & ((uint64_t(1) << n) - 1));
      };
      for_values(lev, t.pw, t.ph, [&](int ctx, int64_t pred, size_t off, bool dc) -> int32_t {
        const Table& tb = tables[size_t(ctx_table[size_t(ctx)])];
        const uint32_t e = tb.slot[s & (kProbScale - 1)];
        const uint32_t tok = e & 127, fq = (e >> 7) & 4095;
        s = fq * (s >> kProbBits) + (e >> 19);
        if (s < kRansL) s = (s << 16) | *in++;
        std::swap(s, other);
        uint32_t m;
        if (tok < 16) {
          m = tok;
        } else {
          const int n = int(tok - 16) / 2 + 4;
          m = (1u << n) | ((tok & 1) << (n - 1)) | raw_bits(n - 1);
        }
        if (dc) {
          const int64_t r = (m & 1) ? -int64_t(m + 1) / 2 : int64_t(m / 2);
          lev[off] = int32_t(pred + r);
          return 0;
        }
        lev[off] = (m && raw_bits(1)) ? -int32_t(m) : int32_t(m);
        return int32_t(m);
      });
    }
  });
  size_t mismatches = 0;
  for (size_t ti = 0; ti < tiles.size(); ++ti)
    for (size_t k = 0; k < tiles[ti].lev.size(); ++k) mismatches += decoded[ti][k] != tiles[ti].lev[k];

  // Dequantisation + inverse transform alone (both decoders need it).
  std::vector<int32_t> work;
  const double t_inverse = best_of([&] {
    for (size_t ti = 0; ti < tiles.size(); ++ti) {
      const Tile& t = tiles[ti];
      work.assign(decoded[ti].begin(), decoded[ti].end());
      for (int y = 0; y < t.ph; ++y)
        for (int x = 0; x < t.pw; ++x) {
          const int band = band_at(x, y);
          int32_t& c = work[size_t(y) * t.pw + x];
          c = int32_t(dequantize(c, steps.q8[band]));
        }
      inverse_lapped(work.data(), t.pw, t.ph, lossy);
    }
  });
  const double ms = samples / 1e6;
  std::printf(
      "%s step %.2f tile %d: RLGR stream %.4f b/s, decode %.1f Ms/s | static rANS %.4f b/s (%zu tables, "
      "%.0f table bits), entropy decode %.1f Ms/s, %zu mismatches | dequant+inverse %.1f Ms/s -> rANS "
      "whole decode ~%.1f Ms/s, RLGR entropy part ~%.1f Ms/s\n",
      argv[1], step, T, 8.0 * double(written) / samples, ms / t_rlgr, double(total_bits) / samples,
      tables.size(), table_cost, ms / t_rans, mismatches, ms / t_inverse, ms / (t_rans + t_inverse),
      t_rlgr > t_inverse ? ms / (t_rlgr - t_inverse) : 0.0);
  return mismatches ? 1 : 0;
}
