// PtcResidualCoder: adapts libcodec's caller-buffer API to the pyramid's ResidualCoder interface.
#include "build/ptc_coder.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>

#include "codec/codec.h"
#include "core/error.h"

namespace terrain {
namespace {

codec::EncodeOptions to_codec(const PtcCoderOptions& o) {
  codec::EncodeOptions c;
  c.step = o.step;
  c.bound_max_error = o.bound_max_error;
  c.max_error = o.max_error;
  c.tile_size = o.tile_size;
  c.phase_tiles = o.phase_tiles;
  return c;
}

// One scratch per thread for decode(), which several threads may call at once (encode() takes its
// scratch from the coder's pool).
codec::Scratch& thread_scratch() {
  thread_local codec::Scratch scratch;
  return scratch;
}

}  // namespace

// What one encode call needs besides the band: libcodec's scratch (its payload buffer grows to a
// band's stream) and the output buffer.
struct EncodeScratch {
  codec::Scratch scratch;
  std::unique_ptr<uint8_t[]> buffer;
  size_t capacity = 0;
  int64_t samples = 0;  // the largest band it coded
};

// The coder's encode scratch, handed out by band size: a call gets the free one that coded the
// smallest band at least as large as its own, else the largest free one (which then grows). So the
// large ones number the large bands coded at once (the builder's bands in flight of the finest
// level, which its memory plan counts), whatever the thread count. Thread-local buffers grew to a
// finest band's size on every coding thread, and the builder's rounds start fresh threads whose
// freed buffers the allocator's per-thread arenas kept: a 32768^2 --lossless or --step 2 build
// under --memory 1G peaked at 1013-1014 MiB with 16 threads and 1025-1027 MiB with 64 (estimate
// 972 / 995 MiB; docs/scale.md "The budget").
struct EncodeScratchPool {
  std::mutex lock;
  std::vector<std::unique_ptr<EncodeScratch>> free;

