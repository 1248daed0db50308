// rANS for the phase tiles (format 7): one 32-bit state, 12-bit frequencies, 16-bit renormalisation.
// docs/codec.md "Phase tiles (format 7)".
//
// The encoder starts from state 1, not from the usual lower bound 2^16: while the state is small it
// emits nothing, so a tile's first symbols cost no flush, and the final state is stored in as few
// bytes as it needs (tiles of 32 x 32 samples are small enough for a fixed 4-byte flush to matter).
// The decoder mirrors this by reading a word only while words remain, and a well-formed payload
// ends with state 1 and every word read. Symbols are (cumulative frequency, frequency) pairs; raw
// bits are symbols of frequency 2^(12 - n).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace codec::detail {

inline constexpr int kRansProbBits = 12;
inline constexpr uint32_t kRansLow = 1u << 16;  // decoder state lower bound (steady state)
inline constexpr int kRansMaxRawBits = 12;      // raw bits per symbol

struct RansSymbol {
  uint16_t cum, freq;
};

// Collects symbols in coding order, then encodes them backwards.
class RansEncoder {
 public:
  void clear() { symbols_.clear(); }
  void put(uint32_t cum, uint32_t freq) { symbols_.push_back({uint16_t(cum), uint16_t(freq)}); }
  // n (0 .. 32) raw bits of v, most significant chunk first.
  void put_raw(uint32_t v, int n) {
    while (n > kRansMaxRawBits) {
      n -= kRansMaxRawBits;
      put_raw_chunk((v >> n) & ((1u << kRansMaxRawBits) - 1), kRansMaxRawBits);
    }
    if (n > 0) put_raw_chunk(v & ((1u << n) - 1), n);
  }
  // Encodes everything: *state gets the final state, words (decode order) are written to `words`.
  void finish(uint32_t* state, std::vector<uint16_t>& words) const {
    words.clear();
    uint32_t x = 1;
    for (size_t i = symbols_.size(); i-- > 0;) {
      const RansSymbol s = symbols_[i];
      if (x >= (uint64_t(s.freq) << 20)) {
        words.push_back(uint16_t(x));
        x >>= 16;
      }
      x = ((x / s.freq) << kRansProbBits) + (x % s.freq) + s.cum;
    }
    *state = x;
    for (size_t i = 0, j = words.size(); i < j / 2; ++i) std::swap(words[i], words[j - 1 - i]);
  }

 private:
  void put_raw_chunk(uint32_t v, int n) {
    const uint32_t freq = 1u << (kRansProbBits - n);
    symbols_.push_back({uint16_t(v * freq), uint16_t(freq)});
  }
  std::vector<RansSymbol> symbols_;
};

class RansDecoder {
 public:
  // words: `count` little-endian 16-bit words at p.
  RansDecoder(uint32_t state, const uint8_t* p, size_t count) : x_(state), p_(p), end_(p + 2 * count) {}
  uint32_t slot() const { return x_ & ((1u << kRansProbBits) - 1); }
  // Consumes the symbol whose slot range holds slot() (cum <= slot < cum + freq).
  void advance(uint32_t cum, uint32_t freq) { step(freq, slot() - cum); }
  // The same with the symbol's frequency and slot() - cum given.
  void step(uint32_t freq, uint32_t offset) {
    x_ = freq * (x_ >> kRansProbBits) + offset;
    renormalise();
  }
  // n (0 .. 32) raw bits, most significant chunk first.
  uint32_t raw(int n) {
    uint32_t v = 0;
    while (n > kRansMaxRawBits) {
      n -= kRansMaxRawBits;
      v = (v << kRansMaxRawBits) | raw_chunk(kRansMaxRawBits);
    }
    return n > 0 ? (v << n) | raw_chunk(n) : v;
  }
  // The payload was well formed: the state is back at 1 and every word was read.
  bool finished() const { return x_ == 1 && p_ == end_; }

 private:
  uint32_t raw_chunk(int n) {
    const int shift = kRansProbBits - n;
    const uint32_t v = slot() >> shift;
    x_ = ((x_ >> kRansProbBits) << shift) + (x_ & ((1u << shift) - 1));
    renormalise();
    return v;
  }
  // Without a branch: whether a word is read is as unpredictable as the data.
  void renormalise() {
    static constexpr uint8_t kNone[2] = {0, 0};
    const bool read = x_ < kRansLow && p_ != end_;
    const uint8_t* q = read ? p_ : kNone;
    const uint32_t next = (x_ << 16) | uint32_t(q[0]) | uint32_t(q[1]) << 8;
    x_ = read ? next : x_;
    p_ += read ? 2 : 0;
  }
  uint32_t x_;
  const uint8_t* p_;
  const uint8_t* end_;
};

}  // namespace codec::detail
