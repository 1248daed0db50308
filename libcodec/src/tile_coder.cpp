// Band order inside a tile bitstream: DC (macroblock DCs in raster order, MED-predicted from the
// quantised neighbours), then LP, then HP, each grouped by frequency position (zig-zag order) and
// within a position by macroblock in raster order (HP: the 16 blocks of each macroblock together, see
// for_hp_blocks). Grouping by position puts coefficients of similar variance next to each other, so
// RLGR's backward adaptation settles quickly and the high frequencies become long zero runs. Each band
// group has its own RLGR state, reset per tile (DC and LP start states chosen by a flag bit each).
#include "codec/internal/tile_coder.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>

#include "codec/internal/bitio.h"
#include "codec/internal/lapped_transform.h"
#include "codec/internal/lifting_transform.h"
#include "codec/internal/phase_coder.h"
#include "codec/internal/rlgr.h"
#include "core/clones.h"

namespace codec::detail {
namespace {

struct Position {
  int u, v;  // column, row inside the 4x4 block
};
// Zig-zag order of the 15 AC positions.
constexpr Position kScan[15] = {{1, 0}, {0, 1}, {0, 2}, {1, 1}, {2, 0}, {3, 0}, {2, 1}, {1, 2},
                                {0, 3}, {1, 3}, {2, 2}, {3, 1}, {3, 2}, {2, 3}, {3, 3}};

// Band of each position in a 16x16 macroblock (row, column).
struct BandMap {
  uint8_t band[16][16];
};
constexpr BandMap make_band_map() {
  BandMap m{};
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) {
      const int p = (y & 3) * 4 + (x & 3), q = (y >> 2) * 4 + (x >> 2);
      m.band[y][x] = uint8_t(p != 0 ? hp_band(p) : q != 0 ? lp_band(q) : 0);
    }
  return m;
}
constexpr BandMap kBandMap = make_band_map();

// LP values are rarely zero and large at the low positions, so their coder usually starts in
// Golomb-Rice mode with k_R = 5 (measured: 2-3% fewer LP bits on SRTM tiles). On smooth tiles at
// large steps most LP values are zero and that start wastes tens of bits per tile, so one bit per tile
// picks the start: kLpStart[flag], whichever codes the tile's LP band in fewer bits.
constexpr RlgrState kLpStart[2] = {{0, 40}, {8, 8}};
// DC residuals (after the first) start in Golomb-Rice mode, k_R = 2 or 6, picked per tile by one bit
// like LP (the default run-mode start suits neither smooth nor rough tiles).
constexpr RlgrState kDcStart[2] = {{0, 16}, {0, 48}};

// The encoder's dead zone for LP and HP, chosen per coefficient from the RLGR state (rlgr.h): wider
// inside zero runs, a little narrower in Golomb-Rice mode, than the fixed 3/8 rounding offset. Encoder
// only: the decoder is unchanged. Measured on six SRTM DEMs (tile 64, rms 0.5-4 m): 2.7% fewer bits at
// equal rms (geometric mean; smooth tiles gain most, Berlin -5% at 1 m rms; every DEM and rate gains).
constexpr DeadZone kAcDeadZone{0.42, 0.30, 0.05, 0.05};
// Start states of the residual transform's bands, one flag bit per band: the default, or long zero
// runs for bands of near-constant tiles (sea, flats) where most levels are zero.
constexpr RlgrState kLiftingStart[2] = {{8, 8}, {64, 8}};
constexpr size_t kRunStartShare = 16;

inline int32_t saturate(int64_t v) { return int32_t(std::clamp<int64_t>(v, INT32_MIN, INT32_MAX)); }
// a + b clamped to the int32 range, in 32-bit lanes so that a row of them vectorises: the sum
// overflowed iff both operands' signs differ from its sign, and then the bound is the one on a's side.
inline int32_t saturating_add(int32_t a, int32_t b) {
  const int32_t sum = int32_t(uint32_t(a) + uint32_t(b));
  const int32_t bound = (a >> 31) ^ INT32_MAX;
  return ((a ^ sum) & (b ^ sum)) < 0 ? bound : sum;
}

inline int64_t med_predict(int64_t left, int64_t top, int64_t top_left) {
  const int64_t lo = std::min(left, top), hi = std::max(left, top);
  if (top_left >= hi) return lo;
  if (top_left <= lo) return hi;
  return left + top - top_left;
}

inline int64_t dc_prediction(const int32_t* tile, int pw, int mx, int my) {
  const auto at = [&](int x, int y) { return int64_t(tile[size_t(y) * 16 * pw + size_t(x) * 16]); };
  if (mx == 0 && my == 0) return 0;
  if (my == 0) return at(mx - 1, 0);
  if (mx == 0) return at(0, my - 1);
  return med_predict(at(mx - 1, my), at(mx, my - 1), at(mx - 1, my - 1));
}

// Coding order of the coefficients at frequency position `pos`: visit(offset) gets each one's offset
// in the padded tile. The encoder's gather and scatter and the decoder's slot table (band_layout) all
// go through these two, so the three cannot disagree.
//
// LP: the stage-2 coefficient at `pos` of every macroblock, macroblocks in raster order.
template <class Visit> inline void for_lp_macroblocks(int pw, int ph, Position pos, Visit&& visit) {
  for (int my = 0; my < ph / 16; ++my)
    for (int mx = 0; mx < pw / 16; ++mx) visit(size_t(16 * my + 4 * pos.v) * pw + 16 * mx + 4 * pos.u);
}

// HP: the coefficient at `pos` of every 4x4 block, macroblocks in raster order and the 16 blocks of
// each in raster order. Keeping a macroblock's blocks together makes busy and quiet areas longer runs
// for RLGR's adaptation than block rows across the whole tile (measured: 0.5% fewer bits at equal rms
// over six SRTM DEMs, every DEM gains; Morton order gave 0.47%).
template <class Visit> inline void for_hp_blocks(int pw, int ph, Position pos, Visit&& visit) {
  for (int my = 0; my < ph / 16; ++my)
    for (int mx = 0; mx < pw / 16; ++mx) {
      const size_t mb = size_t(16 * my + pos.v) * pw + 16 * mx + pos.u;
      for (int by = 0; by < 4; ++by)
        for (int bx = 0; bx < 4; ++bx) visit(mb + size_t(4 * by) * pw + 4 * bx);
    }
}

// The w x h tile at src into a pw x ph buffer (its last column and row repeated), each sample times
// 2^bits (the fraction bits; the encoder picks them so that the scaled samples stay within +-2^22,
// quantizer.h), in one pass (the copy and the scaling were two).
void load_padded(const int32_t* __restrict src, ptrdiff_t stride, int w, int h, int pw, int ph, int bits,
                 int32_t* __restrict tile) {
  for (int y = 0; y < ph; ++y) {
    const int32_t* row = src + ptrdiff_t(std::min(y, h - 1)) * stride;
    int32_t* dst = tile + size_t(y) * pw;
    for (int x = 0; x < w; ++x) dst[x] = int32_t(uint32_t(row[x]) << bits);
    std::fill(dst + w, dst + pw, dst[w - 1]);
  }
}

// Writes a flag bit and then, through code(writer, state), a band coded from starts[flag], choosing
// the flag that gives fewer bits: each candidate is coded once into a copy of `out` to count its bits,
// then the winner is coded for real. Returns the flag.
template <class Code> int code_with_best_start(BitWriter& out, const RlgrState (&starts)[2], Code&& code) {
  size_t cost[2];
  for (int flag = 0; flag < 2; ++flag) {
    BitWriter trial = out;
    trial.put_bit(uint32_t(flag));
    RlgrState state = starts[flag];
    code(trial, state);
    cost[flag] = trial.bit_count();
  }
  const int flag = cost[1] < cost[0] ? 1 : 0;
  out.put_bit(uint32_t(flag));
  RlgrState state = starts[flag];
  code(out, state);
  return flag;
}

// Codes the n LP coefficients at lp (quantising them in place; lp must have room for 2n values) after
// the flag that selects the cheaper start state. Returns the flag.
int code_lp(BitWriter& out, int32_t* lp, size_t n, size_t group_size, const double* group_inverse) {
  int32_t* coefficients = lp + n;
  std::copy(lp, lp + n, coefficients);
  return code_with_best_start(out, kLpStart, [&](BitWriter& writer, RlgrState& state) {
    std::copy(coefficients, coefficients + n, lp);
    rlgr_encode_quantizing(writer, lp, n, group_size, group_inverse, kAcDeadZone, state);
  });
}

bool all_zero(const int32_t* values, size_t n) {
  return std::all_of(values, values + n, [](int32_t v) { return v == 0; });
}

// HP start state from what the decoder already knows about the tile: the LP start flag (1 = smooth)
// and whether every LP level is zero. Smooth tiles start in run mode with long runs, so their mostly
// zero HP band does not spend its first codewords growing k (measured: Berlin -4.9% bits at rms 4 m,
// -0.5% at 2 m; no DEM or rate loses).
RlgrState hp_start(int lp_flag, bool lp_zero) {
  if (lp_flag && lp_zero) return RlgrState{64, 8};
  if (lp_flag) return RlgrState{40, 8};
  return RlgrState{};
}

// Quantises the transformed tile in place and writes the three bands. LP and HP are quantised while
// they are coded (kAcDeadZone).
void code_bands(BitWriter& out, int32_t* tile, int pw, int ph, const BandSteps& steps, int32_t* seq) {
  double inverse[kBandCount];
  for (int b = 0; b < kBandCount; ++b) inverse[b] = double(kStepOne) / double(steps.q8[b]);
  const int mbx = pw / 16, mby = ph / 16, bx_count = pw / 4, by_count = ph / 4;
  for (int my = 0; my < mby; ++my)
    for (int mx = 0; mx < mbx; ++mx) {
      int32_t& dc = tile[size_t(my) * 16 * pw + size_t(mx) * 16];
      dc = quantize(dc, inverse[0]);
    }

  size_t n = 0;
  for (int my = 0; my < mby; ++my)
    for (int mx = 0; mx < mbx; ++mx)
      seq[n++] = int32_t(tile[size_t(my) * 16 * pw + size_t(mx) * 16] - dc_prediction(tile, pw, mx, my));
  gamma_encode(out, seq[0]);
  code_with_best_start(out, kDcStart, [&](BitWriter& writer, RlgrState& state) {
    rlgr_encode(writer, seq + 1, n - 1, state);
  });

  n = 0;
  for (const Position& pos : kScan)
    for_lp_macroblocks(pw, ph, pos, [&](size_t offset) { seq[n++] = tile[offset]; });
  double group_inverse[15];
  for (int s = 0; s < 15; ++s) group_inverse[s] = inverse[lp_band(kScan[s].v * 4 + kScan[s].u)];
  const int lp_flag = code_lp(out, seq, n, size_t(mbx) * mby, group_inverse);
  const bool lp_zero = all_zero(seq, n);
  n = 0;
  for (const Position& pos : kScan)
    for_lp_macroblocks(pw, ph, pos, [&](size_t offset) { tile[offset] = seq[n++]; });

  n = 0;
  for (const Position& pos : kScan)
    for_hp_blocks(pw, ph, pos, [&](size_t offset) { seq[n++] = tile[offset]; });
  for (int s = 0; s < 15; ++s) group_inverse[s] = inverse[hp_band(kScan[s].v * 4 + kScan[s].u)];
  RlgrState hp_state = hp_start(lp_flag, lp_zero);
  rlgr_encode_quantizing(out, seq, n, size_t(bx_count) * by_count, group_inverse, kAcDeadZone, hp_state);
  n = 0;
  for (const Position& pos : kScan)
    for_hp_blocks(pw, ph, pos, [&](size_t offset) { tile[offset] = seq[n++]; });
}

void dequantize_tile(int32_t* tile, int pw, int ph, const BandSteps& steps) {
  for (int y = 0; y < ph; ++y) {
    const uint8_t* bands = kBandMap.band[y & 15];
    int32_t* row = tile + size_t(y) * pw;
    for (int x = 0; x < pw; ++x) row[x] = saturate(dequantize(row[x], steps.q8[bands[x & 15]]));
  }
}

constexpr size_t kLargeLayoutSamples = size_t(256) * 256;

const uint32_t* band_layout(TileWork& work, int pw, int ph) {
  for (const BandLayout& layout : work.layouts)
    if (layout.padded_width == pw && layout.padded_height == ph) return layout.slots.data();
  // Four shapes are cached, except for tiles above 256x256 samples: one table of 4096x4096 tiles
  // is 64 MB, so those keep one table (rebuilt when the shape changes: a pass over the tile, small
  // next to decoding it) and release the others.
  const bool large = size_t(pw) * ph > kLargeLayoutSamples;
  if (large)
    for (size_t i = 1; i < work.layouts.size(); ++i) work.layouts[i] = BandLayout{};
  BandLayout& layout = large ? work.layouts[0] : work.layouts[work.next_layout++ % work.layouts.size()];
  const int mbx = pw / 16, mby = ph / 16;
  assert(size_t(pw) * ph <= (size_t(1) << kSlotOffsetBits));
  layout.padded_width = pw;
  layout.padded_height = ph;
  layout.slots.resize(size_t(pw) * ph - size_t(mbx) * mby);
  const auto slot = [](int band, size_t offset) {
    return uint32_t(band) << kSlotOffsetBits | uint32_t(offset);
  };
  size_t n = 0;
  for (const Position& pos : kScan) {
    const int band = lp_band(pos.v * 4 + pos.u);
    for_lp_macroblocks(pw, ph, pos, [&](size_t offset) { layout.slots[n++] = slot(band, offset); });
  }
  for (const Position& pos : kScan) {
    const int band = hp_band(pos.v * 4 + pos.u);
    for_hp_blocks(pw, ph, pos, [&](size_t offset) { layout.slots[n++] = slot(band, offset); });
  }
  return layout.slots.data();
}

// dequantize() of a non-zero level |q| = magnitude < kRlgrMaxMagnitude, for the decoders' sinks:
// (16 |q| + 1) * step < 2^34 * kMaxBandStep = 2^64.
inline uint64_t dequantized_magnitude(uint32_t magnitude, uint32_t step_q8) {
  static_assert(uint64_t(kRlgrMaxMagnitude) * 16 <= (uint64_t(1) << 34) && kMaxBandStep <= (1u << 30));
  return ((uint64_t(magnitude) * 16 + 1) * step_q8 + 2048) >> 12;
}

// Decodes one band group (LP or HP) and dequantises each non-zero value into its slot. Out of line,
// so that the RLGR loop has the registers to itself (GCC 12: 30-50% faster than inlined into the caller).
// GCC also compiles it for x86-64-v3 (picked at load time): LZCNT and BMI2's flagless shifts, about
// 2% (clang does not combine target_clones with noinline).
// any_nonzero: whether the group held a non-zero level (the HP start state depends on it for LP).
#if defined(__clang__)
__attribute__((noinline))
#elif defined(__GNUC__)
__attribute__((noinline, flatten)) TERRAIN_TARGET_CLONES("arch=x86-64-v3", "default")
#endif
bool decode_band_group(BitReader& in, size_t count, RlgrState state, const uint32_t* slots,
                       const BandSteps& steps, int32_t* tile, bool& any_nonzero) {
  bool nonzero = false;  // a local, not any_nonzero: the stores through tile may alias a reference
  const bool ok = rlgr_decode_dense(in, count, state, [&](size_t i, uint32_t magnitude, bool negative) {
    nonzero |= magnitude != 0;
    const uint32_t slot = slots[i];
    const uint64_t value =
        dequantized_magnitude(magnitude, steps.q8[slot >> kSlotOffsetBits]) & (0 - uint64_t(magnitude != 0));
    // Stored before the range check, so negated in uint32: a rejected value must not overflow.
    tile[slot & ((1u << kSlotOffsetBits) - 1)] = int32_t(negative ? 0u - uint32_t(value) : uint32_t(value));
    return value <= uint64_t(kMaxCoefficient);
  });
  any_nonzero = nonzero;
  return ok;
}

// Reads the three bands and writes dequantised coefficients into the tile.
bool decode_bands(BitReader& in, int32_t* tile, int pw, int ph, const BandSteps& steps, TileWork& work) {
  const int mbx = pw / 16, mby = ph / 16;
  const size_t macroblocks = size_t(mbx) * mby;
  int32_t* seq = work.sequence.data();
  if (!gamma_decode(in, &seq[0])) return false;
  in.refill();
  RlgrState dc_state = kDcStart[in.take(1)];
  if (!rlgr_decode(in, seq + 1, macroblocks - 1, dc_state)) return false;
  std::memset(tile, 0, size_t(pw) * ph * sizeof(int32_t));  // only non-zero values are written below
  // DC prediction runs on quantised values, so keep them in the tile until all DCs are known.
  size_t i = 0;
  for (int my = 0; my < mby; ++my)
    for (int mx = 0; mx < mbx; ++mx) {
      const int64_t q = dc_prediction(tile, pw, mx, my) + seq[i++];
      if (q > kMaxCoefficient || q < -kMaxCoefficient) return false;
      tile[size_t(my) * 16 * pw + size_t(mx) * 16] = int32_t(q);
    }
  for (int my = 0; my < mby; ++my)
    for (int mx = 0; mx < mbx; ++mx) {
      int32_t& c = tile[size_t(my) * 16 * pw + size_t(mx) * 16];
      const int64_t value = dequantize(c, steps.q8[0]);
      if (value > kMaxCoefficient || value < -kMaxCoefficient) return false;
      c = int32_t(value);
    }

  // LP then HP, in the order of band_layout's slots.
  const uint32_t* slots = band_layout(work, pw, ph);
  const size_t lp_count = macroblocks * 15;
  in.refill();
  const int lp_flag = int(in.take(1));
  bool lp_nonzero = false;
  if (!decode_band_group(in, lp_count, kLpStart[lp_flag], slots, steps, tile, lp_nonzero)) return false;
  bool hp_nonzero = false;
  return decode_band_group(in, size_t(pw) * ph - macroblocks - lp_count, hp_start(lp_flag, !lp_nonzero),
                           slots + lp_count, steps, tile, hp_nonzero);
}

// The residual transform's bands (format 5): LL, HL, LH, HH of one lifting level, each in raster order
// with its own RLGR state from a start chosen by a flag bit, quantised while coded (kAcDeadZone). Band b
// covers columns [x0, x1) and rows [y0, y1) of the w x h tile (row stride w).
struct LiftingRect {
  int x0, y0, x1, y1;
};
LiftingRect lifting_rect(int w, int h, int band) {
  const LiftingBands b = lifting_bands(w, h);
  const bool odd_x = band & 1, odd_y = band & 2;
  return {odd_x ? b.even_w : 0, odd_y ? b.even_h : 0, odd_x ? w : b.even_w, odd_y ? h : b.even_h};
}

void code_lifting_bands(BitWriter& out, int32_t* tile, int w, int h, const BandSteps& steps, int32_t* seq) {
  for (int band = 0; band < kLiftingBandCount; ++band) {
    const LiftingRect r = lifting_rect(w, h, band);
    size_t n = 0;
    for (int y = r.y0; y < r.y1; ++y)
      for (int x = r.x0; x < r.x1; ++x) seq[n++] = tile[size_t(y) * w + x];
    if (n == 0) continue;
    const double inverse = double(kStepOne) / double(steps.q8[band]);
    // The start flag from the share of values that will quantise to non-zero (estimated with the
    // plain 3/8 rounding): long zero runs below one in kRunStartShare. Coding the band with both
    // starts and keeping the shorter was a third of the build's coding time for +-0.1 % of the bits.
    const double threshold = 0.625 * double(steps.q8[band]) / double(kStepOne);
    size_t nonzero = 0;
    for (size_t i = 0; i < n; ++i) nonzero += std::abs(double(seq[i])) >= threshold;
    const int flag = nonzero * kRunStartShare < n ? 1 : 0;
    out.put_bit(uint32_t(flag));
    RlgrState state = kLiftingStart[flag];
    rlgr_encode_quantizing(out, seq, n, n, &inverse, kAcDeadZone, state);
    n = 0;
    for (int y = r.y0; y < r.y1; ++y)
      for (int x = r.x0; x < r.x1; ++x) tile[size_t(y) * w + x] = seq[n++];
  }
}

// One band's non-zero values, dequantised straight into their tile positions (the tile is zeroed once),
// as decode_band_group does for the lapped bands; out of line and cloned for the same reasons.
#if defined(__clang__)
__attribute__((noinline))
#elif defined(__GNUC__)
__attribute__((noinline, flatten)) TERRAIN_TARGET_CLONES("arch=x86-64-v3", "default")
#endif
bool decode_lifting_band(BitReader& in, size_t count, RlgrState state, int32_t* origin, int band_w, int w,
                         uint32_t step_q8) {
  // Index i of the band sits at row i / band_w of the tile: a division off the decoder's critical
  // path, where tracking the column costs a branch per codeword that mispredicts at each row's end.
  const uint32_t bw = uint32_t(band_w), gap = uint32_t(w - band_w);
  return rlgr_decode_dense(in, count, state, [&](size_t i, uint32_t magnitude, bool negative) {
    const uint32_t row = uint32_t(i) / bw;
    const uint64_t value = dequantized_magnitude(magnitude, step_q8) & (0 - uint64_t(magnitude != 0));
    origin[i + size_t(row) * gap] = int32_t(negative ? 0u - uint32_t(value) : uint32_t(value));
    return value <= uint64_t(kMaxCoefficient);
  });
}

// Reads the four bands and writes dequantised coefficients into the w x h tile.
bool decode_lifting_bands(BitReader& in, int32_t* tile, int w, int h, const BandSteps& steps) {
  std::memset(tile, 0, size_t(w) * h * sizeof(int32_t));
  for (int band = 0; band < kLiftingBandCount; ++band) {
    const LiftingRect r = lifting_rect(w, h, band);
    const size_t n = size_t(r.x1 - r.x0) * size_t(r.y1 - r.y0);
    if (n == 0) continue;
    in.refill();
    const RlgrState state = kLiftingStart[in.take(1)];
    if (!decode_lifting_band(in, n, state, tile + size_t(r.y0) * w + r.x0, r.x1 - r.x0, w, steps.q8[band]))
      return false;
  }
  return true;
}

void dequantize_lifting(int32_t* tile, int w, int h, const BandSteps& steps) {
  for (int band = 0; band < kLiftingBandCount; ++band) {
    const LiftingRect r = lifting_rect(w, h, band);
    for (int y = r.y0; y < r.y1; ++y)
      for (int x = r.x0; x < r.x1; ++x)
        tile[size_t(y) * w + x] = int32_t(dequantize(tile[size_t(y) * w + x], steps.q8[band]));
  }
}

// n inverse-transformed values back to samples, rounded to the nearest (halves up): the decoder's
// output and the encoder's reconstruction both come through here, so they cannot differ. The add
// wraps: garbage from a corrupt stream must not be undefined behaviour.
void scale_down_row(const int32_t* from, int32_t* to, int n, int bits) {
  if (bits == 0) {
    std::memcpy(to, from, size_t(n) * sizeof(int32_t));
    return;
  }
  const uint32_t half = uint32_t(1) << (bits - 1);
  for (int x = 0; x < n; ++x) to[x] = int32_t(uint32_t(from[x]) + half) >> bits;
}

// The decoder's row outputs below are cloned for AVX-512 and AVX2 (picked at load time): the
// baseline's SSE2 needs about twice the instructions for the saturation and has no 64-bit multiply.
#define CODEC_ROW_CLONES TERRAIN_TARGET_CLONES("arch=x86-64-v4", "avx2", "default")

// dst[x] += from[x], saturating (the same as saturate(int64 sum)).
CODEC_ROW_CLONES void add_row(const int32_t* from, int32_t* dst, int n) {
  for (int x = 0; x < n; ++x) dst[x] = saturating_add(dst[x], from[x]);
}

// to[x] = from[x] * bin, saturating: a spatial-mode tile's samples.
CODEC_ROW_CLONES void spatial_row(const int32_t* from, int32_t* to, int n, int64_t bin) {
  for (int x = 0; x < n; ++x) to[x] = saturate(int64_t(from[x]) * bin);
}

// dst[x] += saturate(scale_down_row's output + c[x]), saturating: a corrected tile in add mode.
CODEC_ROW_CLONES void add_corrected_row(const int32_t* from, const int32_t* c, int32_t* dst, int n,
                                        int bits) {
  const uint32_t half = bits == 0 ? 0 : uint32_t(1) << (bits - 1);
  for (int x = 0; x < n; ++x)
    dst[x] = saturating_add(dst[x], saturating_add(int32_t(uint32_t(from[x]) + half) >> bits, c[x]));
}

// dst[x] += scale_down_row's output, saturating.
CODEC_ROW_CLONES void add_scaled_down_row(const int32_t* from, int32_t* dst, int n, int bits) {
  if (bits == 0) {
    for (int x = 0; x < n; ++x) dst[x] = saturating_add(dst[x], from[x]);
    return;
  }
  const uint32_t half = uint32_t(1) << (bits - 1);
  for (int x = 0; x < n; ++x) dst[x] = saturating_add(dst[x], int32_t(uint32_t(from[x]) + half) >> bits);
}

inline int64_t floor_div(int64_t a, int64_t b) {
  const int64_t q = a / b;
  return (a % b != 0 && ((a < 0) != (b < 0))) ? q - 1 : q;
}

// Transform-mode payload with the residual transform (lifting) or the lapped one; leaves the decoder's
// output in work.reconstruction.
size_t encode_transform(const int32_t* src, ptrdiff_t stride, int w, int h, const TileParams& params,
                        TileWork& work, uint8_t* out, size_t capacity, bool want_reconstruction,
                        bool lifting) {
  const size_t head = params.bound_max_error ? 1 : 0;  // mode byte
  if (capacity < head) return 0;
  const int pw = padded_side(w), ph = padded_side(h);
  int32_t* tile = work.coefficients.data();
  if (head) out[0] = uint8_t(TileMode::Transform);
  BitWriter bits(out + head, capacity - head);
  if (params.lifting) bits.put_bit(lifting ? 0 : 1);
  // The residual transform works on the w x h tile itself (no padding to macroblocks).
  const int tile_stride = lifting ? w : pw;
  if (lifting) {
    load_padded(src, stride, w, h, w, h, params.fraction_bits, tile);
    forward_lifting(tile, w, h, work.lifting_scratch.data());
    code_lifting_bands(bits, tile, w, h, params.lifting_steps, work.sequence.data());
  } else {
    load_padded(src, stride, w, h, pw, ph, params.fraction_bits, tile);
    forward_lapped(tile, pw, ph, params.fraction_bits > 0);
    code_bands(bits, tile, pw, ph, params.steps, work.sequence.data());
  }
  if (!want_reconstruction && !params.bound_max_error) {
    const size_t size = bits.finish();
    return bits.overflow() ? 0 : size + head;
  }
  if (lifting) {
    dequantize_lifting(tile, w, h, params.lifting_steps);
    inverse_lifting(tile, w, h, work.lifting_scratch.data());
  } else {
    dequantize_tile(tile, pw, ph, params.steps);
    inverse_lapped(tile, pw, ph, params.fraction_bits > 0);
  }
  int32_t* recon = work.reconstruction.data();
  for (int y = 0; y < h; ++y)
    scale_down_row(tile + size_t(y) * tile_stride, recon + size_t(y) * w, w, params.fraction_bits);
  if (params.bound_max_error) {
    const int64_t e = params.max_error;
    int32_t* corrections = work.sequence.data();
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const int64_t r = int64_t(src[y * stride + x]) - recon[size_t(y) * w + x];
        const int64_t v = r > e ? r - e : r < -e ? r + e : 0;
        corrections[size_t(y) * w + x] = int32_t(v);
        recon[size_t(y) * w + x] = int32_t(recon[size_t(y) * w + x] + v);
      }
    RlgrState state;
    rlgr_encode(bits, corrections, size_t(w) * h, state);
  }
  const size_t size = bits.finish();
  return bits.overflow() ? 0 : size + head;
}

