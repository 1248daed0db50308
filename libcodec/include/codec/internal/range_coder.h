// Binary adaptive range coder for the phase-mode tiles (docs/codec.md "Phase tiles (format 6)").
//
// 32-bit range, 12-bit probabilities of a 0 bit adapted by 1/16 of the distance after every bit
// (fast: the models restart with every tile), byte-wise renormalisation with a carry-propagating
// cache on the encoder side. The decoder reads past the end of its bytes as zeros, so the encoder
// ends with the shortest value inside its interval and drops trailing zero bytes: a tile whose
// decisions are all likely costs no bytes at all. The decoder never reads outside its buffer.
#pragma once

#include <cstddef>
#include <cstdint>

namespace codec::detail {

inline constexpr int kProbBits = 12;
inline constexpr uint32_t kProbOne = 1u << kProbBits;
inline constexpr int kAdaptShift = 4;
inline constexpr uint32_t kTopValue = 1u << 24;

// Probability (in 1/4096) that the next bit is 0.
struct BitModel {
  uint16_t p0 = kProbOne / 2;
};

class RangeEncoder {
 public:
  RangeEncoder(uint8_t* out, size_t capacity) : out_(out), cap_(capacity) {}

  void encode(BitModel& m, uint32_t bit) {
    const uint32_t bound = (range_ >> kProbBits) * m.p0;
    if (bit == 0) {
      range_ = bound;
      m.p0 = uint16_t(m.p0 + ((kProbOne - m.p0) >> kAdaptShift));
    } else {
      low_ += bound;
      range_ -= bound;
      m.p0 = uint16_t(m.p0 - (m.p0 >> kAdaptShift));
    }
    normalize();
  }
  // Equiprobable bits (the low bits of large magnitudes), most significant first.
  void encode_raw(uint32_t value, int nbits) {
    for (int i = nbits - 1; i >= 0; --i) {
      range_ >>= 1;
      if ((value >> i) & 1) low_ += range_;
      normalize();
    }
  }
  // Ends the stream; returns its size in bytes (0 when it did not fit: overflow()).
  size_t finish() {
    // The shortest value in [low, low + range): the multiple of the largest power of 256 there.
    for (int shift = 32; shift >= 0; shift -= 8) {
      const uint64_t unit = uint64_t(1) << shift;
      const uint64_t v = (low_ + unit - 1) & ~(unit - 1);
      if (v < low_ + range_) {
        low_ = v;
        break;
      }
    }
    for (int i = 0; i < 5; ++i) shift_low();
    size_t n = pos_;
    while (n > 0 && out_[n - 1] == 0) --n;  // the decoder reads zeros past the end
    return overflow_ ? 0 : n;
  }
  bool overflow() const { return overflow_; }

 private:
  void normalize() {
    while (range_ < kTopValue) {
      range_ <<= 8;
      shift_low();
    }
  }
  void shift_low() {
    if (uint32_t(low_) < 0xFF000000u || (low_ >> 32) != 0) {
      const uint8_t carry = uint8_t(low_ >> 32);
      if (started_) emit(uint8_t(cache_ + carry));
      started_ = true;
      for (; pending_ > 0; --pending_) emit(uint8_t(0xFF + carry));
      cache_ = uint8_t(low_ >> 24);
    } else {
      ++pending_;
    }
    low_ = (low_ & 0x00FFFFFFu) << 8;
  }
  void emit(uint8_t b) {
    if (pos_ < cap_)
      out_[pos_++] = b;
    else
      overflow_ = true;
  }

  uint8_t* out_;
  size_t cap_, pos_ = 0;
  uint64_t low_ = 0;
  uint32_t range_ = 0xFFFFFFFFu;
  uint8_t cache_ = 0;
  bool started_ = false;  // the first cache byte is always 0 and is not written
  size_t pending_ = 0;
  bool overflow_ = false;
};

class RangeDecoder {
 public:
  RangeDecoder(const uint8_t* data, size_t size) : p_(data), end_(data + size) {
    for (int i = 0; i < 4; ++i) code_ = (code_ << 8) | next();
  }

  uint32_t decode(BitModel& m) {
    const uint32_t bound = (range_ >> kProbBits) * m.p0;
    uint32_t bit;
    if (code_ < bound) {
      range_ = bound;
      m.p0 = uint16_t(m.p0 + ((kProbOne - m.p0) >> kAdaptShift));
      bit = 0;
    } else {
      code_ -= bound;
      range_ -= bound;
      m.p0 = uint16_t(m.p0 - (m.p0 >> kAdaptShift));
      bit = 1;
    }
    normalize();
    return bit;
  }
  uint32_t decode_raw(int nbits) {
    uint32_t v = 0;
    for (int i = 0; i < nbits; ++i) {
      range_ >>= 1;
      const uint32_t bit = code_ >= range_ ? 1u : 0u;
      code_ -= range_ & (0u - bit);
      v = (v << 1) | bit;
      normalize();
    }
    return v;
  }
  // A valid stream never leaves code >= range; a damaged one may (the tile is then rejected).
  bool consistent() const { return code_ < range_; }

 private:
  uint8_t next() { return p_ < end_ ? *p_++ : 0; }
  void normalize() {
    while (range_ < kTopValue) {
      range_ <<= 8;
      code_ = (code_ << 8) | next();
    }
  }

  const uint8_t* p_;
  const uint8_t* end_;
  uint32_t code_ = 0;
  uint32_t range_ = 0xFFFFFFFFu;
};

}  // namespace codec::detail
