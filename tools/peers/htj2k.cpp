// High-throughput JPEG 2000 (HTJ2K, JPEG 2000 Part 15) peer through OpenJPH: raw J2K codestream in
// memory, one component of 16-bit signed samples (the Image16 values as they are, no offset), one
// tile, 5 decompositions and 64x64 code-blocks as the OpenJPEG peer. HTJ2K has no rate control: the
// lossy sweep is the base quantisation step of the 9/7 irreversible wavelet (OpenJPH derives every
// subband's step from it); lossless is the 5/3 reversible wavelet. OpenJPH runs on the calling thread.
// ojph_arch.h defines OJPH_EXPORT, which the other headers use without including it.
#include <openjph/ojph_arch.h>
#include <openjph/ojph_codestream.h>
#include <openjph/ojph_file.h>
#include <openjph/ojph_mem.h>
#include <openjph/ojph_message.h>
#include <openjph/ojph_params.h>
#include <openjph/ojph_version.h>

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstring>

#include "peers.h"

namespace peers {
namespace {

constexpr int kLossy97 = 0;
constexpr int kLossless53 = 1;
constexpr uint32_t kBitDepth = 16;

// OpenJPH reports errors through a global handler that prints and throws std::runtime_error; this
// one throws a PeerError carrying the library's message instead, so the harness can report it.
class ThrowingError final : public ojph::message_error {
 public:
  void operator()(int code, const char*, int, const char* format, ...) override {
    char text[512];
    va_list args;
    va_start(args, format);
    std::vsnprintf(text, sizeof text, format, args);
    va_end(args);
    char code_text[32];
    std::snprintf(code_text, sizeof code_text, " (OpenJPH error 0x%x)", unsigned(code));
    throw PeerError(std::string("htj2k: ") + text + code_text);
  }
};

// Info and warning messages would interleave with the benchmark's own output.
class QuietWarning final : public ojph::message_warning {
 public:
  void operator()(int, const char*, int, const char*, ...) override {}
};
class QuietInfo final : public ojph::message_info {
 public:
  void operator()(int, const char*, int, const char*, ...) override {}
};

void install_message_handlers() {
  static ThrowingError error;
  static QuietWarning warning;
  static QuietInfo info;
  ojph::configure_error(&error);
  ojph::configure_warning(&warning);
  ojph::configure_info(&info);
}

// Codestream output straight into the caller's byte vector (keeps its capacity across encodes,
// unlike ojph::mem_outfile, which frees its buffer on close).
class BytesOutfile final : public ojph::outfile_base {
 public:
  explicit BytesOutfile(Bytes& out) : out_(out) { out_.clear(); }
  size_t write(const void* ptr, size_t size) override {
    const auto* p = static_cast<const uint8_t*>(ptr);
    out_.insert(out_.end(), p, p + size);
    return size;
  }
  ojph::si64 tell() override { return ojph::si64(out_.size()); }

 private:
  Bytes& out_;
};

class Htj2kPeer final : public Peer {
 public:
  Htj2kPeer() { install_message_handlers(); }
  std::string name() const override { return "htj2k"; }
  std::string configuration() const override {
    return "OpenJPH " + std::to_string(OPENJPH_VERSION_MAJOR) + "." + std::to_string(OPENJPH_VERSION_MINOR) +
           "." + std::to_string(OPENJPH_VERSION_PATCH) +
           ": HTJ2K raw codestream, 1 component 16-bit signed, 5 decompositions, 64x64 code-blocks, one "
           "tile, RPCL, 1 thread; lossy = 9/7 irreversible with base quantisation step = step / 2^16 "
           "(step sweep in metres), lossless = 5/3 reversible";
  }
  bool lossless_capable() const override { return true; }
  std::vector<Setting> sweep(bool quick, double unit_m) const override {
    const std::vector<double> metres =
        quick ? std::vector<double>{0.5, 1, 2, 4, 8, 16, 32}
              : std::vector<double>{0.25, 0.5, 0.75, 1, 1.5, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48};
    std::vector<double> steps;  // sample units
    for (double m : metres) steps.push_back(m / unit_m);
    return wavelet_sweep(steps, "9/7 step=%gu", kLossy97, kLossless53);
  }

  void encode(const Image16& img, const Setting& setting, Bytes& out) override {
    const auto w = ojph::ui32(img.width), h = ojph::ui32(img.height);
    ojph::codestream codestream;
    ojph::param_siz siz = codestream.access_siz();
    siz.set_image_extent(ojph::point(w, h));
    siz.set_tile_size(ojph::size(w, h));
    siz.set_num_components(1);
    siz.set_component(0, ojph::point(1, 1), kBitDepth, true);
    ojph::param_cod cod = codestream.access_cod();
    cod.set_num_decomposition(5);
    cod.set_block_dims(64, 64);
    cod.set_progression_order("RPCL");
    cod.set_color_transform(false);
    cod.set_reversible(setting.mode == kLossless53);
    // OpenJPH normalises samples to [-1/2, 1/2), so a step of s sample units is s / 2^bit_depth.
    if (setting.mode == kLossy97)
      codestream.access_qcd().set_irrev_quant(float(setting.param / std::ldexp(1.0, kBitDepth)));
    codestream.set_planar(false);

    BytesOutfile file(out);
    codestream.write_headers(&file);
    ojph::ui32 component = 0;
    ojph::line_buf* line = codestream.exchange(nullptr, component);
    for (ojph::ui32 y = 0; y < h; ++y) {
      const int16_t* row = img.samples.data() + size_t(y) * w;
      std::copy(row, row + w, line->i32);
      line = codestream.exchange(line, component);
    }
    codestream.flush();
    codestream.close();
  }

  void decode(const uint8_t* data, size_t size, const Image16& shape, const Setting&, int32_t* dst) override {
    ojph::mem_infile file;
    file.open(data, size);
    ojph::codestream codestream;
    codestream.read_headers(&file);
    ojph::param_siz siz = codestream.access_siz();
    if (siz.get_num_components() != 1 || int64_t(siz.get_recon_width(0)) != shape.width ||
        int64_t(siz.get_recon_height(0)) != shape.height)
      throw PeerError("htj2k: decoded image has the wrong shape");
    codestream.set_planar(false);
    codestream.create();
    const size_t w = size_t(shape.width);
    for (int64_t y = 0; y < shape.height; ++y) {
      ojph::ui32 component = 0;
      const ojph::line_buf* line = codestream.pull(component);
      if (component != 0 || line->size < w) throw PeerError("htj2k: unexpected decoded line");
      std::copy(line->i32, line->i32 + w, dst + size_t(y) * w);
    }
    codestream.close();
  }
};

}  // namespace

std::unique_ptr<Peer> make_htj2k_peer() { return std::make_unique<Htj2kPeer>(); }

}  // namespace peers
