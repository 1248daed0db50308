// JPEG 2000 peer through OpenJPEG: raw J2K codestream in memory (user stream callbacks), one
// component of 16-bit signed samples, one quality layer. Lossy: 9/7 irreversible wavelet with PCRD
// rate control at a target rate; lossless: 5/3 reversible wavelet without rate control.
#include <openjpeg.h>

#include <algorithm>
#include <cstring>

#include "peers.h"

namespace peers {
namespace {

constexpr int kLossy97 = 0;
constexpr int kLossless53 = 1;

// Sequential in-memory stream for OpenJPEG: writes grow `bytes`, reads come from `data`.
struct MemoryStream {
  Bytes* bytes = nullptr;         // encode target
  const uint8_t* data = nullptr;  // decode source
  size_t size = 0;                // logical stream size (high-water mark when writing)
  size_t pos = 0;
};

OPJ_SIZE_T stream_write(void* buffer, OPJ_SIZE_T n, void* user) {
  auto* s = static_cast<MemoryStream*>(user);
  if (s->bytes->size() < s->pos + n) s->bytes->resize(std::max(s->pos + n, 2 * s->bytes->size()));
  std::memcpy(s->bytes->data() + s->pos, buffer, n);
  s->pos += n;
  s->size = std::max(s->size, s->pos);
  return n;
}

OPJ_SIZE_T stream_read(void* buffer, OPJ_SIZE_T n, void* user) {
  auto* s = static_cast<MemoryStream*>(user);
  if (s->pos >= s->size) return OPJ_SIZE_T(-1);  // OpenJPEG's end-of-stream marker
  const size_t count = std::min(n, s->size - s->pos);
  std::memcpy(buffer, s->data + s->pos, count);
  s->pos += count;
  return count;
}

OPJ_OFF_T stream_skip(OPJ_OFF_T n, void* user) {
  auto* s = static_cast<MemoryStream*>(user);
  const OPJ_OFF_T target = OPJ_OFF_T(s->pos) + n;
  if (target < 0) return -1;
  s->pos = size_t(target);
  return n;
}

OPJ_BOOL stream_seek(OPJ_OFF_T offset, void* user) {
  auto* s = static_cast<MemoryStream*>(user);
  if (offset < 0) return OPJ_FALSE;
  s->pos = size_t(offset);
  return OPJ_TRUE;
}

void quiet_handler(const char*, void*) {}
void error_handler(const char* msg, void* user) {
  auto* text = static_cast<std::string*>(user);
  if (text->empty()) *text = msg;
  while (!text->empty() && text->back() == '\n') text->pop_back();
}

// Owns the OpenJPEG objects of one encode or decode so that every exit path frees them.
struct OpjSession {
  opj_codec_t* codec = nullptr;
  opj_stream_t* stream = nullptr;
  opj_image_t* image = nullptr;
  std::string error;
  ~OpjSession() {
    if (stream) opj_stream_destroy(stream);
    if (codec) opj_destroy_codec(codec);
    if (image) opj_image_destroy(image);
  }
  void fail(const char* what) {
    throw PeerError(std::string("openjpeg: ") + what + (error.empty() ? "" : ": " + error));
  }
  void quiet() {
    opj_set_info_handler(codec, quiet_handler, nullptr);
    opj_set_warning_handler(codec, quiet_handler, nullptr);
    opj_set_error_handler(codec, error_handler, &error);
  }
};

class OpenJpegPeer final : public Peer {
 public:
  std::string name() const override { return "openjpeg"; }
  std::string configuration() const override {
    return std::string("OpenJPEG ") + opj_version() +
           ": J2K codestream, 1 component 16-bit signed, 6 resolutions, 64x64 code-blocks, 1 quality layer, "
           "LRCP, no tiling, 1 thread; lossy = 9/7 irreversible + PCRD at tcp_rates = 16/bps; "
           "lossless = 5/3 reversible";
  }
  bool lossless_capable() const override { return true; }
  std::vector<Setting> sweep(bool quick, double unit_m) const override {
    std::vector<double> rates = quick ? std::vector<double>{0.5, 1.0, 2.0, 3.5, 5.0, 7.0}
                                      : std::vector<double>{0.1, 0.2, 0.35, 0.5, 0.75, 1.0, 1.5, 2.0,
                                                            2.5, 3.0, 4.0,  5.0, 6.0,  7.0, 8.0};
    // Finer-than-metre units need higher rates to reach the same errors in metres.
    if (!quick && unit_m < 0.75) rates.insert(rates.end(), {9.0, 10.0});
    return wavelet_sweep(rates, "9/7 %.2fbps", kLossy97, kLossless53);
  }

