// JPEG XL lossless peer through libjxl: bare codestream (no container, no boxes) in memory, one grey
// channel of 16-bit unsigned samples, modular lossless at effort 7 (cjxl -d 0 -e 7). libjxl codes
// unsigned samples, so the int16 values are shifted by the image minimum (a 2-byte prefix counted
// in the size) and restored on decode. No parallel runner is set, so encoder and decoder run on the
// calling thread.
#include <jxl/decode.h>
#include <jxl/encode.h>

#include <algorithm>
#include <cstring>

#include "peers.h"

namespace peers {
namespace {

constexpr size_t kOffsetBytes = 2;
constexpr int kEffort = 7;
constexpr JxlPixelFormat kGrey16{1, JXL_TYPE_UINT16, JXL_NATIVE_ENDIAN, 0};

std::string version_text(uint32_t v) {
  return std::to_string(v / 1000000) + "." + std::to_string(v / 1000 % 1000) + "." + std::to_string(v % 1000);
}

// Owns the libjxl objects of one encode or decode so that every exit path frees them.
struct EncoderHandle {
  JxlEncoder* enc = JxlEncoderCreate(nullptr);
  ~EncoderHandle() { JxlEncoderDestroy(enc); }
  void check(JxlEncoderStatus status, const char* what) const {
    if (status == JXL_ENC_SUCCESS) return;
    throw PeerError(std::string("jpegxl: ") + what + " failed (libjxl encoder error " +
                    std::to_string(int(JxlEncoderGetError(enc))) + ")");
  }
};
struct DecoderHandle {
  JxlDecoder* dec = JxlDecoderCreate(nullptr);
  ~DecoderHandle() { JxlDecoderDestroy(dec); }
};

class JpegXlPeer final : public Peer {
 public:
  std::string name() const override { return "jpegxl"; }
  std::string configuration() const override {
    return "libjxl " + version_text(JxlEncoderVersion()) +
           ": JPEG XL bare codestream, 1 grey channel 16-bit unsigned, samples - min (2-byte offset prefix), "
           "modular lossless (JxlEncoderSetFrameLossless), effort 7, no parallel runner (1 thread)";
  }
  bool lossless_capable() const override { return true; }
  std::vector<Setting> sweep(bool, double) const override { return {{"lossless e7", 0, 0, 0}}; }

  void encode(const Image16& img, const Setting&, Bytes& out) override {
    const auto lo = std::min_element(img.samples.begin(), img.samples.end());
    const int16_t zmin = lo == img.samples.end() ? 0 : *lo;
    raw_.resize(img.samples.size());
    for (size_t i = 0; i < raw_.size(); ++i) raw_[i] = uint16_t(int32_t(img.samples[i]) - zmin);

    EncoderHandle h;
    if (!h.enc) throw PeerError("jpegxl: cannot create encoder");
    JxlBasicInfo info;
    JxlEncoderInitBasicInfo(&info);
    info.xsize = uint32_t(img.width);
    info.ysize = uint32_t(img.height);
    info.bits_per_sample = 16;
    info.exponent_bits_per_sample = 0;
    info.num_color_channels = 1;
    info.uses_original_profile = JXL_TRUE;  // lossless needs the samples' own colour space
    h.check(JxlEncoderSetBasicInfo(h.enc, &info), "basic info");
    JxlColorEncoding colour;
    JxlColorEncodingSetToLinearSRGB(&colour, JXL_TRUE);
    h.check(JxlEncoderSetColorEncoding(h.enc, &colour), "colour encoding");
    JxlEncoderFrameSettings* frame = JxlEncoderFrameSettingsCreate(h.enc, nullptr);
    h.check(JxlEncoderSetFrameLossless(frame, JXL_TRUE), "lossless mode");
    h.check(JxlEncoderFrameSettingsSetOption(frame, JXL_ENC_FRAME_SETTING_EFFORT, kEffort), "effort");
    h.check(JxlEncoderAddImageFrame(frame, &kGrey16, raw_.data(), raw_.size() * sizeof(uint16_t)), "frame");
    JxlEncoderCloseInput(h.enc);

    out.resize(std::max<size_t>(out.capacity(), kOffsetBytes + 65536));
    std::memcpy(out.data(), &zmin, kOffsetBytes);
    size_t used = kOffsetBytes;
    for (;;) {
      uint8_t* next = out.data() + used;
      size_t avail = out.size() - used;
      const JxlEncoderStatus status = JxlEncoderProcessOutput(h.enc, &next, &avail);
      used = size_t(next - out.data());
      if (status != JXL_ENC_NEED_MORE_OUTPUT) {
        h.check(status, "encoding");
        break;
      }
      out.resize(2 * out.size());
    }
    out.resize(used);
  }

  void decode(const uint8_t* data, size_t size, const Image16& shape, const Setting&, int32_t* dst) override {
    if (size < kOffsetBytes) throw PeerError("jpegxl: stream too short");
    int16_t zmin;
    std::memcpy(&zmin, data, kOffsetBytes);
    DecoderHandle h;
    if (!h.dec) throw PeerError("jpegxl: cannot create decoder");
    const size_t n = size_t(shape.sample_count());
    if (JxlDecoderSubscribeEvents(h.dec, JXL_DEC_BASIC_INFO | JXL_DEC_FULL_IMAGE) != JXL_DEC_SUCCESS ||
        JxlDecoderSetInput(h.dec, data + kOffsetBytes, size - kOffsetBytes) != JXL_DEC_SUCCESS)
      throw PeerError("jpegxl: decoder setup failed");
    JxlDecoderCloseInput(h.dec);
    bool have_image = false;
    for (bool done = false; !done;) {
      switch (JxlDecoderProcessInput(h.dec)) {
        case JXL_DEC_BASIC_INFO: {
          JxlBasicInfo info;
          if (JxlDecoderGetBasicInfo(h.dec, &info) != JXL_DEC_SUCCESS || int64_t(info.xsize) != shape.width ||
              int64_t(info.ysize) != shape.height || info.num_color_channels != 1 ||
              info.bits_per_sample != 16)
            throw PeerError("jpegxl: decoded image has the wrong shape");
          break;
        }
        case JXL_DEC_NEED_IMAGE_OUT_BUFFER: {
          size_t needed = 0;
          raw_.resize(n);
          if (JxlDecoderImageOutBufferSize(h.dec, &kGrey16, &needed) != JXL_DEC_SUCCESS ||
              needed != n * sizeof(uint16_t) ||
              JxlDecoderSetImageOutBuffer(h.dec, &kGrey16, raw_.data(), needed) != JXL_DEC_SUCCESS)
            throw PeerError("jpegxl: unexpected decoded size");
          break;
        }
        case JXL_DEC_FULL_IMAGE:
          have_image = true;
          break;
        case JXL_DEC_SUCCESS:
          done = true;
          break;
        case JXL_DEC_NEED_MORE_INPUT:
          throw PeerError("jpegxl: stream truncated");
        default:
          throw PeerError("jpegxl: decoding failed");
      }
    }
    if (!have_image) throw PeerError("jpegxl: stream holds no image");
    for (size_t i = 0; i < n; ++i) dst[i] = int32_t(raw_[i]) + zmin;
  }

 private:
  std::vector<uint16_t> raw_;  // samples - min, native endian; reused across calls
};

}  // namespace

std::unique_ptr<Peer> make_jpegxl_peer() { return std::make_unique<JpegXlPeer>(); }

}  // namespace peers
