// JPEG XR peer through jxrlib's glue layer (the HD Photo container around the codestream), coded
// in memory through a WMPStream whose callbacks read and write a byte vector. JPEG XR's 16-bit
// grey format is unsigned, so samples are shifted by the image minimum (stored as a 4-byte trailer
// counted in the size: the container's offsets are absolute, so it must start the stream). QP index 1 is
// lossless; larger indices quantise more coarsely.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "peers.h"

extern "C" {
#include <JXRGlue.h>
}
// jxrlib's headers define min and max as macros, which break the standard library's functions.
#undef min
#undef max

namespace peers {
namespace {

// Growable in-memory WMPStream. The glue closes the streams it is given; Close only detaches, the
// C++ object owns the storage.
struct VectorStream {
  WMPStream ws;                   // first member, so a WMPStream* is a VectorStream*
  Bytes* bytes = nullptr;         // write target
  const uint8_t* data = nullptr;  // read source
  size_t size = 0;                // logical size (high-water mark when writing)
  size_t pos = 0;
};

VectorStream* self(WMPStream* ws) { return reinterpret_cast<VectorStream*>(ws); }

ERR vs_close(WMPStream** ws) {
  *ws = nullptr;
  return WMP_errSuccess;
}
Bool vs_eos(WMPStream* ws) { return self(ws)->pos >= self(ws)->size; }
// The decoder reads the bitstream in fixed-size packets and may ask for bytes past the end; like
// jxrlib's own memory stream, serve what exists and zero-fill the rest.
ERR vs_read(WMPStream* ws, void* dst, size_t n) {
  VectorStream* s = self(ws);
  if (s->pos > s->size) return WMP_errFileIO;
  const size_t count = std::min(n, s->size - s->pos);
  std::memcpy(dst, s->data + s->pos, count);
  std::memset(static_cast<uint8_t*>(dst) + count, 0, n - count);
  s->pos += count;
  return WMP_errSuccess;
}
ERR vs_write(WMPStream* ws, const void* src, size_t n) {
  VectorStream* s = self(ws);
  if (!s->bytes) return WMP_errFileIO;
  if (s->bytes->size() < s->pos + n) s->bytes->resize(std::max(s->pos + n, 2 * s->bytes->size()));
  std::memcpy(s->bytes->data() + s->pos, src, n);
  s->pos += n;
  s->size = std::max(s->size, s->pos);
  return WMP_errSuccess;
}
ERR vs_set_pos(WMPStream* ws, size_t pos) {
  VectorStream* s = self(ws);
  // Writers may seek past the end to patch a header later; readers may not.
  if (!s->bytes && pos > s->size) return WMP_errFileIO;
  s->pos = pos;
  return WMP_errSuccess;
}
ERR vs_get_pos(WMPStream* ws, size_t* pos) {
  *pos = self(ws)->pos;
  return WMP_errSuccess;
}

void init_stream(VectorStream& s) {
  std::memset(&s.ws, 0, sizeof s.ws);
  s.ws.fMem = TRUE;
  s.ws.Close = vs_close;
  s.ws.EOS = vs_eos;
  s.ws.Read = vs_read;
  s.ws.Write = vs_write;
  s.ws.SetPos = vs_set_pos;
  s.ws.GetPos = vs_get_pos;
}

[[noreturn]] void fail(const char* what, ERR err) {
  throw PeerError(std::string("jpegxr: ") + what + " (jxrlib error " + std::to_string(err) + ")");
}

constexpr size_t kOffsetBytes = 4;

class JpegXrPeer final : public Peer {
 public:
  std::string name() const override { return "jpegxr"; }
  std::string configuration() const override {
    return "jxrlib 1.2 (Debian libjxr): HD Photo container in memory, 16bppGray (samples - min, "
           "4-byte offset trailer), Y_ONLY, one-level overlap (OL_ONE), spatial bitstream order, "
           "1 tile, all subbands, QP index q for DC/LP/HP alike (q = 1 lossless)";
  }
  bool lossless_capable() const override { return true; }
  std::vector<Setting> sweep(bool quick, double unit_m) const override {
    std::vector<int> qps =
        quick ? std::vector<int>{1, 24, 40, 56}
              : std::vector<int>{1, 2, 4, 8, 12, 16, 24, 32, 40, 48, 56, 64, 72, 80, 88, 96, 112, 128};
    // Above QP 16 the quantiser step doubles every 16 QP indices: shift the lossy QPs so that the
    // steps in metres stay about the same for finer sample units.
    const int shift = 16 * int(std::lround(std::log2(1.0 / unit_m)));
    for (int& qp : qps)
      if (qp > 16) qp = std::clamp(qp + shift, 17, 255);
    std::vector<Setting> out;
    for (int qp : qps) {
      char label[32];
      std::snprintf(label, sizeof label, qp == 1 ? "qp=1 lossless" : "qp=%d", qp);
      out.push_back({label, double(qp), 0, qp == 1 ? 0.0 : -1.0});
    }
    return out;
  }

