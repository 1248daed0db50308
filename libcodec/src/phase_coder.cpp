// Phase-mode tiles: polyphase prediction, near-lossless quantisation, static token tables and rANS.
// One traversal (code_tile) serves the statistics pass, the encoder and the decoder, so their orders,
// predictions and contexts cannot drift apart.
#include "codec/internal/phase_coder.h"

#include <algorithm>
#include <bit>

#include "codec/internal/tile_coder.h"

namespace codec::detail {
namespace {

constexpr int64_t kLimit = int64_t(1) << 30;  // decoded samples beyond +-2^30 mean a damaged payload
constexpr int kMemberBits = 10;
static_assert(kFamilySize <= (1 << kMemberBits));
// Mode byte 2 + k0 + 5 k1: the final states in k0 and k1 (0 .. 4) bytes; k1 = 0 with one lane.
constexpr uint8_t kPhaseModeFirst = uint8_t(TileMode::Phase);
constexpr int kMaxStateBytes = 4;
constexpr uint8_t kPhaseModeLast = kPhaseModeFirst + (kMaxStateBytes + 1) * (kMaxStateBytes + 1) - 1;

// The statistics pass: counts tokens, codes nothing; with a record, also keeps each level's symbol
// (and raw magnitude) for encode_phase_recorded.
struct CountIo {
  static constexpr bool kDecoding = false;
  PhaseCounts* counts;
  PhaseRecord* record;
  bool bad = false;
  bool flag(bool b) { return b; }
  int64_t level(int context, int64_t q) {
    int raw = 0;
    const uint32_t m = uint32_t(q < 0 ? -q : q);
    const int token = token_of(m, &raw);
    ++counts->counts[context][token];
    if (record) {
      record->symbols.push_back(uint16_t(context << 8 | symbol_of(token, q)));
      if (raw) record->raws.push_back(m);
    }
    return q;
  }
};

// One level's codes (the symbol or the escape, then the raw bits): shared by the encoder and the replay.
inline void put_level(RansEncoder& rans, const TokenTable& t, int symbol, uint32_t m, int raw) {
  if (t.freq[symbol]) {
    rans.put(t.cum[symbol], t.freq[symbol]);
  } else {
    rans.put(t.cum[kTokenEscape], t.freq[kTokenEscape]);
    rans.put_raw(uint32_t(symbol), kTokenEscapeBits);
  }
  if (raw) rans.put_raw(m, raw);
}

struct EncodeIo {
  static constexpr bool kDecoding = false;
  const PhaseTables* tables;
  RansEncoder* rans;
  bool bad = false;
  bool flag(bool b) {
    rans->put_raw(b, 1);
    return b;
  }
  int64_t level(int context, int64_t q) {
    const uint32_t m = uint32_t(q < 0 ? -q : q);
    int raw = 0;
    const int symbol = symbol_of(token_of(m, &raw), q);  // sets raw: not in put_level's arguments
    put_level(*rans, *tables->table[context], symbol, m, raw);
    return q;
  }
};

// Symbols below this have at most kRansMaxRawBits raw bits (tokens up to 35).
constexpr int kOneChunkSymbols = 71;
static_assert(kOneChunkSymbols < kTokenEscape);

// The decoder's levels with more raw bits, and the escape: apart from the hot path, and by value, so
// that the caller's rANS state can live in registers (an escaping address kept it in memory).
template <int kLanes> struct LargeLevel {
  RansDecoder<kLanes> rans;
  int64_t level;
  bool bad;
};
template <int kLanes> [[gnu::noinline]] LargeLevel<kLanes> large_level(RansDecoder<kLanes> rans, int symbol) {
  if (symbol == kTokenEscape) {
    symbol = int(rans.raw(kTokenEscapeBits));
    if (symbol >= kTokenEscape) return {rans, 0, true};
  }
  const int token = (symbol + 1) >> 1;
  int64_t m = token;
  if (token >= 16) {
    int raw = 0;
    m = token_base(token, &raw) | rans.raw(raw);
  }
  return {rans, symbol & 1 ? m : -m, false};
}

template <int kLanes> struct DecodeIo {
  static constexpr bool kDecoding = true;
  const PhaseTables* tables;
  RansDecoder<kLanes> rans;
  bool bad = false;
  bool flag(bool) { return rans.raw(1) != 0; }
  [[gnu::always_inline]] int64_t level(int context, int64_t) {
    const uint32_t slot = rans.slot();
    const int symbol = tables->slots[context][slot];
    const uint32_t fc = tables->freq_cum[context][symbol];
    rans.step(fc & 0xffff, slot - (fc >> 16));
    int64_t m = (symbol + 1) >> 1;  // the token
    if (symbol >= kSmallSymbols) {
      if (symbol >= kOneChunkSymbols) {
        const LargeLevel<kLanes> large = large_level(rans, symbol);
        rans = large.rans;
        bad = bad || large.bad;
        return large.level;
      }
      // At most 12 raw bits (one rANS step): inline, as lossless levels of rough terrain often are.
      int raw = 0;
      const uint32_t base = token_base(int(m), &raw);
      m = base | rans.raw(raw);
    }
    // Odd symbols are positive, even ones negative: negated without a branch (the sign is random).
    const int64_t negative = (symbol & 1) - 1;
    return (m ^ negative) - negative;
  }
};

int64_t floor_div(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

// The level magnitudes live in a (w + 4) x (h + 4) array with a border of 2 zeros, so the context
// needs no edge tests: outside the tile counts as 0, like samples not yet coded.
constexpr int kBorder = 2;

// Activity around the sample at `l` (row stride s): the sum of the level magnitudes of its 8
// neighbours and of the three at distance 2 above, (x-2, y-2), (x, y-2), (x+2, y-2). None of them is
// in the sample's own row and phase, so consecutive levels of a phase depend on each other only
// through the rANS state (with (x-2, y) in the sum instead, files were 0.5-0.7 % smaller and the
// decoder 1.35x slower). The code leaves out the neighbours that `phase`'s order guarantees to be 0
// (not yet coded: phases 0, 1, 2, 3 read 3, 5, 9 and 11 levels), which gives the same sums.
template <int phase> [[gnu::always_inline]] inline int context_class(const int32_t* l, ptrdiff_t s) {
  const auto at = [&](ptrdiff_t d) { return uint32_t(l[d]); };
  uint32_t a = at(-2 * s - 2) + at(-2 * s) + at(-2 * s + 2);  // the same phase, two rows up
  if constexpr (phase == 1) a += at(-1) + at(1);              // phase 0 beside it
  if constexpr (phase == 2) a += at(-s - 1) + at(-s + 1) + at(s - 1) + at(s + 1) + at(-s) + at(s);  // 1 and 0
  if constexpr (phase == 3)
    a += at(-s - 1) + at(-s) + at(-s + 1) + at(-1) + at(1) + at(s - 1) + at(s) + at(s + 1);  // 0, 1 and 2
  // bit_width(a) as the top bit of 2a + 1 (a < 2^24), which is never 0: bit_width itself compiled to
  // a branch on a == 0, as unpredictable as the terrain.
  return std::min(kPhaseClasses - 1, 31 - std::countl_zero(2 * a + 1));
}

// Prediction of (x, y) in `phase` from decoded samples (recon, row stride w).
template <int phase>
[[gnu::always_inline]] inline int64_t predict(const int32_t* r, int w, int h, int x, int y) {
  const auto at = [&](int xx, int yy) { return int64_t(r[size_t(yy) * w + xx]); };
  switch (phase) {
    case 0: {  // even-even, when coded: MED of its even-even neighbours
      if (x < 2 && y < 2) return 0;
      if (y < 2) return at(x - 2, y);
      if (x < 2) return at(x, y - 2);
      const int64_t a = at(x - 2, y), b = at(x, y - 2), c = at(x - 2, y - 2);
      if (c >= std::max(a, b)) return std::min(a, b);
      if (c <= std::min(a, b)) return std::max(a, b);
      return a + b - c;
    }
    case 1: {  // odd column, even row: between its left and right neighbours
      const int64_t a = at(x - 1, y), b = x + 1 < w ? at(x + 1, y) : a;
      return (a + b) >> 1;  // floor
    }
    case 2: {  // even column, odd row: between the rows above and below
      const int64_t a = at(x, y - 1), b = y + 1 < h ? at(x, y + 1) : a;
      return (a + b) >> 1;  // floor
    }
    default: {  // odd-odd: the mean of its four direct neighbours (phases 1 and 2), rounded half up
      int64_t sum = at(x - 1, y) + at(x, y - 1);
      int n = 2;
      if (x + 1 < w) sum += at(x + 1, y), ++n;
      if (y + 1 < h) sum += at(x, y + 1), ++n;
      return n == 4 ? (2 * sum + 4) >> 3 : floor_div(2 * sum + n, 2 * n);  // floor either way
    }
  }
}

template <class Io>
bool code_tile(Io& io, const int32_t* src, ptrdiff_t stride, int w, int h, uint32_t bin_q8, int32_t* recon,
               PhaseWork& work) {
  // Bins of bin_q8 / 256 samples: q = sign(r) floor((256 |r| + bin_q8 / 2) / bin_q8), output
  // p + sign(q) floor((|q| bin_q8 + 128) / 256). With bin_q8 = 256 (2E + 1) that is exactly
  // floor((|r| + E) / (2E + 1)) and p + q (2E + 1): |error| <= E.
  // e: the largest error of a quantised sample, which an even sample may have to be skipped: half a
  // bin, plus the output's rounding when the bin is not a whole number of samples.
  // Whole-number bins (max-error streams) keep the plain multiply: the general output rounding cost
  // the decoder a third of its speed (Rainier --max-error 2: 106 -> 68 Ms/s).
  const int64_t bin = bin_q8, whole_bin = bin_q8 % 256 == 0 ? bin_q8 >> 8 : 0;
  const int64_t e = whole_bin ? bin_q8 >> 9 : (bin_q8 + 256) >> 9;
  const ptrdiff_t ls = w + 2 * kBorder;
  const size_t level_count = size_t(ls) * size_t(h + 2 * kBorder);
  std::vector<int32_t>& levels = work.levels;
  if (levels.size() < level_count) levels.resize(level_count);
  std::fill_n(levels.begin(), level_count, 0);
  int32_t* const level0 = levels.data() + kBorder * ls + kBorder;  // (0, 0)
  bool skip = false;
  if (!Io::kDecoding) {
    skip = true;
    for (int y = 0; y < h && skip; y += 2)
      for (int x = 0; x < w; x += 2)
        if (src[y * stride + x] < -e || src[y * stride + x] > e) {
          skip = false;
          break;
        }
  }
  skip = io.flag(skip);
  work.even_phase_coded = !skip;
  // One loop per phase, so that each has its prediction inlined without a switch.
  // Real-valued bins: the outputs of levels -15..15 from a table (the rounding, a multiply and the
  // sign cost as much again as the rest of the decoder).
  int64_t offsets[31] = {};
  if (!whole_bin)
    for (int k = -15; k <= 15; ++k)
      offsets[k + 15] = (k < 0 ? -1 : 1) * ((int64_t(k < 0 ? -k : k) * bin + 128) >> 8);
  // Each phase works on a copy of io, which the compiler keeps in registers, and hands it back after.
  const auto run = [&]<int phase, bool whole>() {
    constexpr int px = phase & 1, py = phase >> 1;
    Io local = io;
    for (int y = py; y < h; y += 2)
      for (int x = px; x < w; x += 2) {
        int32_t* out = &recon[size_t(y) * w + x];
        const int64_t p = predict<phase>(recon, w, h, x, y);
        int32_t* const l = level0 + ptrdiff_t(y) * ls + x;
        const int context = phase * kPhaseClasses + context_class<phase>(l, ls);
        int64_t q = 0;
        if (!Io::kDecoding) {
          const int64_t r = int64_t(src[y * stride + x]) - p;
          q = r >= 0 ? (256 * r + bin / 2) / bin : -((-256 * r + bin / 2) / bin);
        }
        q = local.level(context, q);
        int64_t v = 0;
        if constexpr (whole) {
          v = p + q * whole_bin;
        } else if (q >= -15 && q <= 15) {
          v = p + offsets[q + 15];
        } else {
          const int64_t step = ((q < 0 ? -q : q) * bin + 128) >> 8;
          v = q < 0 ? p - step : p + step;
        }
        if (local.bad || v < -kLimit || v > kLimit) return false;
        *out = int32_t(v);
        *l = int32_t(std::min<int64_t>(q < 0 ? -q : q, 1 << 20));
      }
    io = local;
    return true;
  };
  const auto run_all = [&]<bool whole>() {
    if (skip) {
      for (int y = 0; y < h; y += 2)
        for (int x = 0; x < w; x += 2) recon[size_t(y) * w + x] = 0;
    } else if (!run.template operator()<0, whole>()) {
      return false;
    }
    return run.template operator()<1, whole>() && run.template operator()<2, whole>() &&
           run.template operator()<3, whole>();
  };
  return whole_bin ? run_all.template operator()<true>() : run_all.template operator()<false>();
}

}  // namespace

PhaseModel fit_phase_model(const PhaseCounts& counts) {
  PhaseModel model;
  for (int c = 0; c < kPhaseContexts; ++c) {
    const uint32_t* k = counts.counts[c];
    model.used[c] = std::any_of(k, k + kTokens, [](uint32_t n) { return n != 0; });
    if (model.used[c]) model.member[c] = uint16_t(best_member(k));
  }
  return model;
}

size_t write_phase_model(const PhaseModel& model, uint8_t* out) {
  uint64_t acc = 0;
  int bits = 0;
  size_t n = 0;
  const auto put = [&](uint32_t v, int nbits) {
    acc = (acc << nbits) | v;
    bits += nbits;
    while (bits >= 8) out[n++] = uint8_t(acc >> (bits -= 8));
  };
  for (int c = 0; c < kPhaseContexts; ++c) put(model.used[c], 1);
  for (int c = 0; c < kPhaseContexts; ++c)
    if (model.used[c]) put(model.member[c], kMemberBits);
  if (bits > 0) out[n++] = uint8_t(acc << (8 - bits));
  return n;
}

bool read_phase_model(const uint8_t*& p, const uint8_t* end, PhaseModel* model) {
  uint64_t acc = 0;
  int bits = 0;
  const auto get = [&](int nbits, uint32_t* v) {
    while (bits < nbits) {
      if (p == end) return false;
      acc = (acc << 8) | *p++;
      bits += 8;
    }
    *v = uint32_t(acc >> (bits - nbits)) & ((1u << nbits) - 1);
    bits -= nbits;
    return true;
  };
  PhaseModel m;
  uint32_t v = 0;
  for (int c = 0; c < kPhaseContexts; ++c) {
    if (!get(1, &v)) return false;
    m.used[c] = v != 0;
  }
  for (int c = 0; c < kPhaseContexts; ++c)
    if (m.used[c]) {
      if (!get(kMemberBits, &v) || v >= uint32_t(kFamilySize)) return false;
      m.member[c] = uint16_t(v);
    }
  if (bits > 0 && (acc & ((uint64_t(1) << bits) - 1)) != 0) return false;  // padding must be 0
  *model = m;
  return true;
}

PhaseTables::PhaseTables(const PhaseModel& model) : lanes(model.lanes) {
  for (int c = 0; c < kPhaseContexts; ++c) {
    table[c] = &token_table(model.used[c] ? model.member[c] : 0);
    slots[c] = table[c]->slots;
    freq_cum[c] = table[c]->freq_cum;
  }
}

size_t phase_payload_bound(int w, int h) {
  // Escape (12 bits) + token (7) + 31 raw bits + sign per sample, the flag, the state and mode byte.
  return size_t(w) * h * 7 + 16;
}

bool is_phase_mode(uint8_t mode) { return mode >= kPhaseModeFirst && mode <= kPhaseModeLast; }

bool phase_statistics(const int32_t* src, ptrdiff_t stride, int w, int h, uint32_t bin_q8, int32_t* recon,
                      PhaseWork& work, PhaseCounts* counts, PhaseRecord* record, size_t tile) {
  CountIo io{counts, record};
  if (!record) return code_tile(io, src, stride, w, h, bin_q8, recon, work);
  PhaseRecord::Tile& t = record->tiles[tile];
  t.first_symbol = record->symbols.size();
  t.first_raw = record->raws.size();
  const bool ok = code_tile(io, src, stride, w, h, bin_q8, recon, work);
  t.symbols = uint32_t(record->symbols.size() - t.first_symbol);
  t.skip = !work.even_phase_coded;
  t.recorded = ok;
  return ok;
}

namespace {

// The payload of the tile whose codes are in work.rans: mode byte, final states, words.
size_t write_phase_payload(int lanes, PhaseWork& work, uint8_t* out, size_t capacity) {
  uint32_t states[2] = {1, 1};
  work.rans.finish(lanes, states, work.words);
  int bytes[2] = {};
  for (int k = 0; k < 2; ++k) bytes[k] = states[k] == 1 ? 0 : (std::bit_width(states[k]) + 7) / 8;
  const size_t size = 1 + size_t(bytes[0] + bytes[1]) + 2 * work.words.size();
  if (size > capacity) return SIZE_MAX;
  out[0] = uint8_t(kPhaseModeFirst + bytes[0] + (kMaxStateBytes + 1) * bytes[1]);
  uint8_t* p = out + 1;
  for (int k = 0; k < 2; ++k)
    for (int i = 0; i < bytes[k]; ++i) *p++ = uint8_t(states[k] >> (8 * i));
  for (uint16_t word : work.words) {
    *p++ = uint8_t(word);
    *p++ = uint8_t(word >> 8);
  }
  return size;
}

}  // namespace

size_t encode_phase(const int32_t* src, ptrdiff_t stride, int w, int h, uint32_t bin_q8,
                    const PhaseTables& tables, uint8_t* out, size_t capacity, int32_t* recon,
                    PhaseWork& work) {
  work.rans.clear();
  EncodeIo io{&tables, &work.rans};
  if (!code_tile(io, src, stride, w, h, bin_q8, recon, work)) return SIZE_MAX;
  return write_phase_payload(tables.lanes, work, out, capacity);
}

size_t encode_phase_recorded(const PhaseRecord& record, size_t tile, const PhaseTables& tables, uint8_t* out,
                             size_t capacity, PhaseWork& work) {
  const PhaseRecord::Tile& t = record.tiles[tile];
  work.rans.clear();
  work.rans.put_raw(t.skip, 1);
  work.even_phase_coded = !t.skip;
  const uint32_t* raw_value = record.raws.data() + t.first_raw;
  const uint16_t* code = record.symbols.data() + t.first_symbol;
  for (uint32_t i = 0; i < t.symbols; ++i) {
    const int symbol = code[i] & 0xff;
    const int token = (symbol + 1) >> 1;
    int raw = 0;
    uint32_t m = 0;
    if (token >= 16) token_base(token, &raw), m = *raw_value++;
    put_level(work.rans, *tables.table[code[i] >> 8], symbol, m, raw);
  }
  return write_phase_payload(tables.lanes, work, out, capacity);
}

bool decode_phase(const uint8_t* data, size_t size, int w, int h, uint32_t bin_q8, const PhaseTables& tables,
                  int32_t* recon, PhaseWork& work) {
  if (size < 1 || !is_phase_mode(data[0])) return false;
  const int mode = data[0] - kPhaseModeFirst;
  const size_t bytes[2] = {size_t(mode % (kMaxStateBytes + 1)), size_t(mode / (kMaxStateBytes + 1))};
  if ((tables.lanes == 1 && bytes[1] != 0) || size < 1 + bytes[0] + bytes[1] ||
      (size - 1 - bytes[0] - bytes[1]) % 2 != 0)
    return false;
  uint32_t states[2] = {1, 1};
  const uint8_t* p = data + 1;
  for (int k = 0; k < 2; ++k) {
    if (bytes[k] == 0) continue;
    uint32_t state = 0;
    for (size_t i = 0; i < bytes[k]; ++i) state |= uint32_t(*p++) << (8 * i);
    if (state >> (8 * (bytes[k] - 1)) == 0 || state == 1) return false;  // not the shortest form
    states[k] = state;
  }
  const size_t words = (size - size_t(p - data)) / 2;
  if (tables.lanes == 2) {
    DecodeIo<2> io{&tables, RansDecoder<2>(states, p, words)};
    return code_tile(io, nullptr, 0, w, h, bin_q8, recon, work) && io.rans.finished();
  }
  DecodeIo<1> io{&tables, RansDecoder<1>(states, p, words)};
  return code_tile(io, nullptr, 0, w, h, bin_q8, recon, work) && io.rans.finished();
}

}  // namespace codec::detail
