// ZFP peer: 2-D float field (int16 samples are exact in float) in fixed-accuracy mode (absolute
// tolerance) and in reversible (lossless) mode. Decoded floats are rounded to the nearest integer,
// so the declared bound is floor(tolerance + 0.5). zfp rounds the tolerance down to a power of two,
// so the sweep uses powers of two. Serial execution.
#include <zfp.h>

#include <cmath>
#include <cstdio>
#include <cstring>

#include "peers.h"

namespace peers {
namespace {

constexpr int kAccuracy = 0;
constexpr int kReversible = 1;

// Owns the zfp objects of one call.
struct ZfpSession {
  zfp_field* field = nullptr;
  zfp_stream* zfp = nullptr;
  bitstream* bits = nullptr;
  ~ZfpSession() {
    if (bits) stream_close(bits);
    if (zfp) zfp_stream_close(zfp);
    if (field) zfp_field_free(field);
  }
  void configure(const Setting& setting) {
    zfp = zfp_stream_open(nullptr);
    if (setting.mode == kReversible)
      zfp_stream_set_reversible(zfp);
    else
      zfp_stream_set_accuracy(zfp, setting.param);
    zfp_stream_set_execution(zfp, zfp_exec_serial);
  }
};

class ZfpPeer final : public Peer {
 public:
  std::string name() const override { return "zfp"; }
  std::string configuration() const override {
    return std::string("zfp ") + ZFP_VERSION_STRING +
           ": 2-D float field (nx = width), serial; fixed-accuracy mode with absolute tolerance t "
           "(decoded rounded to integers), and reversible mode";
  }
  bool lossless_capable() const override { return true; }
  std::vector<Setting> sweep(bool quick, double unit_m) const override {
    const std::vector<double> metres =
        quick ? std::vector<double>{1, 2, 4} : std::vector<double>{0.5, 1, 2, 4, 8, 16, 32, 64};
    std::vector<Setting> out;
    for (double m : metres) {
      const double t = std::exp2(std::round(std::log2(m / unit_m)));  // zfp uses powers of two anyway
      char label[40];
      std::snprintf(label, sizeof label, "tol=%g", t);
      out.push_back({label, t, kAccuracy, std::floor(t + 0.5)});
    }
    out.push_back({"reversible", 0, kReversible, 0});
    return out;
  }

  void encode(const Image16& img, const Setting& setting, Bytes& out) override {
    values_.resize(img.samples.size());
    for (size_t i = 0; i < img.samples.size(); ++i) values_[i] = float(img.samples[i]);
    ZfpSession s;
    s.field = zfp_field_2d(values_.data(), zfp_type_float, size_t(img.width), size_t(img.height));
    s.configure(setting);
    const size_t capacity = zfp_stream_maximum_size(s.zfp, s.field);
    if (out.size() < capacity) out.resize(capacity);
    s.bits = stream_open(out.data(), out.size());
    zfp_stream_set_bit_stream(s.zfp, s.bits);
    zfp_stream_rewind(s.zfp);
    const size_t written = zfp_compress(s.zfp, s.field);
    if (written == 0) throw PeerError("zfp: compression failed");
    out.resize(written);
  }

  void decode(const uint8_t* data, size_t size, const Image16& shape, const Setting& setting,
              int32_t* dst) override {
    values_.resize(size_t(shape.sample_count()));
    ZfpSession s;
    s.field = zfp_field_2d(values_.data(), zfp_type_float, size_t(shape.width), size_t(shape.height));
    s.configure(setting);
    s.bits = stream_open(const_cast<uint8_t*>(data), size);  // zfp's bitstream is not const-correct
    zfp_stream_set_bit_stream(s.zfp, s.bits);
    zfp_stream_rewind(s.zfp);
    if (zfp_decompress(s.zfp, s.field) == 0) throw PeerError("zfp: decompression failed");
    for (size_t i = 0; i < values_.size(); ++i) dst[i] = int32_t(std::lround(values_[i]));
  }

 private:
  std::vector<float> values_;  // reused across calls
};

}  // namespace

std::unique_ptr<Peer> make_zfp_peer() { return std::make_unique<ZfpPeer>(); }

}  // namespace peers
