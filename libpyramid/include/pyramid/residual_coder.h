// How the builder codes residual bands: the interface the real coder implements (build/ptc_coder.h,
// through libcodec) and a uniform quantiser for tests and references.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/fork_join.h"

namespace terrain {

// Residual coding interface (the real coder lives in libcodec and implements this).

class ResidualCoder {
 public:
  virtual ~ResidualCoder() = default;
  // Rows per band the coder wants at the finest level: the builder codes each level as consecutive,
  // independent bands (the last one shorter), level l of m+1 with max(1, band_rows >> (m - l)) rows
  // so that coarse bands do not hold back the finer levels. Each band is a whole image to the coder.
  virtual int64_t band_rows() const = 0;
  // encode/decode may be called concurrently from several threads (one band each).
  // Codes one band of integer residuals (w x h, row-major) and writes into `reconstructed` the exact
  // values decode() will produce from the returned bytes. A coder may return no bytes for a band
  // that reconstructs to all zeros (decode then gets n = 0); the pyramid file stores no stream for it.
  // levels_above_finest: 0 for the finest level, m - l for level l of m + 1 (a coder may scale its
  // error with the level's spacing; decode() never needs it: streams carry their own step).
  // coarsest: the band belongs to level 0, whose "residual" is the level itself (heights, not the
  // small closed-loop residual of the finer levels), so a coder may transform it differently.
  // threads: how many threads the coder may use for this band, the calling thread included (>= 1);
  // the bytes and the reconstruction must not depend on it.
  virtual std::vector<uint8_t> encode(const int32_t* residual, int64_t w, int64_t h, int32_t* reconstructed,
                                      int levels_above_finest, bool coarsest, int threads) = 0;
  // Experimental: encode() with the band split into at most `parts` parts that `runner` runs (the
  // builder's coding workers, which the parts of all the bands coded at once share); the bytes and
  // the reconstruction are encode()'s. The default codes the band on the calling thread alone.
  virtual std::vector<uint8_t> encode_parts(const int32_t* residual, int64_t w, int64_t h,
                                            int32_t* reconstructed, int levels_above_finest, bool coarsest,
                                            int parts, PartRunner& runner) {
    (void)parts, (void)runner;
    return encode(residual, w, h, reconstructed, levels_above_finest, coarsest, 1);
  }
  // Decodes one band; false on malformed or truncated data (never crashes, never reads past n).
  virtual bool decode(const uint8_t* data, size_t n, int64_t w, int64_t h, int32_t* out) = 0;
};

// Uniform scalar quantiser, one absolute step for every level: q = sign(r) * floor((|r| + S/2) / S),
// reconstruction q*S, so |r - r^| <= S/2 (step 1 is lossless). Bytes: zigzag LEB128 varints of q.
class UniformQuantizerCoder final : public ResidualCoder {
 public:
  explicit UniformQuantizerCoder(int32_t step, int64_t band_rows = 64);
  int64_t band_rows() const override { return band_rows_; }
  // One step at every level (levels_above_finest is ignored); one thread.
  std::vector<uint8_t> encode(const int32_t* residual, int64_t w, int64_t h, int32_t* reconstructed,
                              int levels_above_finest, bool coarsest, int threads) override;
  bool decode(const uint8_t* data, size_t n, int64_t w, int64_t h, int32_t* out) override;
  int32_t step() const { return step_; }

 private:
  int32_t step_;
  int64_t band_rows_;
};

}  // namespace terrain
