// Prototype (built as experiments/rlgr_start, not installed): how many bits does RLGR spend warming up
// in each tile, and what would a better start state per band save? Format unchanged: this program
// re-encodes the coded levels with libcodec's rlgr_encode and counts bits.
//
// The pyramid is built as experiments/coarse_context builds it (the same code, level_streams.h): as
// pyramid-build builds an rms or step target with the wavelet D (the library's builder,
// DownsampleFilter::wavelet(), PtcResidualCoder with the given finest step and coarse step ratio, tile
// 32, its default bands;
// levels coded by libcodec format 5: per tile the residual lifting transform or the lapped transform,
// RLGR). Every tile of the levels above the coarsest is parsed out of its band's real stream
// (read_header / read_tile_index, gamma_decode and rlgr_decode from libcodec's start states), which
// gives every RLGR sequence exactly as it was coded: a residual-transform tile's four bands LL, HL, LH,
// HH (each after its start flag bit), a lapped tile's DC residuals after the first (after a flag bit),
// LP (after a flag bit) and HP (start derived from the LP flag). These 7 groups are the band groups
// below. Each sequence ("tile band") is then re-encoded with rlgr_encode from:
//  today     the start the stream used, plus its flag bits (1 per lifting band, DC and LP; HP none).
//            With each tile's transform bit and gamma-coded first DC this must reproduce the real
//            payload up to each tile's byte padding ("check": re-encoded bits against 8 * payload
//            bytes, every tile within 0-7 bits).
//  level K   (K = 1, 2, 4, 8) per level and group a set of K start states (kp, krp) on the grid
//            kp, krp in {0, 4, ..., 80} (21 x 21), chosen by the encoder from the level's tile bands
//            (K = 1: the state that codes the level's bands of that group in the fewest bits;
//            K > 1: greedily, each next state the one that lowers the sum of the per-tile-band minimum
//            most), stored once per level and used group: 10 bits per state (kp / 4 and krp / 4 in 5
//            bits each); each tile band then picks the best of the K with log2(K) bits, in place of
//            today's flag bits. K = 1: one start per level and group, no per-tile bit. Also with the
//            index coded at its empirical entropy over the level's tile bands of the group (an ideal
//            static code of the choice; no table for it counted).
//  oracle    every tile band from its best grid state, nothing signalled: the bound of any start
//            choice (the whole warm-up a start state can remove).
//  carry     every tile band from the state in which the previous tile band of the same group in the
//            level's raster order (across the level's band streams) ended; the first of each group
//            from today's start and flag. No flag bits. Tiles would no longer decode independently:
//            a bound, not a design.
// Each variant's change is (bits(variant) - bits(today)) / (8 * the real pyramid's bytes), the change
// of the whole file if the variant replaced today's starts; the coarsest level (coded as values) is
// left as it is. The quantised levels are held fixed (the product's state-dependent dead zone would
// requantise a little under another start). RESULT line: DEM, step, ratio, check (tiles off by more than
// their padding), then level1 level2 level4 level8, level2 level4 level8 with entropy-coded index, oracle,
// carry (all in % of the whole pyramid), and today's flag bits in % of the whole pyramid.
//
// Build: cd build && make -j2 rlgr_start
// Run:   build/experiments/rlgr_start DEM STEP [RATIO [TILE]]
//        (the arguments of coarse_context: STEP and RATIO from `pyramid-build DEM -o X.pyr --rms T
//        --downsample wavelet --json -`, step_metres and coarse_step_ratio). Environment: LEVELS=1
//        (per-level lines with each group's level-1 start).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "codec/internal/bitio.h"
#include "codec/internal/rlgr.h"
#include "level_streams.h"

using namespace terrain;
using namespace codec::detail;
using experiments::kGroupName;
using experiments::kGroups;
using experiments::TileBand;

namespace {

constexpr int kGridStep = 4, kGridSide = 80 / kGridStep + 1, kCandidates = kGridSide * kGridSide;
constexpr double kStateBits = 10;  // a stored state: kp / 4 and krp / 4 in 5 bits each
constexpr int kSetSizes[] = {1, 2, 4, 8};
constexpr int kSets = 4;

RlgrState candidate(int c) { return RlgrState{(c / kGridSide) * kGridStep, (c % kGridSide) * kGridStep}; }

std::vector<uint8_t> g_buffer(1 << 20);
// Bits of rlgr_encode(values) from state s; s becomes the end state.
double rlgr_bits(const std::vector<int32_t>& values, RlgrState& s) {
  BitWriter out(g_buffer.data(), g_buffer.size());
  rlgr_encode(out, values.data(), values.size(), s);
  if (out.overflow()) {
    std::fprintf(stderr, "buffer overflow\n");
    std::exit(1);
  }
  return double(out.bit_count());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: rlgr_start DEM STEP [RATIO [TILE]]\n");
    return 2;
  }
  const Heightmap map = read_heightmap(argv[1]);
  const PtcCoderOptions co = experiments::coder_options(argc, argv);
  const bool per_level = std::getenv("LEVELS") != nullptr;

