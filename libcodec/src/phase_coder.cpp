// Phase-mode tiles: polyphase prediction, near-lossless quantisation, binary adaptive range coding.
// One traversal (code_tile) serves the encoder and the decoder, so their orders, predictions and
// contexts cannot drift apart.
#include "codec/internal/phase_coder.h"

#include <algorithm>
#include <bit>
#include <cstring>

#include "codec/internal/range_coder.h"

namespace codec::detail {
namespace {

constexpr int kClasses = 12;       // context classes: bit width of the neighbours' level magnitudes
constexpr int kLengthModels = 16;  // models for the unary bit length of a magnitude
constexpr int kMaxLength = 31;     // magnitudes below 2^32
constexpr int64_t kLimit = int64_t(1) << 30;  // decoded samples beyond +-2^30 mean a damaged payload

// Zero-flag start probabilities by context class with a bound E > 0: quiet neighbourhoods are mostly
// zero there. The models restart with every tile, so a good start saves their learning on low-rate
// tiles (smooth terrain at E = 5: 8-15 % fewer bits; lossless tiles, rarely zero, keep 1/2).
constexpr uint16_t kZeroStart[kClasses] = {3686, 3072, 2458, 2048, 2048, 2048,
                                           2048, 2048, 2048, 2048, 2048, 2048};

struct Models {
  explicit Models(bool bounded) {
    if (bounded)
      for (auto& phase : zero)
        for (int c = 0; c < kClasses; ++c) phase[c].p0 = kZeroStart[c];
  }
  BitModel skip_even;
  BitModel zero[4][kClasses];
  BitModel sign[4];
  BitModel length[kClasses][kLengthModels];
  BitModel below[kLengthModels];
};

class EncodeIo {
 public:
  EncodeIo(uint8_t* out, size_t capacity) : rc_(out, capacity) {}
  uint32_t bit(BitModel& m, uint32_t b) {
    rc_.encode(m, b);
    return b;
  }
  uint64_t raw(uint64_t value, int nbits) {
    rc_.encode_raw(uint32_t(value), nbits);
    return value;
  }
  static constexpr bool kDecoding = false;
  bool bad = false;
  RangeEncoder rc_;
};

class DecodeIo {
 public:
  DecodeIo(const uint8_t* data, size_t size) : rc_(data, size) {}
  uint32_t bit(BitModel& m, uint32_t) { return rc_.decode(m); }
  uint64_t raw(uint64_t, int nbits) { return rc_.decode_raw(nbits); }
  static constexpr bool kDecoding = true;
  bool bad = false;
  RangeDecoder rc_;
};

int64_t floor_div(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

// One quantised level: zero flag, sign, bit length in unary, the bit below the leading one, raw rest.
template <class Io> int64_t code_level(Io& io, Models& m, int phase, int ctx, int64_t q) {
  if (!io.bit(m.zero[phase][ctx], q != 0)) return 0;
  const bool negative = io.bit(m.sign[phase], q < 0) != 0;
  const uint64_t v = uint64_t(q < 0 ? -q : q);
  const int bits = Io::kDecoding ? 0 : int(std::bit_width(v)) - 1;
  int n = 0;
  while (io.bit(m.length[ctx][std::min(n, kLengthModels - 1)], n < bits)) {
    if (++n > kMaxLength) {
      io.bad = true;
      return 0;
    }
  }
  uint64_t mag = 1;
  if (n >= 1) {
    mag = 2 | io.bit(m.below[std::min(n, kLengthModels - 1)], uint32_t(v >> (n - 1)) & 1);
    if (n >= 2) mag = (mag << (n - 1)) | io.raw(v & ((uint64_t(1) << (n - 1)) - 1), n - 1);
  }
  return negative ? -int64_t(mag) : int64_t(mag);
}

// The level magnitudes live in a (w + 4) x (h + 4) array with a border of 2 zeros, so the context
// needs no edge tests: outside the tile counts as 0, like samples not yet coded.
constexpr int kBorder = 2;

// Activity around the sample at `l` (row stride s): the level magnitudes of the 8 neighbours and the
// two at distance 2 to the left and above.
int context_class(const int32_t* l, ptrdiff_t s) {
  const uint32_t a = uint32_t(l[-s - 1]) + uint32_t(l[-s]) + uint32_t(l[-s + 1]) + uint32_t(l[-1]) +
                     uint32_t(l[1]) + uint32_t(l[s - 1]) + uint32_t(l[s]) + uint32_t(l[s + 1]) +
                     uint32_t(l[-2]) + uint32_t(l[-2 * s]);
  return std::min(kClasses - 1, int(std::bit_width(a)));
}

// Prediction of (x, y) in `phase` from decoded samples (recon, row stride w).
template <int phase> int64_t predict(const int32_t* r, int w, int h, int x, int y) {
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
      return floor_div(a + b, 2);
    }
    case 2: {  // even column, odd row: between the rows above and below
      const int64_t a = at(x, y - 1), b = y + 1 < h ? at(x, y + 1) : a;
      return floor_div(a + b, 2);
    }
    default: {  // odd-odd: the mean of its four direct neighbours (phases 1 and 2), rounded half up
      int64_t sum = at(x - 1, y) + at(x, y - 1);
      int n = 2;
      if (x + 1 < w) sum += at(x + 1, y), ++n;
      if (y + 1 < h) sum += at(x, y + 1), ++n;
      return floor_div(2 * sum + n, 2 * n);
    }
  }
}

template <class Io>
bool code_tile(Io& io, const int32_t* src, ptrdiff_t stride, int w, int h, uint32_t max_error, int32_t* recon,
               int32_t* levels) {
  Models m(max_error > 0);
  const int64_t e = max_error, bin = 2 * e + 1;
  const ptrdiff_t ls = w + 2 * kBorder;
  std::memset(levels, 0, size_t(ls) * size_t(h + 2 * kBorder) * sizeof(int32_t));
  int32_t* const level0 = levels + kBorder * ls + kBorder;  // (0, 0)
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
  skip = io.bit(m.skip_even, skip) != 0;
  // One loop per phase, so that each has its prediction inlined without a switch.
  const auto run = [&]<int phase>() {
    constexpr int px = phase & 1, py = phase >> 1;
    for (int y = py; y < h; y += 2)
      for (int x = px; x < w; x += 2) {
        int32_t* out = &recon[size_t(y) * w + x];
        const int64_t p = predict<phase>(recon, w, h, x, y);
        int32_t* const l = level0 + ptrdiff_t(y) * ls + x;
        const int ctx = context_class(l, ls);
        int64_t q = 0;
        if (!Io::kDecoding) {
          const int64_t r = int64_t(src[y * stride + x]) - p;
          q = r >= 0 ? (r + e) / bin : -((-r + e) / bin);
        }
        q = code_level(io, m, phase, ctx, q);
        const int64_t v = p + q * bin;
        if (io.bad || v < -kLimit || v > kLimit) return false;
        *out = int32_t(v);
        *l = int32_t(std::min<int64_t>(q < 0 ? -q : q, 1 << 20));
      }
    return true;
  };
  if (skip) {
    for (int y = 0; y < h; y += 2)
      for (int x = 0; x < w; x += 2) recon[size_t(y) * w + x] = 0;
  } else if (!run.template operator()<0>()) {
    return false;
  }
  return run.template operator()<1>() && run.template operator()<2>() && run.template operator()<3>();
}

}  // namespace

size_t phase_payload_bound(int w, int h) { return size_t(w) * h * 9 + 16; }

size_t phase_levels_size(int w, int h) { return size_t(w + 2 * kBorder) * size_t(h + 2 * kBorder); }

size_t encode_phase(const int32_t* src, ptrdiff_t stride, int w, int h, uint32_t max_error, uint8_t* out,
                    size_t capacity, int32_t* recon, int32_t* levels) {
  EncodeIo io(out, capacity);
  if (!code_tile(io, src, stride, w, h, max_error, recon, levels)) return SIZE_MAX;
  const size_t n = io.rc_.finish();
  return io.rc_.overflow() ? SIZE_MAX : n;
}

bool decode_phase(const uint8_t* data, size_t size, int w, int h, uint32_t max_error, int32_t* recon,
                  int32_t* levels) {
  DecodeIo io(data, size);
  return code_tile(io, nullptr, 0, w, h, max_error, recon, levels) && io.rc_.consistent();
}

}  // namespace codec::detail
