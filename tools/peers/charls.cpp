// JPEG-LS peer through CharLS's C API: lossless (NEAR = 0) and near-lossless (max error = NEAR).
// JPEG-LS codes unsigned samples of P bits, so samples are shifted by the image minimum (a 4-byte
// prefix counted in the size) and P is the bit width of the image's range, as a careful user would
// set it (the default thresholds scale with MAXVAL = 2^P - 1).
#include <charls/charls.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

#include "peers.h"

namespace peers {
namespace {

constexpr size_t kOffsetBytes = 4;
constexpr charls_jpegls_errc kSuccess = charls::jpegls_errc::success;

[[noreturn]] void fail(const char* what, charls_jpegls_errc err) {
  throw PeerError(std::string("charls: ") + what + ": " + charls_get_error_message(err));
}

class CharlsPeer final : public Peer {
 public:
  std::string name() const override { return "charls"; }
  std::string configuration() const override {
    return std::string("CharLS ") + charls_get_version_string() +
           ": JPEG-LS, 1 component, P = bit width of (max - min) (min >= 2), samples - min "
           "(4-byte offset prefix), default thresholds, no SPIFF header; NEAR sweep";
  }
  bool lossless_capable() const override { return true; }
  std::vector<Setting> sweep(bool quick, double unit_m) const override {
    const std::vector<double> metres =
        quick ? std::vector<double>{1, 2, 5} : std::vector<double>{1, 2, 3, 4, 5, 6, 8, 10, 12, 16, 20};
    std::vector<Setting> out{{"near=0 lossless", 0, 0, 0}};
    for (double m : metres) {
      const int near = std::max(1, int(std::lround(m / unit_m)));
      if (near == int(out.back().param)) continue;
      out.push_back({"near=" + std::to_string(near), double(near), 0, double(near)});
    }
    return out;
  }

  void encode(const Image16& img, const Setting& setting, Bytes& out) override {
    const auto [lo, hi] = std::minmax_element(img.samples.begin(), img.samples.end());
    const int32_t zmin = img.samples.empty() ? 0 : *lo;
    const uint32_t range = img.samples.empty() ? 0 : uint32_t(int32_t(*hi) - zmin);
    const int32_t bits = std::max(2, int32_t(std::bit_width(range)));
    // CharLS takes one byte per sample up to 8 bits, two above.
    const size_t n = img.samples.size();
    if (bits <= 8) {
      raw_.resize(n);
      for (size_t i = 0; i < n; ++i) raw_[i] = uint8_t(int32_t(img.samples[i]) - zmin);
    } else {
      raw_.resize(2 * n);
      for (size_t i = 0; i < n; ++i) {
        const uint16_t v = uint16_t(int32_t(img.samples[i]) - zmin);
        std::memcpy(raw_.data() + 2 * i, &v, 2);
      }
    }

    charls_jpegls_encoder* encoder = charls_jpegls_encoder_create();
    if (!encoder) throw PeerError("charls: cannot create encoder");
    const charls_frame_info frame{uint32_t(img.width), uint32_t(img.height), bits, 1};
    size_t capacity = 0, written = 0;
    charls_jpegls_errc err = charls_jpegls_encoder_set_frame_info(encoder, &frame);
    if (err == kSuccess) err = charls_jpegls_encoder_set_near_lossless(encoder, int32_t(setting.param));
    if (err == kSuccess) err = charls_jpegls_encoder_get_estimated_destination_size(encoder, &capacity);
    if (err == kSuccess) {
      out.resize(kOffsetBytes + capacity);
      std::memcpy(out.data(), &zmin, kOffsetBytes);
      err = charls_jpegls_encoder_set_destination_buffer(encoder, out.data() + kOffsetBytes, capacity);
    }
    if (err == kSuccess) err = charls_jpegls_encoder_encode_from_buffer(encoder, raw_.data(), raw_.size(), 0);
    if (err == kSuccess) err = charls_jpegls_encoder_get_bytes_written(encoder, &written);
    charls_jpegls_encoder_destroy(encoder);
    if (err != kSuccess) fail("encoding failed", err);
    out.resize(kOffsetBytes + written);
  }

  void decode(const uint8_t* data, size_t size, const Image16& shape, const Setting&, int32_t* dst) override {
    if (size < kOffsetBytes) throw PeerError("charls: stream too short");
    int32_t zmin;
    std::memcpy(&zmin, data, kOffsetBytes);
    charls_jpegls_decoder* decoder = charls_jpegls_decoder_create();
    if (!decoder) throw PeerError("charls: cannot create decoder");
    charls_frame_info frame{};
    size_t needed = 0;
    charls_jpegls_errc err =
        charls_jpegls_decoder_set_source_buffer(decoder, data + kOffsetBytes, size - kOffsetBytes);
    if (err == kSuccess) err = charls_jpegls_decoder_read_header(decoder);
    if (err == kSuccess) err = charls_jpegls_decoder_get_frame_info(decoder, &frame);
    if (err == kSuccess && (int64_t(frame.width) != shape.width || int64_t(frame.height) != shape.height ||
                            frame.component_count != 1 || frame.bits_per_sample > 16)) {
      charls_jpegls_decoder_destroy(decoder);
      throw PeerError("charls: decoded frame has the wrong shape");
    }
    if (err == kSuccess) err = charls_jpegls_decoder_get_destination_size(decoder, 0, &needed);
    if (err == kSuccess) {
      const size_t bytes_per_sample = frame.bits_per_sample <= 8 ? 1 : 2;
      if (needed != size_t(shape.sample_count()) * bytes_per_sample) {
        charls_jpegls_decoder_destroy(decoder);
        throw PeerError("charls: unexpected decoded size");
      }
      raw_.resize(needed);
      err = charls_jpegls_decoder_decode_to_buffer(decoder, raw_.data(), needed, 0);
    }
    charls_jpegls_decoder_destroy(decoder);
    if (err != kSuccess) fail("decoding failed", err);
    const size_t n = size_t(shape.sample_count());
    if (raw_.size() == n) {
      for (size_t i = 0; i < n; ++i) dst[i] = int32_t(raw_[i]) + zmin;
    } else {
      for (size_t i = 0; i < n; ++i) {
        uint16_t v;
        std::memcpy(&v, raw_.data() + 2 * i, 2);
        dst[i] = int32_t(v) + zmin;
      }
    }
  }

 private:
  Bytes raw_;  // samples - min, 1 or 2 bytes each (native endian); reused across calls
};

}  // namespace

std::unique_ptr<Peer> make_charls_peer() { return std::make_unique<CharlsPeer>(); }

}  // namespace peers