  void encode(const Image16& img, const Setting& setting, Bytes& out) override {
    opj_cparameters_t params;
    opj_set_default_encoder_parameters(&params);
    params.tcp_numlayers = 1;
    params.cp_disto_alloc = 1;
    if (setting.mode == kLossy97) {
      params.irreversible = 1;
      params.tcp_rates[0] = float(16.0 / setting.param);  // compression ratio against 16-bit samples
    } else {
      params.irreversible = 0;
      params.tcp_rates[0] = 0;  // 0 = keep everything (lossless with the 5/3 wavelet)
    }

    opj_image_cmptparm_t component;
    std::memset(&component, 0, sizeof component);
    component.dx = component.dy = 1;
    component.w = OPJ_UINT32(img.width);
    component.h = OPJ_UINT32(img.height);
    component.prec = 16;
    component.sgnd = 1;

    OpjSession session;
    session.image = opj_image_create(1, &component, OPJ_CLRSPC_GRAY);
    if (!session.image) session.fail("cannot create image");
    session.image->x0 = session.image->y0 = 0;
    session.image->x1 = OPJ_UINT32(img.width);
    session.image->y1 = OPJ_UINT32(img.height);
    std::copy(img.samples.begin(), img.samples.end(), session.image->comps[0].data);

    session.codec = opj_create_compress(OPJ_CODEC_J2K);
    session.quiet();
    if (!opj_setup_encoder(session.codec, &params, session.image)) session.fail("encoder setup failed");
    opj_codec_set_threads(session.codec, 1);

    out.clear();
    MemoryStream mem;
    mem.bytes = &out;
    session.stream = opj_stream_create(OPJ_J2K_STREAM_CHUNK_SIZE, OPJ_FALSE);
    opj_stream_set_user_data(session.stream, &mem, nullptr);
    opj_stream_set_write_function(session.stream, stream_write);
    opj_stream_set_skip_function(session.stream, stream_skip);
    opj_stream_set_seek_function(session.stream, stream_seek);
    if (!opj_start_compress(session.codec, session.image, session.stream) ||
        !opj_encode(session.codec, session.stream) || !opj_end_compress(session.codec, session.stream))
      session.fail("encoding failed");
    opj_stream_destroy(session.stream);  // flushes the stream's internal buffer into mem
    session.stream = nullptr;
    out.resize(mem.size);
  }

  void decode(const uint8_t* data, size_t size, const Image16& shape, const Setting&, int32_t* dst) override {
    OpjSession session;
    session.codec = opj_create_decompress(OPJ_CODEC_J2K);
    session.quiet();
    opj_dparameters_t params;
    opj_set_default_decoder_parameters(&params);
    if (!opj_setup_decoder(session.codec, &params)) session.fail("decoder setup failed");
    opj_codec_set_threads(session.codec, 1);

    MemoryStream mem;
    mem.data = data;
    mem.size = size;
    session.stream = opj_stream_create(OPJ_J2K_STREAM_CHUNK_SIZE, OPJ_TRUE);
    opj_stream_set_user_data(session.stream, &mem, nullptr);
    opj_stream_set_user_data_length(session.stream, size);
    opj_stream_set_read_function(session.stream, stream_read);
    opj_stream_set_skip_function(session.stream, stream_skip);
    opj_stream_set_seek_function(session.stream, stream_seek);
    if (!opj_read_header(session.stream, session.codec, &session.image)) session.fail("bad header");
    if (!opj_decode(session.codec, session.stream, session.image) ||
        !opj_end_decompress(session.codec, session.stream))
      session.fail("decoding failed");
    const opj_image_comp_t& c = session.image->comps[0];
    if (session.image->numcomps != 1 || int64_t(c.w) != shape.width || int64_t(c.h) != shape.height)
      session.fail("decoded image has the wrong shape");
    std::copy(c.data, c.data + shape.sample_count(), dst);
  }
};

}  // namespace

std::unique_ptr<Peer> make_openjpeg_peer() { return std::make_unique<OpenJpegPeer>(); }

}  // namespace peers
