// A pyramid held in memory (tests, small inputs) and its whole-level decoder.
#pragma once

#include <cstdint>
#include <vector>

#include "pyramid/builder.h"
#include "pyramid/residual_coder.h"

namespace terrain {

// An in-memory sink (tests, small inputs) and a decoder over it.
class MemoryPyramid final : public PyramidSink {
 public:
  struct Band {
    int64_t y0, rows;
    std::vector<uint8_t> bytes;
  };
  PyramidHeader header;
  std::vector<std::vector<Band>> bands;     // [level][band]
  std::vector<uint8_t> mask;                // finest level, row-major (1 = data); empty: no voids
  std::vector<std::vector<int32_t>> recon;  // [level] when keep_reconstruction
  bool keep_reconstruction = true;

  void begin(const PyramidHeader& h) override;
  void band(int level, int64_t y0, int64_t rows, std::vector<uint8_t>&& bytes) override;
  void mask_rows(int64_t y0, int64_t rows, const uint8_t* valid) override;
  bool wants_reconstruction(int) const override { return keep_reconstruction; }
  void reconstructed_rows(int level, int64_t y0, int64_t rows, int64_t width, const int32_t* data) override;
  uint64_t total_bytes() const;  // coded residual bytes
};

// Decodes levels 0..up_to_level coarse to fine (U + decoded residual) and returns level
// up_to_level; valid (when non-null) receives the finest level's mask when up_to_level is finest.
// Throws Error(CorruptData) on bad bytes.
std::vector<int32_t> decode_pyramid(const MemoryPyramid& pyramid, ResidualCoder& coder, int up_to_level,
                                    std::vector<uint8_t>* valid = nullptr);

}  // namespace terrain
