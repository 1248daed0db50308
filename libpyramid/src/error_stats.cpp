#include "pyramid/error_stats.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace terrain {

ErrorStats error_stats(std::vector<double>& abs_err, double range) {
  ErrorStats s;
  s.count = int64_t(abs_err.size());
  if (abs_err.empty()) return s;
  double sq = 0;
  for (double e : abs_err) sq += e * e, s.max_abs = std::max(s.max_abs, e);
  s.rms = std::sqrt(sq / double(abs_err.size()));
  const size_t k = std::min(abs_err.size() - 1, size_t(std::ceil(0.999 * double(abs_err.size()))) - 1);
  std::nth_element(abs_err.begin(), abs_err.begin() + std::ptrdiff_t(k), abs_err.end());
  s.p999_abs = abs_err[k];
  s.psnr_db = s.rms > 0 ? 20 * std::log10(range / s.rms) : std::numeric_limits<double>::infinity();
  return s;
}

ErrorStats error_stats(const double* reference, const double* decoded, const uint8_t* valid, size_t n) {
  std::vector<double> abs_err;
  abs_err.reserve(n);
  double zmin = std::numeric_limits<double>::infinity(), zmax = -zmin;
  for (size_t i = 0; i < n; ++i) {
    if (valid && !valid[i]) continue;
    zmin = std::min(zmin, reference[i]);
    zmax = std::max(zmax, reference[i]);
    abs_err.push_back(std::fabs(decoded[i] - reference[i]));
  }
  return error_stats(abs_err, std::max(zmax - zmin, 1e-300));
}

}  // namespace terrain