// Spatial-quantisation payload (max-error mode): q = floor((x + E) / (2E + 1)) coded losslessly.
size_t encode_spatial(const int32_t* src, ptrdiff_t stride, int w, int h, const TileParams& params,
                      TileWork& work, uint8_t* out, size_t capacity) {
  if (capacity < 1) return 0;
  const int pw = padded_side(w), ph = padded_side(h);
  const int64_t e = params.max_error, bin = 2 * e + 1;
  int32_t* quantized = work.reconstruction.data();  // reused as input, rewritten below
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      quantized[size_t(y) * w + x] = int32_t(floor_div(src[y * stride + x] + e, bin));
  out[0] = uint8_t(TileMode::SpatialQuantized);
  BitWriter bits(out + 1, capacity - 1);
  int32_t* tile = work.coefficients.data();
  load_padded(quantized, w, w, h, pw, ph, 0, tile);
  forward_lapped(tile, pw, ph, false);
  code_bands(bits, tile, pw, ph, unit_band_steps(), work.sequence.data());
  for (size_t i = 0; i < size_t(w) * h; ++i) quantized[i] = saturate(int64_t(quantized[i]) * bin);
  const size_t size = bits.finish();
  return bits.overflow() ? 0 : size + 1;
}

double squared_error(const int32_t* src, ptrdiff_t stride, int w, int h, const int32_t* recon) {
  double sum = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double e = double(src[y * stride + x]) - double(recon[size_t(y) * w + x]);
      sum += e * e;
    }
  return sum;
}