  std::unique_ptr<EncodeScratch> take(int64_t samples) {
    const std::lock_guard<std::mutex> hold(lock);
    if (free.empty()) return std::make_unique<EncodeScratch>();
    // Whether a suits the band better than b: one that fits over one that does not, then the smaller
    // of two that fit, the larger of two that do not.
    const auto better = [samples](int64_t a, int64_t b) {
      const bool a_fits = a >= samples, b_fits = b >= samples;
      return a_fits != b_fits ? a_fits : a_fits ? a < b : a > b;
    };
    size_t pick = 0;
    for (size_t i = 1; i < free.size(); ++i)
      if (better(free[i]->samples, free[pick]->samples)) pick = i;
    std::unique_ptr<EncodeScratch> got = std::move(free[pick]);
    free.erase(free.begin() + ptrdiff_t(pick));
    return got;
  }
  void give(std::unique_ptr<EncodeScratch> s) {
    const std::lock_guard<std::mutex> hold(lock);
    free.push_back(std::move(s));
  }
};

PtcResidualCoder::PtcResidualCoder(const PtcCoderOptions& options)
    : options_(options),
      band_rows_(options.band_rows > 0 ? options.band_rows : 4 * int64_t(options.tile_size)),
      pool_(std::make_shared<EncodeScratchPool>()) {
  if (codec::encode_bound(16, 16, to_codec(options_)) == 0)
    throw std::invalid_argument("residual coder: invalid options (step " + std::to_string(options_.step) +
                                ", tile size " + std::to_string(options_.tile_size) + ")");
  if (!(options_.coarse_step_ratio > 0 && options_.coarse_step_ratio <= 1))
    throw std::invalid_argument("residual coder: coarse step ratio " +
                                std::to_string(options_.coarse_step_ratio) + " is outside (0, 1]");
}

static_assert(kLargestStep == double(codec::kMaxAbsSample),
              "ptc_coder.h's step cap is libcodec's largest sample");

PtcCoderOptions PtcResidualCoder::level_options(int levels_above_finest) const {
  PtcCoderOptions o = options_;
  // Zero error (lossless, or a max error of 0) is zero in screen space too: every level stays exact.
  if (levels_above_finest <= 0 || (o.bound_max_error ? o.max_error == 0 : o.step <= 1)) return o;
  const int k = std::min(levels_above_finest, 40);
  const double screen = o.screen_level_error ? std::ldexp(1.0, k) : 1.0;
  if (o.bound_max_error) {
    o.step = std::min(o.step * screen, kLargestStep);
    o.max_error = uint32_t(std::min(double(o.max_error) * screen, double(codec::kMaxAbsSample)));
  } else {
    o.step = std::clamp(o.step * std::pow(o.coarse_step_ratio, std::min(k, kCoarseStepRatioLevels)) * screen,
                        1.0, kLargestStep);
  }
  return o;
}

std::vector<uint8_t> PtcResidualCoder::encode(const int32_t* residual, int64_t w, int64_t h,
                                              int32_t* reconstructed, int levels_above_finest, bool coarsest,
                                              int threads) {
  return encode_spliceable(residual, w, h, reconstructed, levels_above_finest, coarsest, nullptr, 0, threads);
}

std::vector<uint8_t> PtcResidualCoder::encode_parts(const int32_t* residual, int64_t w, int64_t h,
                                                    int32_t* reconstructed, int levels_above_finest,
                                                    bool coarsest, int parts, PartRunner& runner) {
  return encode_spliceable(residual, w, h, reconstructed, levels_above_finest, coarsest, nullptr, 0, parts,
                           &runner);
}

std::vector<uint8_t> PtcResidualCoder::encode_spliceable(const int32_t* residual, int64_t w, int64_t h,
                                                         int32_t* reconstructed, int levels_above_finest,
                                                         bool coarsest, const uint8_t* into, size_t into_size,
                                                         int threads, PartRunner* runner) {
  codec::EncodeOptions copts = to_codec(level_options(levels_above_finest));
  copts.threads = uint32_t(std::max(1, threads));
  copts.part_runner = runner;
  copts.transform = coarsest ? codec::Transform::Lapped : options_.residual_transform;
  copts.phase_model_stream = into;
  copts.phase_model_stream_size = into_size;
  // A fresh zero-filled buffer per band cost 8-14% of the build's CPU in page faults, so the pool's
  // buffers are kept and the bytes copied out. The bound is ~16 bytes per sample and a band's stream
  // ~0.3: a buffer of the bound was most of a wide input's memory (a 4194304-column band of 64 rows,
  // 4 GiB). The buffer starts at kGuessBytesPerSample and is not zero-filled (pages the coder never
  // writes stay unmapped); a stream that does not fit (noise coded losslessly) is coded again into
  // the bound, with the same result.
  constexpr size_t kGuessBytesPerSample = 2;
  struct Taken {
    EncodeScratchPool& pool;
    std::unique_ptr<EncodeScratch> s;
    ~Taken() { pool.give(std::move(s)); }
  } taken{*pool_, pool_->take(w * h)};
  EncodeScratch& es = *taken.s;
  es.samples = std::max(es.samples, w * h);
  const auto reserve = [&es](size_t bytes) {
    if (es.capacity >= bytes) return;
    es.buffer.reset(new uint8_t[bytes]);
    es.capacity = bytes;
  };
  const size_t bound = codec::encode_bound(w, h, copts);
  reserve(std::min(bound, (size_t(1) << 16) + kGuessBytesPerSample * size_t(w) * size_t(h)));
  size_t written = 0;
  codec::Status s = codec::encode(residual, w, w, h, copts, es.buffer.get(), es.capacity, &written,
                                  es.scratch, reconstructed, w);
  if (s == codec::Status::BufferTooSmall && es.capacity < bound) {
    reserve(bound);
    s = codec::encode(residual, w, w, h, copts, es.buffer.get(), es.capacity, &written, es.scratch,
                      reconstructed, w);
  }
  if (s != codec::Status::Ok) {
    int64_t largest = 0;
    for (int64_t i = 0; i < w * h; ++i) largest = std::max<int64_t>(largest, std::abs(int64_t(residual[i])));
    if (s == codec::Status::ValueOutOfRange)
      throw ValueRangeError(ErrorCode::InvalidOption,
                            "level values beyond the coder's range: a " +
                                std::string(coarsest ? "coarsest-level value" : "residual") + " of " +
                                std::to_string(largest) + " units from its centre, where at most " +
                                std::to_string(codec::kMaxAbsSample) +
                                " (2^20) fit (the input's values span too many units, "
                                "or vary by that much between neighbours); " +
                                kValueSpanAdvice);
    throw std::runtime_error(std::string("residual coder: libcodec encode failed (") + std::to_string(w) +
                             "x" + std::to_string(h) + " band, largest |residual| " +
                             std::to_string(largest) + "): " + codec::status_name(s));
  }
  codec::HeaderInfo header;
  // An all-empty stream (every tile decodes to zeros) becomes no bytes at all: the band table marks it.
  if (codec::read_header(es.buffer.get(), written, &header) == codec::Status::Ok && header.empty()) return {};
  return std::vector<uint8_t>(es.buffer.get(), es.buffer.get() + written);
}

bool PtcResidualCoder::decode(const uint8_t* data, size_t n, int64_t w, int64_t h, int32_t* out) {
  if (n == 0) {  // an all-zero band
    std::fill_n(out, size_t(w * h), 0);
    return true;
  }
  codec::Decoder d;
  if (d.open(data, n) != codec::Status::Ok) return false;
  if (d.header().width != w || d.header().height != h) return false;
  return d.decode_region(codec::Rect{0, 0, w, h}, out, w, thread_scratch()) == codec::Status::Ok;
}

}  // namespace terrain
