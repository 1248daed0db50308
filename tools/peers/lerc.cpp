// LERC peer through Esri's C API: int16 samples coded with a max-error bound (maxZErr); for integer
// data a bound below 0.5 is lossless. Voids are coded as their fill value like for every other peer
// (no validity mask), so all peers code the same grid.
#include <Lerc_c_api.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "peers.h"

namespace peers {
namespace {

constexpr unsigned kLercShort = 2;  // Lerc data type code for int16

class LercPeer final : public Peer {
 public:
  std::string name() const override { return "lerc"; }
  std::string configuration() const override {
    return "LERC 4.0 (Debian liblerc): lerc_encode, data type short (int16), 1 band, depth 1, no mask, "
           "maxZErr = declared max error (0 = lossless), latest codec version";
  }
  bool lossless_capable() const override { return true; }
  std::vector<Setting> sweep(bool quick, double unit_m) const override {
    const std::vector<double> metres =
        quick ? std::vector<double>{0, 1, 2, 5} : std::vector<double>{0, 1, 2, 3, 4, 5, 6, 8, 10, 12, 16, 20};
    std::vector<Setting> out;
    for (double m : metres) {
      // Whole sample units, so the declared bound is exactly the parameter.
      const double e = m == 0 ? 0.0 : std::max(1.0, std::round(m / unit_m));
      if (!out.empty() && out.back().param == e) continue;
      char label[40];
      std::snprintf(label, sizeof label, e == 0 ? "maxerr=0 lossless" : "maxerr=%g", e);
      out.push_back({label, e, 0, e});
    }
    return out;
  }

  void encode(const Image16& img, const Setting& setting, Bytes& out) override {
    // Worst case is a little over the raw size; a generous buffer avoids a sizing pass.
    const size_t capacity = size_t(img.sample_count()) * 2 + 4096;
    if (out.size() < capacity) out.resize(capacity);
    unsigned written = 0;
    const lerc_status status =
        lerc_encode(img.samples.data(), kLercShort, 1, int(img.width), int(img.height), 1, 0, nullptr,
                    setting.param, out.data(), unsigned(out.size()), &written);
    if (status != 0) throw PeerError("lerc: encoding failed (status " + std::to_string(status) + ")");
    out.resize(written);
  }

  void decode(const uint8_t* data, size_t size, const Image16& shape, const Setting&, int32_t* dst) override {
    decoded_.resize(size_t(shape.sample_count()));
    const lerc_status status = lerc_decode(data, unsigned(size), 0, nullptr, 1, int(shape.width),
                                           int(shape.height), 1, kLercShort, decoded_.data());
    if (status != 0) throw PeerError("lerc: decoding failed (status " + std::to_string(status) + ")");
    for (size_t i = 0; i < decoded_.size(); ++i) dst[i] = decoded_[i];
  }

 private:
  std::vector<int16_t> decoded_;  // reused across calls
};

}  // namespace

std::unique_ptr<Peer> make_lerc_peer() { return std::make_unique<LercPeer>(); }

}  // namespace peers
