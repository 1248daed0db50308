// The coded levels as the product writes them, read back for the prototypes that study them
// (coarse_context.cpp: contexts for the quantised levels; rlgr_start.cpp: RLGR's start states): one
// piece of code where the logic is the same, so that both measure the very same pyramid and levels.
// It provides
//  * libcodec's RLGR start states (tile_coder.cpp's kLiftingStart, kDcStart, kLpStart and hp_start;
//    a decoder needs them to parse a tile) and the 7 band groups (kGroups: a residual-transform tile's
//    lifting bands LL, HL, LH, HH, then a lapped tile's DC residuals, LP and HP);
//  * the pyramid built as pyramid-build builds an rms or step target with the wavelet D
//    (coder_options from the arguments DEM STEP [RATIO [TILE]], build_wavelet_pyramid: the library's
//    builder, DownsampleFilter::wavelet(), PtcResidualCoder, one thread);
//  * the parsing of every band's real stream of a level back into its quantised levels (for_each_tile:
//    read_header / read_tile_index, then each tile payload with libcodec's own gamma_decode and
//    rlgr_decode from those start states), so the levels are exactly the ones RLGR coded.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <utility>
#include <vector>

#include "build/ptc_coder.h"
#include "codec/codec.h"
#include "codec/internal/bitio.h"
#include "codec/internal/lifting_transform.h"
#include "codec/internal/rlgr.h"
#include "codec/internal/tile_coder.h"
#include "pyramid/builder.h"
#include "pyramid/downsample.h"
#include "pyramid/memory_pyramid.h"
#include "readers/heightmap.h"

