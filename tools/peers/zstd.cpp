// zstd peer: the raw little-endian int16 samples through one reused compression context, as the
// general-purpose lossless baseline.
#include <zstd.h>

#include <cstring>

#include "peers.h"

namespace peers {
namespace {

class ZstdPeer final : public Peer {
 public:
  ZstdPeer() : cctx_(ZSTD_createCCtx()), dctx_(ZSTD_createDCtx()) {
    if (!cctx_ || !dctx_) throw PeerError("zstd: cannot create contexts");
  }
  ~ZstdPeer() override {
    ZSTD_freeCCtx(cctx_);
    ZSTD_freeDCtx(dctx_);
  }
  ZstdPeer(const ZstdPeer&) = delete;
  ZstdPeer& operator=(const ZstdPeer&) = delete;

  std::string name() const override { return "zstd"; }
  std::string configuration() const override {
    return std::string("zstd ") + ZSTD_versionString() +
           ": raw int16 little-endian samples, ZSTD_compressCCtx at level L, single thread";
  }
  bool lossless_capable() const override { return true; }
  std::vector<Setting> sweep(bool quick, double) const override {
    if (quick) return {{"level=3", 3, 0, 0}};
    return {{"level=3", 3, 0, 0}, {"level=19", 19, 0, 0}};
  }

  void encode(const Image16& img, const Setting& setting, Bytes& out) override {
    const size_t raw_bytes = img.samples.size() * sizeof(int16_t);
    const size_t capacity = ZSTD_compressBound(raw_bytes);
    if (out.size() < capacity) out.resize(capacity);
    const size_t written =
        ZSTD_compressCCtx(cctx_, out.data(), out.size(), img.samples.data(), raw_bytes, int(setting.param));
    if (ZSTD_isError(written)) throw PeerError(std::string("zstd: ") + ZSTD_getErrorName(written));
    out.resize(written);
  }

  void decode(const uint8_t* data, size_t size, const Image16& shape, const Setting&, int32_t* dst) override {
    samples_.resize(size_t(shape.sample_count()));
    const size_t got =
        ZSTD_decompressDCtx(dctx_, samples_.data(), samples_.size() * sizeof(int16_t), data, size);
    if (ZSTD_isError(got)) throw PeerError(std::string("zstd: ") + ZSTD_getErrorName(got));
    if (got != samples_.size() * sizeof(int16_t))
      throw PeerError("zstd: decoded size does not match the image");
    for (size_t i = 0; i < samples_.size(); ++i) dst[i] = samples_[i];
  }

 private:
  ZSTD_CCtx* cctx_;
  ZSTD_DCtx* dctx_;
  std::vector<int16_t> samples_;  // reused across calls
};

}  // namespace

std::unique_ptr<Peer> make_zstd_peer() { return std::make_unique<ZstdPeer>(); }

}  // namespace peers