  void encode(const Image16& img, const Setting& setting, Bytes& out) override {
    const int16_t zmin = img.samples.empty() ? 0 : *std::min_element(img.samples.begin(), img.samples.end());
    unsigned_.resize(img.samples.size());
    for (size_t i = 0; i < img.samples.size(); ++i) unsigned_[i] = uint16_t(int32_t(img.samples[i]) - zmin);

    out.clear();
    VectorStream stream;
    init_stream(stream);
    stream.bytes = &out;

    CWMIStrCodecParam scp;
    std::memset(&scp, 0, sizeof scp);
    scp.cfColorFormat = Y_ONLY;
    scp.bdBitDepth = BD_LONG;
    scp.bfBitstreamFormat = SPATIAL;
    scp.bProgressiveMode = FALSE;
    scp.olOverlap = OL_ONE;
    scp.sbSubband = SB_ALL;
    scp.cNumOfSliceMinus1H = scp.cNumOfSliceMinus1V = 0;
    const U8 qp = U8(setting.param);
    scp.uiDefaultQPIndex = scp.uiDefaultQPIndexYLP = scp.uiDefaultQPIndexYHP = qp;
    scp.uiDefaultQPIndexAlpha = 1;

    PKImageEncode* encoder = nullptr;
    ERR err = PKImageEncode_Create_WMP(&encoder);
    if (err < 0) fail("cannot create encoder", err);
    const char* stage = "initialize";
    if ((err = encoder->Initialize(encoder, &stream.ws, &scp, sizeof scp)) >= 0 &&
        (stage = "set pixel format", err = encoder->SetPixelFormat(encoder, GUID_PKPixelFormat16bppGray)) >=
            0 &&
        (stage = "set size", err = encoder->SetSize(encoder, I32(img.width), I32(img.height))) >= 0 &&
        (stage = "set resolution", err = encoder->SetResolution(encoder, 96.f, 96.f)) >= 0) {
      stage = "encode";
      err = encoder->WritePixels(encoder, U32(img.height), reinterpret_cast<U8*>(unsigned_.data()),
                                 U32(img.width * 2));
    }
    encoder->Release(&encoder);
    if (err < 0) fail((std::string("encoding failed at ") + stage).c_str(), err);
    out.resize(stream.size + kOffsetBytes);
    const int32_t offset = zmin;
    std::memcpy(out.data() + stream.size, &offset, kOffsetBytes);
  }

  void decode(const uint8_t* data, size_t size, const Image16& shape, const Setting&, int32_t* dst) override {
    if (size < kOffsetBytes) throw PeerError("jpegxr: stream too short");
    int32_t offset;
    std::memcpy(&offset, data + size - kOffsetBytes, kOffsetBytes);
    VectorStream stream;
    init_stream(stream);
    stream.data = data;
    stream.size = size - kOffsetBytes;

    PKImageDecode* decoder = nullptr;
    ERR err = PKImageDecode_Create_WMP(&decoder);
    if (err < 0) fail("cannot create decoder", err);
    unsigned_.resize(size_t(shape.sample_count()));
    I32 w = 0, h = 0;
    if ((err = decoder->Initialize(decoder, &stream.ws)) >= 0 &&
        (err = decoder->GetSize(decoder, &w, &h)) >= 0) {
      if (w != shape.width || h != shape.height) {
        decoder->Release(&decoder);
        throw PeerError("jpegxr: decoded image has the wrong shape");
      }
      decoder->WMP.wmiSCP.uAlphaMode = 0;
      PKRect rect = {0, 0, w, h};
      err = decoder->Copy(decoder, &rect, reinterpret_cast<U8*>(unsigned_.data()), U32(w * 2));
    }
    decoder->Release(&decoder);
    if (err < 0) fail("decoding failed", err);
    for (size_t i = 0; i < unsigned_.size(); ++i) dst[i] = int32_t(unsigned_[i]) + offset;
  }

 private:
  std::vector<uint16_t> unsigned_;  // shifted samples; reused across calls
};

}  // namespace

std::unique_ptr<Peer> make_jpegxr_peer() { return std::make_unique<JpegXrPeer>(); }

}  // namespace peers