  MemoryPyramid mem;
  const BuildResult built = experiments::build_wavelet_pyramid(map, co, mem);
  const uint64_t total_bytes = mem.total_bytes();
  const int levels = int(mem.header.levels.size());
  const double finest_n = double(map.info.width) * double(map.info.height);

  double payload_bits = 0, overhead_bits = 0, today_bits = 0;  // levels >= 1
  double set_bits[kSets] = {}, set_entropy_bits[kSets] = {}, oracle_bits = 0, carry_bits = 0, flag_bits = 0;
  uint64_t tiles = 0, bad_tiles = 0;
  std::vector<RlgrState> set_state[kSets];

  for (int l = 1; l < levels; ++l) {
    std::vector<TileBand> bands;  // the level's tile bands in raster order
    double level_today = 0, level_payload = 0;
    const bool parsed = experiments::for_each_tile(
        mem, l, [&](const codec::HeaderInfo&, const codec::TileEntry& e, experiments::LevelTile& tile) {
          ++tiles;
          level_payload += 8.0 * e.size;
          double tile_bits = 0;  // today's bits of this tile, re-encoded
          if (tile.transform_bits) overhead_bits += 1, tile_bits += 1;
          if (!tile.lifting) {
            BitWriter g(g_buffer.data(), g_buffer.size());
            gamma_encode(g, tile.dc0);
            overhead_bits += double(g.bit_count()), tile_bits += double(g.bit_count());
          }
          for (TileBand& tb : tile.bands) {
            RlgrState s = tb.start;
            tile_bits += tb.flag_bits + rlgr_bits(tb.values, s);
            bands.push_back(std::move(tb));
          }
          if (tile_bits > 8.0 * e.size || tile_bits <= 8.0 * e.size - 8) ++bad_tiles;
          level_today += tile_bits;
        });
    if (!parsed) return 1;
    payload_bits += level_payload;
    today_bits += level_today;

    // Costs of every tile band from every grid state.
    std::vector<std::vector<double>> cost(bands.size(), std::vector<double>(kCandidates));
    for (size_t i = 0; i < bands.size(); ++i)
      for (int c = 0; c < kCandidates; ++c) {
        RlgrState s = candidate(c);
        cost[i][size_t(c)] = rlgr_bits(bands[i].values, s);
      }
    double level_set[kSets] = {}, level_set_entropy[kSets] = {}, level_oracle = 0;
    for (const TileBand& tb : bands) flag_bits += tb.flag_bits;
    int best_single[kGroups];
    for (int g = 0; g < kGroups; ++g) {
      best_single[g] = -1;
      std::vector<size_t> members;
      for (size_t i = 0; i < bands.size(); ++i)
        if (bands[i].group == g) members.push_back(i);
      if (members.empty()) continue;
      for (size_t i : members) level_oracle += *std::min_element(cost[i].begin(), cost[i].end());
      // Greedy sets: best[i] is the member's cost from the best state chosen so far.
      std::vector<double> best(members.size(), 1e300);
      std::vector<int> which(members.size(), 0);  // the index of the member's best state in the set
      int chosen = 0;
      for (int s = 0; s < kSets; ++s) {
        while (chosen < kSetSizes[s]) {
          double best_sum = 1e300;
          int best_c = 0;
          for (int c = 0; c < kCandidates; ++c) {
            double sum = 0;
            for (size_t m = 0; m < members.size(); ++m) sum += std::min(best[m], cost[members[m]][size_t(c)]);
            if (sum < best_sum) best_sum = sum, best_c = c;
          }
          for (size_t m = 0; m < members.size(); ++m)
            if (cost[members[m]][size_t(best_c)] < best[m])
              best[m] = cost[members[m]][size_t(best_c)], which[m] = chosen;
          if (chosen == 0) best_single[g] = best_c;
          ++chosen;
        }
        double sum = 0;
        for (double b : best) sum += b;
        const double index_bits = std::log2(double(kSetSizes[s]));
        level_set[s] += sum + index_bits * double(members.size()) + kStateBits * kSetSizes[s];
        // The indices coded at their empirical entropy over the level's tile bands of the group.
        std::vector<double> count(size_t(kSetSizes[s]), 0);
        for (int i : which) count[size_t(i)] += 1;
        double entropy = 0;
        for (double c : count)
          if (c > 0) entropy -= c * std::log2(c / double(members.size()));
        level_set_entropy[s] += sum + entropy + kStateBits * kSetSizes[s];
      }
    }
    // Carry: each group's state runs on from tile band to tile band.
    double level_carry = 0;
    RlgrState carried[kGroups];
    bool started[kGroups] = {};
    for (const TileBand& tb : bands) {
      RlgrState& s = carried[tb.group];
      if (!started[tb.group]) s = tb.start, started[tb.group] = true, level_carry += tb.flag_bits;
      level_carry += rlgr_bits(tb.values, s);
    }
    // The bits outside RLGR sequences (transform bits, first DC) are the same in every variant.
    double level_overhead = level_today;
    for (const TileBand& tb : bands) {
      RlgrState s = tb.start;
      level_overhead -= tb.flag_bits + rlgr_bits(tb.values, s);
    }
    for (int s = 0; s < kSets; ++s)
      set_bits[s] += level_set[s] + level_overhead,
          set_entropy_bits[s] += level_set_entropy[s] + level_overhead;
    oracle_bits += level_oracle + level_overhead;
    carry_bits += level_carry + level_overhead;
    if (per_level && level_today > 0) {
      const GridSize fine = mem.header.levels[size_t(l)];
      std::printf(
          "level %d %lldx%lld: payload %.0f today %.0f | level1 %+.2f%% level4 %+.2f%% oracle %+.2f%% "
          "carry %+.2f%% (of the level's today) | level-1 starts",
          l, (long long)fine.width, (long long)fine.height, level_payload, level_today,
          100 * (level_set[0] + level_overhead - level_today) / level_today,
          100 * (level_set[2] + level_overhead - level_today) / level_today,
          100 * (level_oracle + level_overhead - level_today) / level_today,
          100 * (level_carry + level_overhead - level_today) / level_today);
      for (int g = 0; g < kGroups; ++g)
        if (best_single[g] >= 0)
          std::printf(" %s %d/%d", kGroupName[g], candidate(best_single[g]).kp,
                      candidate(best_single[g]).krp);
      std::printf("\n");
    }
  }

