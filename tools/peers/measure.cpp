// Measurement shared by all peers: timing loop, error statistics (terrain::error_stats) and rate
// interpolation. Keeping it outside the peers guarantees every codec is timed and judged the same way.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <limits>

#include "peers.h"

namespace peers {

ErrorStats error_stats(const Image16& img, const std::vector<int32_t>& decoded) {
  const size_t n = size_t(img.sample_count());
  if (decoded.size() != n) throw PeerError("decoded sample count does not match the image");
  const std::vector<double> reference(img.samples.begin(), img.samples.end());
  const std::vector<double> out(decoded.begin(), decoded.end());
  return terrain::error_stats(reference.data(), out.data(), img.valid.empty() ? nullptr : img.valid.data(),
                              n);
}

double process_cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

Result measure(Peer& peer, const Image16& img, const Setting& setting, double min_total_seconds,
               int max_reps) {
  Result r;
  Bytes stream;
  r.encode_seconds = best_time([&] { peer.encode(img, setting, stream); }, min_total_seconds, max_reps,
                               &r.encode_reps, &r.encode_cpu_seconds);
  r.bytes = stream.size();
  r.bits_per_sample = 8.0 * double(r.bytes) / double(img.sample_count());
  r.decoded.assign(size_t(img.sample_count()), 0);
  r.decode_seconds =
      best_time([&] { peer.decode(stream.data(), stream.size(), img, setting, r.decoded.data()); },
                min_total_seconds, max_reps, &r.decode_reps, &r.decode_cpu_seconds);
  r.error = error_stats(img, r.decoded);
  return r;
}

namespace {

// One family's lossy points (already without the lossless ones): bits at target on their lower envelope.
double family_bits_at_error(std::vector<RatePoint> points, double target, double lossless) {
  std::sort(points.begin(), points.end(), [](const RatePoint& a, const RatePoint& b) {
    return a.error < b.error || (a.error == b.error && a.bits < b.bits);
  });
  // Lower envelope: a point is useful only if it needs fewer bits than every point with less error.
  std::vector<RatePoint> envelope;
  for (const RatePoint& p : points)
    if (envelope.empty() || p.bits < envelope.back().bits) envelope.push_back(p);
  if (!(target > 0)) return lossless;
  if (envelope.empty() || target < envelope.front().error) return lossless;  // -1 without one
  if (target > envelope.back().error) return -1;
  for (size_t i = 0; i < envelope.size(); ++i) {
    if (envelope[i].error == target) return envelope[i].bits;
    if (i + 1 < envelope.size() && target < envelope[i + 1].error) {
      const RatePoint& a = envelope[i];
      const RatePoint& b = envelope[i + 1];
      const double t = std::log(target / a.error) / std::log(b.error / a.error);
      return std::exp(std::log(a.bits) + t * (std::log(b.bits) - std::log(a.bits)));
    }
  }
  return envelope.back().bits;
}

}  // namespace

double bits_at_error(std::vector<RatePoint> points, double target) {
  // A lossless point (error 0) meets every target: it caps the rate and dominates any lossy point
  // that costs more.
  double lossless = -1;
  for (const RatePoint& p : points)
    if (p.error == 0 && p.bits > 0 && (lossless < 0 || p.bits < lossless)) lossless = p.bits;
  std::erase_if(points, [lossless](const RatePoint& p) {
    return !(p.error > 0) || !(p.bits > 0) || (lossless > 0 && p.bits >= lossless);
  });
  std::vector<int> families;
  for (const RatePoint& p : points)
    if (std::find(families.begin(), families.end(), p.family) == families.end()) families.push_back(p.family);
  if (families.empty()) return lossless;  // -1 without one
  double best = -1;
  for (int f : families) {
    std::vector<RatePoint> mine;
    for (const RatePoint& p : points)
      if (p.family == f) mine.push_back(p);
    const double b = family_bits_at_error(std::move(mine), target, lossless);
    if (b > 0 && (best < 0 || b < best)) best = b;
  }
  return best;
}

}  // namespace peers