namespace experiments {

using codec::detail::RlgrState;

// libcodec's start states (tile_coder.cpp; the decoder needs them to parse a tile).
inline constexpr RlgrState kLpStart[2] = {{0, 40}, {8, 8}};
inline constexpr RlgrState kDcStart[2] = {{0, 16}, {0, 48}};
inline constexpr RlgrState kLiftingStart[2] = {{8, 8}, {64, 8}};
inline RlgrState hp_start(int lp_flag, bool lp_zero) {
  if (lp_flag && lp_zero) return RlgrState{64, 8};
  if (lp_flag) return RlgrState{40, 8};
  return RlgrState{};
}

// The band groups: a residual-transform tile's lifting band k (0 .. 3), then a lapped tile's bands.
inline constexpr int kGroups = 7;  // LL, HL, LH, HH, DC, LP, HP
inline constexpr int kGroupDc = 4, kGroupLp = 5, kGroupHp = 6;
inline const char* const kGroupName[kGroups] = {"LL", "HL", "LH", "HH", "DC", "LP", "HP"};

// The arguments DEM STEP [RATIO [TILE]]: the finest step, the coarse step ratio (default 1) and the
// tile size (default 32).
inline terrain::PtcCoderOptions coder_options(int argc, char** argv) {
  terrain::PtcCoderOptions co;
  co.step = std::atof(argv[2]);
  co.coarse_step_ratio = argc > 3 ? std::atof(argv[3]) : 1.0;
  co.tile_size = argc > 4 ? uint32_t(std::atoi(argv[4])) : 32;
  return co;
}

// Builds map's pyramid into mem as pyramid-build builds an rms or step target with the wavelet D.
inline terrain::BuildResult build_wavelet_pyramid(const terrain::Heightmap& map,
                                                  const terrain::PtcCoderOptions& co,
                                                  terrain::MemoryPyramid& mem) {
  terrain::BuildOptions bo;
  bo.threads = 1;
  bo.use_fixed_filter = true;
  bo.fixed_filter = terrain::DownsampleFilter::wavelet();
  terrain::PtcResidualCoder coder(co);
  return terrain::build_pyramid(map, bo, coder, mem);
}

// One RLGR sequence of a tile as the stream coded it ("tile band").
struct TileBand {
  int group;                         // 0 .. kGroups - 1
  std::vector<int32_t> values;       // the quantised levels
  RlgrState start;                   // the start state the stream used
  int flag_bits;                     // the bits that chose it (1 per lifting band, DC and LP; HP none)
  int x0 = 0, y0 = 0, w = 0, h = 0;  // a lifting band: its rectangle in the tile
};

// A tile of a level, parsed out of its band's stream.
struct LevelTile {
  int tx = 0, ty = 0, w = 0, h = 0;      // its place in the band's stream and its size
  int64_t y0 = 0;                        // its first row in the level
  bool lifting = false;                  // residual (lifting) transform, else lapped
  int transform_bits = 0;                // the bit that chose the transform (residual streams only)
  int32_t dc0 = 0;                       // lapped: the first DC (gamma-coded)
  int pw = 0, ph = 0, mbx = 0, mby = 0;  // lapped: the padded tile and its macroblocks
  // lifting: LL, HL, LH, HH (empty bands left out); lapped: the DC residuals after the first (present
  // even where there are none: its flag is still coded), LP, HP.
  std::vector<TileBand> bands;
};

// Parses the payload of one tile of a band stream (transform bit, then its RLGR sequences).
inline bool parse_tile(codec::detail::BitReader& in, bool residual_stream, int level, LevelTile& tile) {
  using namespace codec::detail;
  if (residual_stream) {
    in.refill();
    tile.lifting = in.take(1) == 0;
    tile.transform_bits = 1;
  }
  const int w = tile.w, h = tile.h;
  if (tile.lifting) {
    const LiftingBands lb = lifting_bands(w, h);
    for (int k = 0; k < kLiftingBandCount; ++k) {
      const bool ox = k & 1, oy = k & 2;
      const int x0 = ox ? lb.even_w : 0, y0 = oy ? lb.even_h : 0, x1 = ox ? w : lb.even_w,
                y1 = oy ? h : lb.even_h;
      const int bw = x1 - x0, bh = y1 - y0;
      if (bw <= 0 || bh <= 0) continue;
      const size_t n = size_t(bw) * size_t(bh);
      in.refill();
      TileBand tb{k, std::vector<int32_t>(n), kLiftingStart[in.take(1)], 1, x0, y0, bw, bh};
      RlgrState st = tb.start;
      if (!rlgr_decode(in, tb.values.data(), n, st)) {
        std::fprintf(stderr, "level %d: a tile does not parse\n", level);
        return false;
      }
      tile.bands.push_back(std::move(tb));
    }
    return true;
  }
  tile.pw = padded_side(w), tile.ph = padded_side(h), tile.mbx = tile.pw / 16, tile.mby = tile.ph / 16;
  const size_t mbs = size_t(tile.mbx) * tile.mby, lp_count = mbs * 15,
               hp_count = size_t(tile.pw) * tile.ph - mbs - lp_count;
  bool ok = gamma_decode(in, &tile.dc0);
  in.refill();
  TileBand dc{kGroupDc, std::vector<int32_t>(mbs - 1), kDcStart[in.take(1)], 1};
  RlgrState st = dc.start;
  ok = ok && rlgr_decode(in, dc.values.data(), mbs - 1, st);
  in.refill();
  const int lp_flag = int(in.take(1));
  TileBand lp{kGroupLp, std::vector<int32_t>(lp_count), kLpStart[lp_flag], 1};
  st = lp.start;
  ok = ok && rlgr_decode(in, lp.values.data(), lp_count, st);
  const bool lp_zero = std::all_of(lp.values.begin(), lp.values.end(), [](int32_t x) { return x == 0; });
  TileBand hp{kGroupHp, std::vector<int32_t>(hp_count), hp_start(lp_flag, lp_zero), 0};
  st = hp.start;
  ok = ok && rlgr_decode(in, hp.values.data(), hp_count, st);
  if (!ok) {
    std::fprintf(stderr, "level %d: a lapped tile does not parse\n", level);
    return false;
  }
  tile.bands.push_back(std::move(dc));
  tile.bands.push_back(std::move(lp));
  tile.bands.push_back(std::move(hp));
  return true;
}

// Parses every tile of level l out of its bands' streams (non-empty bands and tiles, in stream order)
// and calls fn(hi, e, tile): the stream's header, the tile's index entry and the parsed tile. false,
// with a line on stderr, where a band does not open or a tile does not parse.
template <class Fn> bool for_each_tile(const terrain::MemoryPyramid& mem, int l, Fn&& fn) {
  for (const terrain::MemoryPyramid::Band& band : mem.bands[size_t(l)]) {
    if (band.bytes.empty()) continue;
    codec::HeaderInfo hi;
    std::vector<codec::TileEntry> entries;
    std::vector<codec::RowChecksum> rows;
    if (codec::read_header(band.bytes.data(), band.bytes.size(), &hi) != codec::Status::Ok ||
        codec::read_tile_index(band.bytes.data(), band.bytes.size(), hi, &entries, &rows) !=
            codec::Status::Ok) {
      std::fprintf(stderr, "level %d: band at %lld does not open\n", l, (long long)band.y0);
      return false;
    }
    const bool residual_stream = hi.transform == codec::Transform::Residual;
    const int T = int(hi.tile_size);
    for (const codec::TileEntry& e : entries) {
      if (e.size == 0) continue;
      LevelTile tile;
      const int64_t t = e.first_tile;
      tile.tx = int(t % hi.tiles_x) * T, tile.ty = int(t / hi.tiles_x) * T;
      tile.w = int(std::min<int64_t>(T, hi.width - tile.tx));
      tile.h = int(std::min<int64_t>(T, hi.height - tile.ty));
      tile.y0 = band.y0 + tile.ty;
      codec::detail::BitReader in(band.bytes.data() + e.offset, e.size);
      if (!parse_tile(in, residual_stream, l, tile)) return false;
      fn(hi, e, tile);
    }
  }
  return true;
}

}  // namespace experiments
