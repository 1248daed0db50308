// Peer-codec benchmark harness: thin wrappers of the Debian-packaged peer codecs (OpenJPEG, OpenJPH,
// libjxl, jxrlib, CharLS, LERC, ZFP, zstd, and our own libcodec) behind one interface, plus the measurement
// loop (codec time only, one thread, best of N) and the error metrics every peer is judged by.
//
// The benchmark codes int16-range integer grids: each Peer gets the same Image16 and must return
// exactly width*height decoded samples; errors are measured by the harness, never by the peer.
// Peers throw PeerError (message names the codec and the problem) when the library reports failure.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "pyramid/error_stats.h"

namespace peers {

class PeerError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A grid of integer heights in int16 range, row-major, row 0 north.
struct Image16 {
  int64_t width = 0;
  int64_t height = 0;
  std::vector<int16_t> samples;  // width*height
  std::vector<uint8_t> valid;  // width*height, 1 = data; empty = all valid. Errors count valid samples only.
  double unit_m = 1.0;         // metres per sample unit (1 for SRTM, 0.2 for Puget Sound halved)
  int64_t sample_count() const { return width * height; }
};

// One point of a peer's parameter sweep. `param` means what the peer says (rate, QP, NEAR, tolerance...).
struct Setting {
  std::string label;  // e.g. "9/7 1.50bps", "near=2"
  double param = 0;
  int mode = 0;                 // peer-specific variant (e.g. lossless vs lossy family)
  double max_error_bound = -1;  // declared max |decoded - input| in sample units; < 0 = no guarantee
};

using Bytes = std::vector<uint8_t>;

class Peer {
 public:
  virtual ~Peer() = default;
  // Short identifier used on the command line and in CSV rows.
  virtual std::string name() const = 0;
  // Library version and every fixed coding parameter, for the report.
  virtual std::string configuration() const = 0;
  // The settings to benchmark for a grid whose sample unit is unit_m metres: error-type parameters
  // (NEAR, max error, tolerance, step) are chosen in metres and converted to sample units, so every
  // grid gets a sweep over the same metre range. `quick` gives a shorter sweep for smoke runs.
  virtual std::vector<Setting> sweep(bool quick, double unit_m) const = 0;
  virtual bool lossless_capable() const = 0;
  // Encodes img into out; on return out.size() is the complete stream size in bytes (everything a
  // decoder needs besides width and height). Reuses out's capacity. Throws PeerError.
  virtual void encode(const Image16& img, const Setting& setting, Bytes& out) = 0;
  // Decodes a stream made by encode() for an image of shape's width/height into dst[width*height].
  virtual void decode(const uint8_t* data, size_t size, const Image16& shape, const Setting& setting,
                      int32_t* dst) = 0;
};

// The sweep of a JPEG 2000 family codec: one 9/7 irreversible setting per parameter, no error bound,
// labelled by printf of label_format with the parameter (its family name is the label up to the
// first space, "9/7"), then the exact 5/3 reversible setting.
inline std::vector<Setting> wavelet_sweep(const std::vector<double>& params, const char* label_format,
                                          int lossy_mode, int lossless_mode) {
  std::vector<Setting> out;
  for (double p : params) {
    char label[48];
    std::snprintf(label, sizeof label, label_format, p);
    out.push_back({label, p, lossy_mode, -1});
  }
  out.push_back({"5/3 lossless", 0, lossless_mode, 0});
  return out;
}

// Every peer linked into this build, in a fixed order.
std::vector<std::unique_ptr<Peer>> all_peers();

// Error figures of decoded against img over valid samples, in sample units.
using ErrorStats = terrain::ErrorStats;
ErrorStats error_stats(const Image16& img, const std::vector<int32_t>& decoded);

struct Result {
  size_t bytes = 0;
  double bits_per_sample = 0;
  double encode_seconds = 0;  // best wall-clock time of encode_reps
  double decode_seconds = 0;  // best wall-clock time of decode_reps
  // Best process CPU time (all threads) of the same repetitions: on a machine shared with other
  // work, wall-clock time includes waiting for a core and CPU time does not.
  double encode_cpu_seconds = 0, decode_cpu_seconds = 0;
  int encode_reps = 0, decode_reps = 0;
  ErrorStats error;
  std::vector<int32_t> decoded;
};

// Encodes and decodes img with one setting, timing encode and decode separately with
// std::chrono::steady_clock (and process CPU time): each is repeated until its repetitions total at
// least min_total_seconds of wall time (see best_time) and the fastest
// repetition is kept.
Result measure(Peer& peer, const Image16& img, const Setting& setting, double min_total_seconds,
               int max_reps);

// CPU time of the whole process (all threads), in seconds.
double process_cpu_seconds();

// Runs fn until the runs total min_total_seconds of wall time (at least twice when max_reps allows:
// a first run alone is cold (page faults on fresh buffers, tables built on first use) and was 5x
// slower than the next for libcodec's encoder; at most max_reps); returns the fastest wall-clock time
// and stores the fastest CPU time in *best_cpu.
template <class Fn>
double best_time(Fn&& fn, double min_total_seconds, int max_reps, int* reps, double* best_cpu) {
  using clock = std::chrono::steady_clock;
  double best = std::numeric_limits<double>::infinity(), total = 0;
  *best_cpu = std::numeric_limits<double>::infinity();
  int count = 0;
  do {
    const double c0 = process_cpu_seconds();
    const auto t0 = clock::now();
    fn();
    const double t = std::chrono::duration<double>(clock::now() - t0).count();
    *best_cpu = std::min(*best_cpu, process_cpu_seconds() - c0);
    best = std::min(best, t);
    total += t;
    ++count;
  } while ((total < min_total_seconds || count < 2) && count < max_reps);
  *reps = count;
  return best;
}

// One (error, bits/sample) point of a sweep. Points of one family come from one parameter sweep of
// one mode (e.g. libcodec's step sweep, or its max-error sweep).
struct RatePoint {
  double error = 0;
  double bits = 0;
  int family = 0;
};
// Bits/sample needed for `target` error: within each family, log-log interpolated on the lower
// envelope of its points (those with error > 0; a point exactly at the target returns its rate);
// the cheapest family wins, so one mode's points never raise another mode's curve. A target below a
// family's smallest non-zero error is met by the lossless point (error 0, any family) when there is
// one: its rate is returned. Returns a negative value when target lies outside what the points can show.
double bits_at_error(std::vector<RatePoint> points, double target);

}  // namespace peers
