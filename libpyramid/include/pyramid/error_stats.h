// Error figures of a decoded height grid against its reference: the one definition of rms, max,
// 99.9th percentile and PSNR that every report and benchmark uses, so their figures compare.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace terrain {

struct ErrorStats {
  int64_t count = 0;    // samples that counted
  double rms = 0;       // sqrt(mean of e^2)
  double max_abs = 0;   // max |e|
  double p999_abs = 0;  // 99.9th percentile of |e|, nearest rank: the smallest |e| that at least
                        // 99.9 % of the samples do not exceed
  double psnr_db = 0;   // 20 log10(range / rms); +inf when rms is 0 (lossless)
};

// Returns the figures of abs_err, the |decoded - reference| of every sample that counts (the caller
// leaves out voids and any other masked samples), in any one unit; `range` is zmax - zmin of the
// reference in that unit over the samples the caller chooses, and must be > 0. Reorders abs_err.
// All zero (count 0) when abs_err is empty. Never throws; thread-safe.
ErrorStats error_stats(std::vector<double>& abs_err, double range);

// The same for decoded[i] against reference[i], i < n, counting the samples with valid[i] != 0
// (valid null: all). The range is the counted reference samples' zmax - zmin (at least 1e-300, so a
// flat reference gives a large finite PSNR). Throws std::bad_alloc only; thread-safe.
ErrorStats error_stats(const double* reference, const double* decoded, const uint8_t* valid, size_t n);

}  // namespace terrain
