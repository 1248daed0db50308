// The real residual coder for the pyramid: libcodec's lapped-transform coder behind the
// ResidualCoder interface. Each band of a level becomes one self-contained libcodec stream (with
// its own tile index), so a region decoder can find a band, then decode only the tiles it needs.
#pragma once

#include <cstdint>
#include <memory>

#include "codec/codec.h"
#include "core/error.h"
#include "pyramid/pyramid.h"

namespace terrain {

// libcodec quantises with steps up to its largest sample magnitude; a target so loose that the
// calibration would go beyond it (a constant or all-void grid, --rms 1e6) gets that step, which
// already codes every residual of such a grid as zero.
inline constexpr double kLargestStep = double(1 << 20);

// The levels above the finest that coarse_step_ratio refines one factor more each; coarser ones keep
// the last factor. The rms calibration measures the ratio on windows of a quarter of its 1024 rows,
// whose deep levels are a few rows tall: refined without a limit, a smooth synthetic 2048 x 1536 tile
// at --rms 4 came out at 3.49 m (3.91 m with the limit, 0.0203 b/s against 0.0182).
inline constexpr int kCoarseStepRatioLevels = 2;

struct PtcCoderOptions {
  double step = 1.0;       // quantiser step in level units at the finest level (every level: absolute)
  uint32_t max_error = 0;  // with bound_max_error: |residual error| <= max_error at every sample
  bool bound_max_error = false;
  // false (the paper): one absolute step and max error at every level. true: level l of m + 1 gets
  // step and max error times 2^(m - l), its spacing over the finest one, so every level has the same
  // error in screen space (a level is drawn at a distance proportional to its spacing); capped at
  // kLargestStep and libcodec's largest max error.
  bool screen_level_error = false;
  // Step-coded levels only (not bound_max_error): the level k levels above the finest gets its step
  // times coarse_step_ratio^min(k, kCoarseStepRatioLevels) (then the screen schedule's 2^k), at least
  // 1. In (0, 1]: coarse levels more accurate than the finest predict it better, which pays on smooth
  // terrain at low rates (pyramid-build --rms chooses it by calibration, docs/pyramid.md); 1 is the
  // paper's one absolute step.
  double coarse_step_ratio = 1.0;
  uint32_t tile_size = 64;  // libcodec tile side; also the band height unless band_rows says otherwise
  // Transform of the finer levels' residual streams: Residual (libcodec format 5: 8-17 % fewer bits
  // than Lapped on closed-loop residuals, docs/codec.md) or Lapped (the format-4 streams of .pyr 2.x).
  // The coarsest level, coded as values, always uses Lapped.
  codec::Transform residual_transform = codec::Transform::Residual;
  int64_t band_rows = 0;  // 0: 4 tile rows per band
  // libcodec's phase tiles (format 7), for pyramids whose D is point sampling, where a residual's even
  // phase is the coarse level's error: beside the other modes in max-error streams (bound_max_error,
  // max_error 0 = lossless), every tile with the step as a real-valued bin otherwise.
  bool phase_tiles = false;
};

struct EncodeScratchPool;  // ptc_coder.cpp

// Thrown by PtcResidualCoder for level values beyond the coder's range (InvalidOption; the message
// names the value, not the file: build_pyramid_file adds that).
class ValueRangeError : public Error {
 public:
  using Error::Error;
};

// What to do about level values the coder cannot hold (more than 2^20 units from the coarsest level's
// centre, or residuals as large): the end of the errors that say so.
inline constexpr const char* kValueSpanAdvice =
    "float input is coded in units of --quantum (give a coarser one); integer input in its own units (store "
    "it in coarser ones, centimetres instead of millimetres, or as float32 metres)";

class PtcResidualCoder final : public ResidualCoder {
 public:
  // Throws std::invalid_argument for options libcodec rejects (step < 1, bad tile size) and a
  // coarse_step_ratio outside (0, 1].
  explicit PtcResidualCoder(const PtcCoderOptions& options);
  int64_t band_rows() const override { return band_rows_; }
  // Thread-safe: the builder codes bands in parallel. The coder keeps the encoders' scratch memory
  // (copies of a coder share it) and hands each call the part that suits its band's size.
  // Throws std::runtime_error naming the libcodec status if a band cannot be coded (e.g. a residual
  // beyond libcodec's +-2^20 range). threads: libcodec codes the band's tile rows on that many
  // threads (codec::EncodeOptions::threads; the same bytes).
  std::vector<uint8_t> encode(const int32_t* residual, int64_t w, int64_t h, int32_t* reconstructed,
                              int levels_above_finest, bool coarsest, int threads) override;
  // The band's tiles in up to `parts` chunks on the runner's threads (the same bytes).
  std::vector<uint8_t> encode_parts(const int32_t* residual, int64_t w, int64_t h, int32_t* reconstructed,
                                    int levels_above_finest, bool coarsest, int parts,
                                    PartRunner& runner) override;
  // The same, coded so that its tiles can be spliced into `into` (into_size bytes, an existing stream
  // of the same band; codec::EncodeOptions::phase_model_stream): for editors that re-code some tiles.
  std::vector<uint8_t> encode_spliceable(const int32_t* residual, int64_t w, int64_t h,
                                         int32_t* reconstructed, int levels_above_finest, bool coarsest,
                                         const uint8_t* into, size_t into_size, int threads = 1,
                                         PartRunner* runner = nullptr);
  // The step and max error a level gets (see screen_level_error and coarse_step_ratio).
  PtcCoderOptions level_options(int levels_above_finest) const;
  bool decode(const uint8_t* data, size_t n, int64_t w, int64_t h, int32_t* out) override;
  const PtcCoderOptions& options() const { return options_; }

 private:
  PtcCoderOptions options_;
  int64_t band_rows_;
  std::shared_ptr<EncodeScratchPool> pool_;
};

}  // namespace terrain
