// UniformQuantizerCoder: the stand-in residual coder (one absolute step, zigzag varints).
#include <algorithm>
#include <cstdlib>
#include <limits>
#include <stdexcept>

#include "core/bytes.h"
#include "pyramid/internal/zigzag.h"
#include "pyramid/pyramid.h"

namespace terrain {

UniformQuantizerCoder::UniformQuantizerCoder(int32_t step, int64_t band_rows)
    : step_(step), band_rows_(band_rows) {
  if (step < 1) throw std::invalid_argument("UniformQuantizerCoder: step must be >= 1");
  if (band_rows < 1) throw std::invalid_argument("UniformQuantizerCoder: band_rows must be >= 1");
}

std::vector<uint8_t> UniformQuantizerCoder::encode(const int32_t* residual, int64_t w, int64_t h,
                                                   int32_t* reconstructed, int /*levels_above_finest*/,
                                                   bool /*coarsest*/, int /*threads*/) {
  const int64_t n = w * h;
  std::vector<uint8_t> out(size_t(n) * 5);
  uint8_t* p = out.data();
  const int64_t s = step_, half = step_ / 2;
  // Division by a runtime step is slow: a power-of-two step shifts; otherwise a double reciprocal
  // gets within one of the quotient and an integer correction makes it exact.
  int shift = -1;
  for (int b = 0; b < 31; ++b)
    if (s == (int64_t(1) << b)) shift = b;
  const double inv = 1.0 / double(s);
  const int64_t lo = std::numeric_limits<int32_t>::min(), hi = std::numeric_limits<int32_t>::max();
  for (int64_t k = 0; k < n; ++k) {
    const int64_t r = residual[k];
    // Round half away from zero, symmetric for both signs so |r - q*S| <= S/2.
    const int64_t a = (r < 0 ? -r : r) + half;
    int64_t qa;
    if (shift >= 0) {
      qa = a >> shift;
    } else {
      qa = int64_t(double(a) * inv);
      if (qa * s > a) --qa;
      if ((qa + 1) * s <= a) ++qa;
    }
    const int64_t q = std::clamp<int64_t>(r < 0 ? -qa : qa, lo, hi);
    reconstructed[k] = int32_t(std::clamp<int64_t>(q * s, lo, hi));
    const uint32_t z = detail::zigzag(int32_t(q));
    if (z < 0x80)
      *p++ = uint8_t(z);
    else
      p = bytes::put_varint(p, z);
  }
  out.resize(size_t(p - out.data()));
  return out;
}

bool UniformQuantizerCoder::decode(const uint8_t* data, size_t n, int64_t w, int64_t h, int32_t* out) {
  const uint8_t* p = data;
  const uint8_t* end = data + n;
  const int64_t s = step_;
  for (int64_t k = 0; k < w * h; ++k) {
    uint64_t v;
    if (!bytes::get_varint(p, end, &v, 0xffffffffu)) return false;
    const int64_t q = detail::unzigzag(uint32_t(v));
    out[k] = int32_t(
        std::clamp<int64_t>(q * s, std::numeric_limits<int32_t>::min(), std::numeric_limits<int32_t>::max()));
  }
  return p == end;
}

}  // namespace terrain