// Format 5 transform-mode tiles: both transforms are tried and the tile keeps the lower cost
// bits + lambda * squared error, lambda = 6 / (ln 2 * S^2) bits per squared sample unit, the slope of
// an entropy-coded uniform quantiser's rate-distortion curve at step S (lossless: fewer bytes win).
// The residual transform wins on rough residuals and small steps, the lapped one on smooth residuals
// at large steps (measured: docs/codec.md "Residual transform").
size_t encode_either_transform(const int32_t* src, ptrdiff_t stride, int w, int h, const TileParams& params,
                               TileWork& work, uint8_t* out, size_t capacity) {
  const size_t samples = size_t(w) * h;
  const size_t a = encode_transform(src, stride, w, h, params, work, out, capacity, true, true);
  // Above one bit per sample the lapped transform never won in the measurements (its wins are smooth
  // tiles at large steps, well below it), so those tiles keep the residual transform, the lapped one
  // untried (the same files within 0.1 %, a third less coding time).
  if (a > 0 && a * 8 > samples) return a;
  if (work.candidate.size() < samples) work.candidate.resize(samples);
  std::copy_n(work.reconstruction.begin(), samples, work.candidate.begin());
  if (work.second.size() < work.alternative.size()) work.second.resize(work.alternative.size());
  const size_t b =
      encode_transform(src, stride, w, h, params, work, work.second.data(), work.second.size(), true, false);
  const auto cost = [&](size_t bytes, const int32_t* recon) {
    if (params.fraction_bits == 0 || params.bound_max_error) return double(bytes);
    return 8.0 * double(bytes) + params.lambda * squared_error(src, stride, w, h, recon);
  };
  if (b == 0 || (a > 0 && cost(a, work.candidate.data()) <= cost(b, work.reconstruction.data()))) {
    std::copy_n(work.candidate.begin(), samples, work.reconstruction.begin());
    return a;
  }
  if (b > capacity) return 0;
  std::memcpy(out, work.second.data(), b);
  return b;
}

}  // namespace

