// The coefficient model shared by the entropy-coding prototypes (entropy_bits.cpp: its bits;
// rans_decode.cpp: a real coder and its speed): libcodec's position scan, the hybrid-integer tokens and
// the static-table cost estimate used to cluster context histograms.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "codec/codec.h"

namespace experiments {

struct Pos {
  int u, v;
};
// libcodec's scan of the 15 AC positions of a 4x4 block (LP: of a macroblock's block DCs).
constexpr Pos kScan[15] = {{1, 0}, {0, 1}, {0, 2}, {1, 1}, {2, 0}, {3, 0}, {2, 1}, {1, 2},
                           {0, 3}, {1, 3}, {2, 2}, {3, 1}, {3, 2}, {2, 3}, {3, 3}};
constexpr int kTokens = 68;
constexpr int kClasses = 10;

// Token of magnitude m: m below 16, else 16 + 2 (n - 4) + the bit below the leading one (n = floor
// log2 m); raw_bits receives the n - 1 bits that follow.
inline int token_of(uint32_t m, int* raw_bits) {
  if (m < 16) {
    *raw_bits = 0;
    return int(m);
  }
  const int n = 31 - __builtin_clz(m);
  *raw_bits = n - 1;
  return 16 + (n - 4) * 2 + int((m >> (n - 1)) & 1);
}

// A 1201 x 1201 SRTM3 .hgt (big-endian int16, voids as 0) into src; false when unreadable.
inline bool read_srtm3(const char* path, std::vector<int32_t>& src) {
  FILE* f = std::fopen(path, "rb");
  if (!f) return false;
  std::vector<uint8_t> bytes(size_t(1201) * 1201 * 2);
  const bool whole = std::fread(bytes.data(), 1, bytes.size(), f) == bytes.size();
  std::fclose(f);
  src.resize(bytes.size() / 2);
  for (size_t i = 0; i < src.size(); ++i) {
    const int16_t v = int16_t(bytes[2 * i] << 8 | bytes[2 * i + 1]);
    src[i] = v == -32768 ? 0 : v;
  }
  return whole;
}

// The real codec's stream of src (w x h) at step and tile size: bytes into stream, its decoded samples
// into recon; returns the stream size.
inline size_t encode_rlgr(const std::vector<int32_t>& src, int w, int h, double step, int tile,
                          std::vector<uint8_t>& stream, std::vector<int32_t>& recon,
                          codec::Scratch& scratch) {
  codec::EncodeOptions o;
  o.step = step;
  o.tile_size = uint32_t(tile);
  stream.resize(codec::encode_bound(w, h, o));
  recon.resize(src.size());
  size_t written = 0;
  codec::encode(src.data(), w, w, h, o, stream.data(), stream.size(), &written, scratch, recon.data(), w);
  return written;
}

// LOCO-I's median predictor.
inline int64_t med(int64_t l, int64_t t, int64_t tl) {
  const int64_t lo = std::min(l, t), hi = std::max(l, t);
  return tl >= hi ? lo : tl <= lo ? hi : l + t - tl;
}

// The MED prediction of macroblock (mx, my)'s DC level from its decoded neighbours (lev: a tile of
// levels in place, row stride pw; DCs at multiples of 16).
inline int64_t dc_prediction(const int32_t* lev, int pw, int mx, int my) {
  const auto at = [&](int x, int y) { return int64_t(lev[size_t(y) * 16 * pw + size_t(x) * 16]); };
  return (mx | my) == 0 ? 0
         : my == 0      ? at(mx - 1, 0)
         : mx == 0      ? at(0, my - 1)
                        : med(at(mx - 1, my), at(mx, my - 1), at(mx - 1, my - 1));
}

// libcodec's band of the coefficient at (x, y) of a tile: 0 DC, 1..15 LP, 16..30 HP (quantizer.h).
inline int band_at(int x, int y) {
  const int p = (y & 3) * 4 + (x & 3), q = (y >> 2 & 3) * 4 + (x >> 2 & 3);
  return p != 0 ? 15 + p : q;
}

// Bits of coding counts h with frequencies normalised to 2^prob_bits.
inline double coded_bits(const std::vector<uint64_t>& h, int prob_bits) {
  uint64_t total = 0;
  for (auto c : h) total += c;
  if (!total) return 0;
  const double scale = std::ldexp(1.0, prob_bits);
  double bits = 0;
  for (auto c : h)
    if (c)
      bits +=
          double(c) * (prob_bits - std::log2(std::max(1.0, std::round(scale * double(c) / double(total)))));
  return bits;
}
// Estimated cost of storing a table: 8 bits + 9 per used token + 1 per unused one below the last.
inline double table_bits(const std::vector<uint64_t>& h) {
  int used = 0, last = 0;
  for (int t = 0; t < kTokens; ++t)
    if (h[size_t(t)]) ++used, last = t;
  return used ? 8 + used * 9.0 + (last + 1 - used) : 0;
}

// Greedy clustering of context histograms: merges the pair that saves most (coded bits at 2^prob_bits
// precision + table_bits) while any saves, then, with MAX_TABLES=N in the environment, the cheapest
// pairs until N tables are left. out receives the merged histograms, table_cost their tables' bits;
// returns each context's table (contexts without counts: table 0).
inline std::vector<int> cluster(const std::vector<std::vector<uint64_t>>& hist, int prob_bits,
                                std::vector<std::vector<uint64_t>>& out, double* table_cost) {
  const auto coded = [prob_bits](const std::vector<uint64_t>& h) { return coded_bits(h, prob_bits); };
  const size_t n = hist.size();
  const size_t max_tables = std::getenv("MAX_TABLES") ? size_t(std::atoi(std::getenv("MAX_TABLES"))) : n;
  std::vector<std::vector<uint64_t>> c = hist;
  std::vector<int> owner(n);
  for (size_t i = 0; i < n; ++i) owner[i] = int(i);
  std::vector<bool> alive(n);
  for (size_t i = 0; i < n; ++i) {
    uint64_t s = 0;
    for (auto v : hist[i]) s += v;
    alive[i] = s > 0;
  }
  std::vector<double> cost(n);
  for (size_t i = 0; i < n; ++i) cost[i] = alive[i] ? coded(c[i]) + table_bits(c[i]) : 0;
  auto merged = [&](size_t i, size_t j) {
    std::vector<uint64_t> m(kTokens);
    for (int t = 0; t < kTokens; ++t) m[size_t(t)] = c[i][size_t(t)] + c[j][size_t(t)];
    return m;
  };
  std::vector<std::vector<double>> gain(n, std::vector<double>(n, -1e300));
  auto update = [&](size_t i, size_t j) {
    auto m = merged(i, j);
    gain[i][j] = cost[i] + cost[j] - coded(m) - table_bits(m);
  };
  for (size_t i = 0; i < n; ++i)
    for (size_t j = i + 1; j < n; ++j)
      if (alive[i] && alive[j]) update(i, j);
  for (;;) {
    double best = 0;
    size_t bi = 0, bj = 0;
    for (size_t i = 0; i < n; ++i)
      if (alive[i])
        for (size_t j = i + 1; j < n; ++j)
          if (alive[j] && gain[i][j] > best) best = gain[i][j], bi = i, bj = j;
    size_t count = 0;
    for (size_t i = 0; i < n; ++i) count += alive[i];
    if (best <= 0) {
      // Over the table limit: merge the cheapest pair even at a loss.
      if (count <= max_tables) break;
      best = -1e300;
      for (size_t i = 0; i < n; ++i)
        if (alive[i])
          for (size_t j = i + 1; j < n; ++j)
            if (alive[j] && gain[i][j] > best) best = gain[i][j], bi = i, bj = j;
    }
    c[bi] = merged(bi, bj);
    alive[bj] = false;
    for (size_t k = 0; k < n; ++k)
      if (owner[k] == int(bj)) owner[k] = int(bi);
    cost[bi] = coded(c[bi]) + table_bits(c[bi]);
    for (size_t k = 0; k < n; ++k)
      if (alive[k] && k != bi) update(std::min(k, bi), std::max(k, bi));
  }
  std::vector<int> index(n, -1), map(n, 0);
  out.clear();
  *table_cost = 0;
  for (size_t i = 0; i < n; ++i)
    if (alive[i]) {
      index[i] = int(out.size());
      out.push_back(c[i]);
      *table_cost += table_bits(c[i]);
    }
  for (size_t k = 0; k < n; ++k) map[k] = index[size_t(owner[k])] < 0 ? 0 : index[size_t(owner[k])];
  return map;
}

}  // namespace experiments
