// MSB-first bit writer and bounds-checked bit reader for the tile bitstreams.
//
// The writer never writes past its buffer: it sets overflow() instead. The reader never reads past
// its buffer: beyond the end it supplies zero bits and overrun() reports it, so a decoder can loop
// without checks and validate once per tile.
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>

namespace codec::detail {

class BitWriter {
 public:
  BitWriter(uint8_t* buffer, size_t capacity) : buf_(buffer), cap_(capacity) {}

  // Appends the low `nbits` bits of value (nbits <= 32, value < 2^nbits).
  void put(uint32_t value, int nbits) {
    acc_ = (acc_ << nbits) | value;
    n_ += nbits;
    if (n_ >= 32) flush32();
  }
  void put_bit(uint32_t bit) { put(bit, 1); }
  // Appends `count` one bits.
  void put_ones(int count) {
    while (count >= 32) {
      put(0xFFFFFFFFu, 32);
      count -= 32;
    }
    if (count > 0) put((1u << count) - 1, count);
  }
  // Pads to a byte boundary with zeros; returns the number of bytes written.
  size_t finish() {
    while (n_ >= 8) {
      emit(uint8_t(acc_ >> (n_ - 8)));
      n_ -= 8;
    }
    if (n_ > 0) emit(uint8_t(acc_ << (8 - n_)));
    n_ = 0;
    return pos_;
  }
  bool overflow() const { return overflow_; }
  size_t bit_count() const { return pos_ * 8 + size_t(n_); }  // bits put so far

 private:
  void flush32() {
    const uint32_t top = uint32_t(acc_ >> (n_ - 32));
    if (pos_ + 4 <= cap_) {
      buf_[pos_] = uint8_t(top >> 24);
      buf_[pos_ + 1] = uint8_t(top >> 16);
      buf_[pos_ + 2] = uint8_t(top >> 8);
      buf_[pos_ + 3] = uint8_t(top);
      pos_ += 4;
    } else {
      overflow_ = true;
    }
    n_ -= 32;
  }
  void emit(uint8_t byte) {
    if (pos_ < cap_)
      buf_[pos_++] = byte;
    else
      overflow_ = true;
  }

  uint8_t* buf_;
  size_t cap_;
  size_t pos_ = 0;
  uint64_t acc_ = 0;
  int n_ = 0;
  bool overflow_ = false;
};

class BitReader {
 public:
  BitReader(const uint8_t* data, size_t size) : begin_(data), p_(data), end_(data + size) { refill(); }

  // Guarantees at least 56 bits in the cache (zeros past the end).
  void refill() {
    if (count_ > 56 || refill_fast()) return;
    while (count_ <= 56) {
      uint64_t byte = 0;
      if (p_ < end_)
        byte = *p_++;
      else
        ++zero_bytes_;
      cache_ |= byte << (56 - count_);
      count_ += 8;
    }
  }
  // refill() while at least 8 bytes remain, without a data-dependent branch (a codeword-per-
  // iteration decoder calls it directly); the same guarantee. False: call refill() instead.
  bool refill_fast() {
    if (end_ - p_ < 8) return false;
    uint64_t v;
    std::memcpy(&v, p_, 8);
    if constexpr (std::endian::native == std::endian::little) v = __builtin_bswap64(v);
    // Bits of a partly taken byte land below count_; they are that byte's true bits, so OR-ing the
    // byte again later is harmless. Whole bytes are taken: count_ + 8 * ((63 - count_) >> 3) ==
    // count_ | 56 for count_ < 64.
    cache_ |= v >> count_;
    p_ += (63 - count_) >> 3;
    count_ |= 56;
    return true;
  }
  // The cached bits, most significant first (at least 56 valid after a refill).
  uint64_t cache() const { return cache_; }
  // Next n bits (0 <= n <= 32) without consuming; the cache must hold them (call refill()).
  uint32_t peek(int n) const { return uint32_t((cache_ >> 32) >> (32 - n)); }
  // Consumes n bits (0 <= n <= 32) that refill() has made available.
  uint32_t take(int n) {
    const uint32_t v = peek(n);
    skip(n);
    return v;
  }
  // Leading one bits in the cache (valid up to the cached count, at least 56 after refill()); a
  // cache of all ones gives 63, so compare the result only with counts below 63.
  int leading_ones() const { return __builtin_clzll(~cache_ | 1); }
  int leading_zeros() const { return cache_ ? __builtin_clzll(cache_) : 64; }
  void skip(int n) {
    cache_ <<= n;
    count_ -= n;
  }
  uint32_t get(int n) {  // n <= 32
    if (count_ < n) refill();
    const uint32_t v = peek(n);
    skip(n);
    return v;
  }
  uint32_t get_bit() { return get(1); }
  // Number of leading one bits, at most `cap` (cap <= 32); consumes them, and the terminating zero
  // when fewer than cap ones were found.
  int get_ones_capped(int cap) {
    if (count_ < 33) refill();
    const uint64_t inverted = ~cache_;
    int ones = inverted ? __builtin_clzll(inverted) : 64;
    if (ones >= cap) {
      skip(cap);
      return cap;
    }
    skip(ones + 1);
    return ones;
  }
  // True when more bits were consumed than the buffer holds.
  bool overrun() const {
    const uint64_t fed = uint64_t(p_ - begin_) + zero_bytes_;
    return fed * 8 - uint64_t(count_) > uint64_t(end_ - begin_) * 8;
  }

 private:
  const uint8_t* begin_;
  const uint8_t* p_;
  const uint8_t* end_;
  uint64_t cache_ = 0;
  int count_ = 0;
  uint64_t zero_bytes_ = 0;
};

}  // namespace codec::detail
