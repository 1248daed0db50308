// rANS for the phase tiles: 32-bit states, 12-bit frequencies, 16-bit renormalisation; one state
// (format 7) or two interleaved lanes sharing one word stream (format 8). docs/codec.md "Phase tiles (formats
// 7 and 8)".
//
// The encoder starts each state from 1, not from the usual lower bound 2^16: while a state is small
// it emits nothing, so a tile's first symbols cost no flush, and the final states are stored in as few
// bytes as they need (tiles of 32 x 32 samples are small enough for a fixed 4-byte flush to matter).
// The decoder mirrors this by reading a word only while words remain, and a well-formed payload
// ends with every state back at its start and every word read. Symbols are (cumulative frequency,
// frequency) pairs; raw bits are symbols of frequency 2^(12 - n).
//
// Two lanes: the k-th operation (symbol or raw chunk) of a tile uses state k mod 2, so consecutive
// decodes do not wait for each other (one state's decode is a chain of dependent loads and a
// multiply). The shared word stream stays in step with "read while words remain" only if no state is
// still below 2^16 (growing from 1) at a position where a word remains to be read; the encoder checks
// that and otherwise codes the tile again with one lane, then the other, then both starting at 2^16,
// which the decoder needs no flag for (its reads are the same rule; it accepts a final state of 1 or
// 2^16).
#pragma once

#include <cstddef>
#include <cstdint>
#include <utility>
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
  // Encodes everything on `lanes` (1 or 2) states: states[0 .. lanes) get the final states, the words
  // (decode order) go to `words`.
  void finish(int lanes, uint32_t* states, std::vector<uint16_t>& words) const {
    // The first that works: a lane from 2^16 costs 16 bits, so the growing lane alone first.
    static constexpr uint32_t kStarts[4][2] = {{1, 1}, {kRansLow, 1}, {1, kRansLow}, {kRansLow, kRansLow}};
    for (const uint32_t* start : kStarts)
      if (finish_from(start, lanes, states, words)) return;
  }

 private:
  void put_raw_chunk(uint32_t v, int n) {
    const uint32_t freq = 1u << (kRansProbBits - n);
    symbols_.push_back({uint16_t(v * freq), uint16_t(freq)});
  }
  // Codes backwards from lane k's state at start[k]; false when the decoder's "read while words
  // remain" would go wrong: a state still below 2^16 where a word (of the other lane) remains. One
  // lane, or both from 2^16, never fails.
  bool finish_from(const uint32_t* start, int lanes, uint32_t* states, std::vector<uint16_t>& words) const {
    words.clear();
    uint32_t x[2] = {start[0], start[1]};
    bool emitted = false;  // a word lies at or after this position in decode order
    for (size_t i = symbols_.size(); i-- > 0;) {
      const RansSymbol s = symbols_[i];
      uint32_t& xi = x[lanes == 2 ? i & 1 : 0];
      if (xi >= (uint64_t(s.freq) << 20)) {
        words.push_back(uint16_t(xi));
        xi >>= 16;
        emitted = true;
      } else if (xi < kRansLow && emitted) {
        return false;
      }
      xi = ((xi / s.freq) << kRansProbBits) + (xi % s.freq) + s.cum;
    }
    for (int k = 0; k < lanes; ++k) states[k] = x[k];
    for (size_t i = 0, j = words.size(); i < j / 2; ++i) std::swap(words[i], words[j - 1 - i]);
    return true;
  }
  std::vector<RansSymbol> symbols_;
};

// kLanes 1 or 2 states; with two, each operation uses the current one and then switches.
template <int kLanes> class RansDecoder {
  static_assert(kLanes == 1 || kLanes == 2);

 public:
  // states: the encoder's final states; words: `count` little-endian 16-bit words at p.
  RansDecoder(const uint32_t* states, const uint8_t* p, size_t count)
      : x_(states[0]), y_(kLanes == 2 ? states[1] : 1), p_(p), end_(p + 2 * count) {}
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
  // The payload was well formed: every state is back at its start (1, or 2^16 after the encoder's
  // fallback) and every word was read.
  bool finished() const {
    const auto start = [](uint32_t x) { return x == 1 || (kLanes == 2 && x == kRansLow); };
    return start(x_) && start(y_) && p_ == end_;
  }

 private:
  uint32_t raw_chunk(int n) {
    const int shift = kRansProbBits - n;
    const uint32_t v = slot() >> shift;
    x_ = ((x_ >> kRansProbBits) << shift) + (x_ & ((1u << shift) - 1));
    renormalise();
    return v;
  }
  // Reads a word into a state below 2^16 while words remain. One lane: as a conditional, which
  // compilers make a branch; the branch predictor's guesses then let the next symbols start early. Two
  // lanes: without a branch (whether a word is read is as unpredictable as the data, and a
  // misprediction discards the other lane's work too), the word loaded before the state is known
  // (from p_, or two zero bytes at the end), then the other lane.
  void renormalise() {
    static constexpr uint8_t kNone[2] = {0, 0};
    if constexpr (kLanes == 1) {
      if (x_ < kRansLow && p_ != end_) {
        x_ = (x_ << 16) | uint32_t(p_[0]) | uint32_t(p_[1]) << 8;
        p_ += 2;
      }
    } else {
      const uint8_t* q = p_ != end_ ? p_ : kNone;
      const uint32_t word = uint32_t(q[0]) | uint32_t(q[1]) << 8;
      const uint32_t read = uint32_t(x_ < kRansLow) & uint32_t(p_ != end_);
      x_ = (x_ << (read << 4)) | (word & (0u - read));
      p_ += 2 * read;
      std::swap(x_, y_);
    }
  }
  uint32_t x_, y_;  // the current lane's state, the other's
  const uint8_t* p_;
  const uint8_t* end_;
};

}  // namespace codec::detail