  const double total_bits = 8.0 * double(total_bytes);
  const auto change = [&](double bits) { return 100 * (bits - today_bits) / total_bits; };
  std::printf("%s step %.4f ratio %.3g tile %u: pyramid %llu bytes (%.4f b/s), finest rms %.4f, %d levels\n",
              argv[1], co.step, co.coarse_step_ratio, co.tile_size, (unsigned long long)total_bytes,
              total_bits / finest_n, built.levels.back().error_rms, levels);
  std::printf(
      "levels >= 1: %llu tiles, payload %.0f bits, re-encoded with today's starts %.0f bits (%.3f%% below: "
      "byte padding), %llu tiles outside 0-7 bits of padding; transform bits and first DCs %.0f\n",
      (unsigned long long)tiles, payload_bits, today_bits, 100 * (payload_bits - today_bits) / payload_bits,
      (unsigned long long)bad_tiles, overhead_bits);
  std::printf("whole-pyramid change against today's starts:");
  for (int s = 0; s < kSets; ++s) std::printf(" level%d %+.2f%%", kSetSizes[s], change(set_bits[s]));
  std::printf(" oracle %+.2f%% carry %+.2f%%\n", change(oracle_bits), change(carry_bits));
  std::printf("with the set index entropy-coded:");
  for (int s = 1; s < kSets; ++s) std::printf(" level%d %+.2f%%", kSetSizes[s], change(set_entropy_bits[s]));
  std::printf("; today's start flag bits %.0f (%.2f%% of the pyramid)\n", flag_bits,
              100 * flag_bits / total_bits);
  std::printf("RESULT %s %.4f %.3g %llu", argv[1], co.step, co.coarse_step_ratio,
              (unsigned long long)bad_tiles);
  for (int s = 0; s < kSets; ++s) std::printf(" %.2f", change(set_bits[s]));
  for (int s = 1; s < kSets; ++s) std::printf(" %.2f", change(set_entropy_bits[s]));
  std::printf(" %.2f %.2f %.2f\n", change(oracle_bits), change(carry_bits), 100 * flag_bits / total_bits);
  return 0;
}