void TileWork::reserve(int pw, int ph, size_t reconstruction_samples, size_t payload_bound) {
  const size_t padded = size_t(pw) * ph;
  if (coefficients.size() < padded) coefficients.resize(padded);
  if (sequence.size() < padded) sequence.resize(padded);  // also the decoder's correction layer (w x h)
  if (reconstruction.size() < reconstruction_samples) reconstruction.resize(reconstruction_samples);
  if (alternative.size() < payload_bound) alternative.resize(payload_bound);
  if (lifting_scratch.size() < lifting_scratch_size(pw, ph))
    lifting_scratch.resize(lifting_scratch_size(pw, ph));
}

size_t tile_payload_bound(int width, int height) {
  const size_t padded = size_t(padded_side(width)) * padded_side(height);
  const size_t codes = padded + size_t(width) * height;  // coefficients + corrections
  return std::max(1 + codes * (kRlgrMaxCodeBits / 8) + 8, phase_payload_bound(width, height));
}

size_t encode_tile(const int32_t* src, ptrdiff_t src_stride, int w, int h, const TileParams& params,
                   TileWork& work, uint8_t* out, size_t capacity, bool want_reconstruction,
                   const PhaseReplay* replay) {
  work.reserve(padded_side(w), padded_side(h), size_t(w) * h,
               params.bound_max_error || params.lifting ? tile_payload_bound(w, h) : 0);
  size_t phase_size = SIZE_MAX;
  // Phase tiles, where the stream has them: in rms streams every tile is one. In max-error streams a
  // phase tile that skipped its even phase (a point-sampled pyramid's residual) is kept as it is:
  // trying the transform modes as well (kept when smaller) saved 0.00-0.11 % of the file (13 DEMs x
  // lossless, max error 1, 2, 5 m: 1643 bytes over 36 files) and doubled the encoder's time. Tiles
  // that code their even phase (a coarsest level, data that is no such residual) try them too.
  if (params.phase) {
    size_t size = SIZE_MAX;
    if (replay) {
      size = encode_phase_recorded(*replay->record, replay->tile, *params.phase_tables, out, capacity,
                                   work.phase_work);
      for (int y = 0; y < h; ++y)
        std::copy_n(replay->recon + y * replay->recon_stride, w,
                    work.reconstruction.begin() + ptrdiff_t(y) * w);
    } else {
      size = encode_phase(src, src_stride, w, h, params.phase_bin_q8, *params.phase_tables, out, capacity,
                          work.reconstruction.data(), work.phase_work);
    }
    if (!params.bound_max_error) return size == SIZE_MAX ? 0 : size;
    if (size != SIZE_MAX && !work.phase_work.even_phase_coded) return size;
    if (size != SIZE_MAX) {  // the candidate to beat, set aside
      const size_t samples = size_t(w) * h;
      if (work.phase_recon.size() < samples) work.phase_recon.resize(samples);
      std::copy_n(work.reconstruction.begin(), samples, work.phase_recon.begin());
      work.phase_payload.assign(out, out + size);
      phase_size = size;
    }
  }
  if (params.lifting && !params.bound_max_error)
    return encode_either_transform(src, src_stride, w, h, params, work, out, capacity);
  if (!params.bound_max_error)
    return encode_transform(src, src_stride, w, h, params, work, out, capacity, want_reconstruction, false);
  // Max-error mode: try spatial quantisation first (into the side buffer), then the transform with
  // corrections (into out, leaving its reconstruction in work); keep the smaller.
  const size_t spatial =
      encode_spatial(src, src_stride, w, h, params, work, work.alternative.data(), work.alternative.size());
  assert(spatial > 0);
  const size_t transform =
      params.lifting ? encode_either_transform(src, src_stride, w, h, params, work, out, capacity)
                     : encode_transform(src, src_stride, w, h, params, work, out, capacity, true, false);
  const size_t best = transform > 0 && transform <= spatial ? transform : spatial;
  if (phase_size < best) {
    std::memcpy(out, work.phase_payload.data(), phase_size);
    std::copy_n(work.phase_recon.begin(), size_t(w) * h, work.reconstruction.begin());
    return phase_size;
  }
  if (best == transform) return transform;
  if (spatial > capacity) return 0;
  std::memcpy(out, work.alternative.data(), spatial);
  // Rebuild the spatial reconstruction, which encode_transform overwrote.
  const int64_t e = params.max_error, bin = 2 * e + 1;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      work.reconstruction[size_t(y) * w + x] = saturate(floor_div(src[y * src_stride + x] + e, bin) * bin);
  return spatial;
}

