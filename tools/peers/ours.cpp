// Our codec (libcodec) as one more peer, through its public API only: lossy at a quantiser step
// (step 1 = lossless) and the max-error mode, one thread; twice: with 64x64 tiles (libcodec's
// default; the pyramid uses 32 for region decoding) and with 256x256 tiles (whole-image use, as the
// single-tile peers are run: fewer tile starts and index entries, which matter at low rates on smooth
// terrain).
#include <codec/codec.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "peers.h"

namespace peers {
namespace {

constexpr int kStep = 0;
constexpr int kMaxError = 1;

class OursPeer final : public Peer {
 public:
  explicit OursPeer(uint32_t tile_size) : tile_size_(tile_size) {}
  std::string name() const override {
    return tile_size_ == codec::EncodeOptions{}.tile_size ? "libcodec"
                                                          : "libcodec-t" + std::to_string(tile_size_);
  }
  std::string configuration() const override {
    return name() + ": libcodec format v" + std::to_string(codec::kFormatVersion) +
           ": int32 input, tile_size " + std::to_string(tile_size_) +
           ", one thread; step sweep (step 1 = lossless) with "
           "bound_max_error off, and max-error sweep (bound_max_error on, max_error = E)";
  }
  bool lossless_capable() const override { return true; }
  std::vector<Setting> sweep(bool quick, double unit_m) const override {
    const std::vector<double> step_metres =
        quick ? std::vector<double>{2, 4, 8}
              : std::vector<double>{1.25, 1.5, 2, 3, 4, 6, 8, 11, 16, 23, 32, 45, 64, 90, 128, 181, 256};
    const std::vector<double> error_metres =
        quick ? std::vector<double>{1, 2, 5} : std::vector<double>{1, 2, 3, 4, 5, 6, 8, 10, 12, 16, 20};
    std::vector<Setting> out{{"step=1 lossless", 1, kStep, 0}};
    for (double m : step_metres) {
      const double s = std::max(1.0, m / unit_m);
      if (s == out.back().param) continue;
      char label[40];
      std::snprintf(label, sizeof label, "step=%g", s);
      out.push_back({label, s, kStep, -1});
    }
    out.push_back({"maxerr=0 lossless", 0, kMaxError, 0});
    for (double m : error_metres) {
      const double e = std::max(1.0, std::round(m / unit_m));
      if (e == out.back().param) continue;
      out.push_back({"maxerr=" + std::to_string(int(e)), e, kMaxError, e});
    }
    return out;
  }

  void encode(const Image16& img, const Setting& setting, Bytes& out) override {
    samples_.assign(img.samples.begin(), img.samples.end());
    codec::EncodeOptions options;
    options.tile_size = tile_size_;
    if (setting.mode == kStep) {
      options.step = setting.param;
    } else {
      options.bound_max_error = true;
      options.max_error = uint32_t(setting.param);
    }
    const size_t capacity = codec::encode_bound(img.width, img.height, options);
    if (capacity == 0) throw PeerError("ours: invalid options for this image");
    if (out.size() < capacity) out.resize(capacity);
    size_t written = 0;
    const codec::Status status = codec::encode(samples_.data(), img.width, img.width, img.height, options,
                                               out.data(), out.size(), &written, scratch_);
    if (status != codec::Status::Ok)
      throw PeerError(std::string("ours: encode: ") + codec::status_name(status));
    out.resize(written);
  }

  void decode(const uint8_t* data, size_t size, const Image16& shape, const Setting&, int32_t* dst) override {
    codec::HeaderInfo header;
    codec::Status status = codec::read_header(data, size, &header);
    if (status == codec::Status::Ok && (header.width != shape.width || header.height != shape.height))
      throw PeerError("ours: decoded image has the wrong shape");
    if (status == codec::Status::Ok) status = codec::decode(data, size, dst, shape.width, scratch_);
    if (status != codec::Status::Ok)
      throw PeerError(std::string("ours: decode: ") + codec::status_name(status));
  }

 private:
  uint32_t tile_size_;
  std::vector<int32_t> samples_;  // int32 copy of the input; reused across calls
  codec::Scratch scratch_;
};

}  // namespace

std::unique_ptr<Peer> make_ours_peer(uint32_t tile_size) { return std::make_unique<OursPeer>(tile_size); }

}  // namespace peers