TileResult decode_tile(const uint8_t* payload, size_t size, int w, int h, const TileParams& params,
                       TileWork& work, const TileWindow& window) {
  assert(0 <= window.x0 && window.x0 < window.x1 && window.x1 <= w && 0 <= window.y0 &&
         window.y0 < window.y1 && window.y1 <= h);
  const size_t head = params.bound_max_error ? 1 : 0;  // mode byte
  if (size < 1) return TileResult::Corrupt;
  const int pw = padded_side(w), ph = padded_side(h);
  work.reserve(pw, ph, window.add ? size_t(w) : 0, 0);
  const uint8_t mode = head ? payload[0] : uint8_t(TileMode::Transform);
  if (params.phase && (!params.bound_max_error || is_phase_mode(mode))) {
    const size_t samples = size_t(w) * h;
    if (work.phase_recon.size() < samples) work.phase_recon.resize(samples);
    int32_t* recon = work.phase_recon.data();
    if (!decode_phase(payload, size, w, h, params.phase_bin_q8, *params.phase_tables, recon, work.phase_work))
      return TileResult::Corrupt;
    const int n = window.x1 - window.x0;
    for (int y = window.y0; y < window.y1; ++y) {
      const int32_t* from = recon + size_t(y) * w + window.x0;
      int32_t* dst = window.dst + ptrdiff_t(y - window.y0) * window.stride;
      if (window.add)
        add_row(from, dst, n);
      else
        std::copy_n(from, n, dst);
    }
    return TileResult::Ok;
  }
  const bool spatial = mode == uint8_t(TileMode::SpatialQuantized);
  if (mode != uint8_t(TileMode::Transform) && !spatial) return TileResult::Corrupt;
  BitReader bits(payload + head, size - head);
  int32_t* tile = work.coefficients.data();
  if (window.add)  // the caller's samples, usually just written and evicted from L1: loaded while RLGR runs
    for (int y = window.y0; y < window.y1; ++y) {
      const int32_t* row = window.dst + ptrdiff_t(y - window.y0) * window.stride;
      for (int x = 0; x < window.x1 - window.x0; x += 16) __builtin_prefetch(row + x, 1, 3);
    }
  static const BandSteps unit_steps = unit_band_steps();
  bool lifting = false;
  if (params.lifting && !spatial) {
    bits.refill();
    lifting = bits.take(1) == 0;
  }
  if (lifting ? !decode_lifting_bands(bits, tile, w, h, params.lifting_steps)
              : !decode_bands(bits, tile, pw, ph, spatial ? unit_steps : params.steps, work))
    return TileResult::Corrupt;
  const bool corrected = !spatial && params.bound_max_error;
  const int32_t* corrections = work.sequence.data();
  if (corrected) {  // the correction layer follows the bands; decoded whole, added inside the window
    RlgrState state;
    if (!rlgr_decode(bits, work.sequence.data(), size_t(w) * h, state)) return TileResult::Corrupt;
  }
  if (bits.overrun()) return TileResult::Corrupt;
  if (lifting)
    inverse_lifting(tile, w, h, work.lifting_scratch.data());
  else
    inverse_lapped(tile, pw, ph, !spatial && params.fraction_bits > 0);
  const int tile_stride = lifting ? w : pw;
  // Straight from the tile into the caller's window: no intermediate copy (add mode: in one pass for
  // transform tiles; spatial ones through one row, then added).
  const int64_t bin = 2 * int64_t(params.max_error) + 1;
  const int n = window.x1 - window.x0;
  int32_t* row = work.reconstruction.data();
  for (int y = window.y0; y < window.y1; ++y) {
    const int32_t* from = tile + size_t(y) * tile_stride + window.x0;
    int32_t* dst = window.dst + ptrdiff_t(y - window.y0) * window.stride;
    if (window.add && !spatial) {  // without the row
      if (corrected)
        add_corrected_row(from, corrections + size_t(y) * w + window.x0, dst, n, params.fraction_bits);
      else
        add_scaled_down_row(from, dst, n, params.fraction_bits);
      continue;
    }
    int32_t* to = window.add ? row : dst;
    if (spatial) {
      spatial_row(from, to, n, bin);
    } else {
      scale_down_row(from, to, n, params.fraction_bits);
      if (corrected) add_row(corrections + size_t(y) * w + window.x0, to, n);
    }
    if (window.add) add_row(to, dst, n);
  }
  return TileResult::Ok;
}

}  // namespace codec::detail
