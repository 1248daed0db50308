// The closed-loop residual pyramid, built in one streaming pass over the input, without spilling
// the levels to disk (disk writes are the bottleneck of out-of-core builds).
//
// Every level is a stream of rows. The input rows (converted to int32, voids filled) are the finest
// level T_m; a cascade of D row engines turns rows of T_l into rows of T_{l-1} as soon as enough of
// them exist. The D filter is fitted first, on windows in the top fit_rows rows (the same rows
// whatever the input's chunking, so in-memory and streamed builds agree).
//
// The closed loop runs behind the cascade: a band of level l is coded once its own rows exist and
// the decoded coarser level T^_{l-1} covers the rows U needs there. D has finite support, so T_0 row j
// depends only on T_m rows near 2^m j: each level lags the input by a bounded number of rows
// (about 8 * 2^l rows of level l), and every level holds only that lag in a ring of rows. Memory is
// therefore independent of the input height, O(width * 2^m) for m+1 levels.
//
// Bands go to the sink as they are coded, levels interleaved: arranging them for a file (levels
// contiguous, coarsest first) is the container writer's job, so builds into memory or into a
// counting sink write nothing.
#include <time.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <limits>
#include <memory>
#include <mutex>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <tuple>
#include <utility>

#include "pyramid/internal/filter_downsample.h"
#include "pyramid/internal/pyramid_fill.h"
#include "pyramid/internal/pyramid_parallel.h"
#include "pyramid/pyramid.h"

namespace terrain {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// CPU seconds of the calling thread (the build log's account of the main thread's share).
double thread_cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

inline int32_t saturate(int64_t v) {
  return int32_t(
      std::clamp<int64_t>(v, std::numeric_limits<int32_t>::min(), std::numeric_limits<int32_t>::max()));
}

void validate(const BuildOptions& o, const GridInfo& info) {
  if (info.width <= 0 || info.height <= 0)
    throw std::invalid_argument("pyramid: input has no samples (" + std::to_string(info.width) + "x" +
                                std::to_string(info.height) + ")");
  if (o.threads < 1 || o.threads > 256) throw std::invalid_argument("pyramid: threads must be 1..256");
  if (!(o.value_scale > 0) || !std::isfinite(o.value_scale))
    throw std::invalid_argument("pyramid: value_scale must be finite and > 0");
  if (!(std::abs(o.value_offset) <= 2147483647.0) || o.value_offset != std::nearbyint(o.value_offset))
    throw std::invalid_argument("pyramid: value_offset must be an integer within int32");
  if (o.fill_band_rows < 1) throw std::invalid_argument("pyramid: fill_band_rows must be >= 1");
  if (o.fit_rows < 1) throw std::invalid_argument("pyramid: fit_rows must be >= 1");
  if (o.level_count < 0) throw std::invalid_argument("pyramid: level_count must be >= 0");
  if (o.memory_budget < 0) throw std::invalid_argument("pyramid: memory_budget must be >= 0");
  if (o.use_fixed_filter && !(std::abs(o.fixed_filter.sum() - 1.0) < 1e-9))
    throw std::invalid_argument("pyramid: the fixed filter must sum to 1");
}

// Input samples -> level integers (value * scale, rounded; integer grids must stay integers) with the
// voids filled by push-pull. Bands must come in order and be opt.fill_band_rows tall (the last one
// shorter), so the fill - and everything after it - never depends on how the input was chunked.
class InputConverter {
 public:
  InputConverter(const BuildOptions& opt, const GridInfo& info)
      : scale_(opt.value_scale),
        offset_(opt.value_offset),
        exact_(info.integer_valued() && opt.value_scale == 1.0),
        width_(info.width) {}

  // Converts rows y.. of a band and fills its voids: convert_rows on the whole band, then fill.
  // Returns the number of voids in the band.
  int64_t convert(const double* values, const uint8_t* valid, int64_t y, int64_t rows, int32_t* ints) {
    const int64_t voids = convert_rows(values, valid, y, rows, ints);
    if (voids) fill(valid, rows, ints);
    return voids;
  }

  // Converts `rows` rows starting at input row y, voids as 0; returns the number of voids. A band
  // may be converted in pieces, in order, before it is filled.
  int64_t convert_rows(const double* values, const uint8_t* valid, int64_t y, int64_t rows, int32_t* ints) {
    const int64_t W = width_;
    int64_t voids = 0;
    if (exact_ && offset_ == 0.0) {
      // Integer input in its own units (most DEMs): the same checks and messages as below without
      // nearbyint, a library call per sample (the value is integral exactly when its int32 converts
      // back to it). 2.5x faster (6.1 -> 2.4 % of a one-thread build's samples, 8192^2 --step 2); a
      // branch-free form that vectorises was slower (3.9 %: the branches here always predict).
      constexpr double kMax = double(std::numeric_limits<int32_t>::max());
      for (int64_t k = 0; k < rows * W; ++k) {
        const double v = values[k];
        int32_t i = 0;
        if (valid[k]) {
          if (!(std::abs(v) <= kMax))
            throw std::invalid_argument("pyramid input: sample at row " + std::to_string(y + k / W) +
                                        ", column " + std::to_string(k % W) +
                                        " does not fit int32 after scaling");
          i = int32_t(v);
          if (double(i) != v)
            throw std::invalid_argument("pyramid input: non-integer sample in an integer grid at row " +
                                        std::to_string(y + k / W) + ", column " + std::to_string(k % W));
        } else {
          ++voids;
        }
        ints[k] = i;
      }
      return voids;
    }
    for (int64_t k = 0; k < rows * W; ++k) {
      if (!valid[k]) {
        ++voids;
        ints[k] = 0;
        continue;
      }
      const double v = values[k] * scale_;
      const double r = std::nearbyint(v) - offset_;
      if (!(std::abs(r) <= double(std::numeric_limits<int32_t>::max())))
        throw std::invalid_argument("pyramid input: sample at row " + std::to_string(y + k / W) +
                                    ", column " + std::to_string(k % W) +
                                    " does not fit int32 after scaling");
      if (exact_ && r + offset_ != v)
        throw std::invalid_argument("pyramid input: non-integer sample in an integer grid at row " +
                                    std::to_string(y + k / W) + ", column " + std::to_string(k % W));
      ints[k] = int32_t(r);
    }
    return voids;
  }

  // Whether the level integers are the input samples themselves (integers in their own units).
  bool identity() const { return exact_ && offset_ == 0.0; }

  // Fills the voids of a whole converted band (push-pull; carries state from band to band). Throws
  // StripeRowsAboveNeeded where the carry is unknown (forget_carry) and this band would use it.
  void fill(const uint8_t* valid, int64_t rows, int32_t* ints) {
    if (!carry_known_) {
      // The carry comes in only where the band's first tile has no valid sample: every tile, void or
      // not, sets it from its own samples when it has any, and tiles are taken left to right.
      const int64_t tw = std::min(kFillTile, width_);
      for (int64_t y = 0; y < rows && !carry_known_; ++y)
        carry_known_ = std::memchr(valid + y * width_, 1, size_t(tw)) != nullptr;
      if (!carry_known_) throw StripeRowsAboveNeeded("pyramid: a void fill needs the rows above the stripe");
    }
    detail::fill_voids(ints, valid, width_, rows, kFillTile, &carry_, scratch_);
  }
  // The rows that would set the carry were skipped (BuildStripe::seek_above).
  void forget_carry() { carry_known_ = false; }

 private:
  static constexpr int64_t kFillTile = 256;
  double scale_, offset_;
  bool exact_;
  int64_t width_;
  int32_t carry_ = 0;
  bool carry_known_ = true;
  detail::PushPullScratch scratch_;
};

// Per-band state of the closed loop, reused across band groups.
struct BandWork {
  int64_t y0 = 0, rows = 0;
  // Its rows of T_l and validity as the level holds them, taken when the band is scheduled: the coder
  // threads read them while the main thread appends rows (each row is a buffer of its own, which
  // neither appending nor dropping other rows moves).
  std::vector<const void*> src;
  std::vector<const std::vector<uint64_t>*> src_mask;
  std::vector<int32_t> t;  // one row of T_l (the band's rows are read from the level, src)
  std::vector<int32_t> res, rhat;
  std::vector<int32_t> pred_row;  // U of one row, where T_l - R does not give it back
  std::vector<uint8_t> valid, bytes;
  // The rows of T^_{l-1} its U reads, copied when it is scheduled (the level drops them as it moves on).
  std::vector<int32_t> window;
  UpsampleScratch scratch;
  BandFigures figures;
};

// Rows [first, end) of one level. Each row is its own buffer, recycled through a free list: the
// store never copies rows to grow and holds no slack (these rows are most of the builder's memory).
template <class T> class RowRing {
 public:
  void reset(int64_t width, int64_t first = 0) {
    width_ = width;
    first_ = end_ = first;
    peak_ = 0;
    rows_.clear();
    free_.clear();
  }
  // Drops the rows before r; an empty ring then continues at r (a stripe's rows start there).
  void skip_to(int64_t r) {
    drop_before(r);
    if (first_ == end_ && end_ < r) first_ = end_ = r;
  }
  int64_t first() const { return first_; }
  int64_t end() const { return end_; }
  int64_t peak() const { return peak_; }
  const T* row(int64_t r) const { return rows_[size_t(r - first_)].data(); }
  template <class In> void append(const In* rows, int64_t n) {
    for (int64_t k = 0; k < n; ++k) {
      std::vector<T> buf;
      if (!free_.empty()) {
        buf = std::move(free_.back());
        free_.pop_back();
      }
      buf.resize(size_t(width_));
      for (int64_t x = 0; x < width_; ++x) buf[size_t(x)] = static_cast<T>(rows[k * width_ + x]);
      rows_.push_back(std::move(buf));
    }
    end_ += n;
    peak_ = std::max(peak_, end_ - first_);
  }
  // n row buffers of width() values, recycled where possible, for rows filled by another thread and
  // then adopted. Allocated here, on the thread that frees them: rows allocated on the reader's
  // thread (a new one per band) and freed on this one scattered them over the allocator's
  // per-thread arenas (a 32768^2 build at 64 threads peaked 14 % higher).
  std::vector<std::vector<T>> take_spares(int64_t n) {
    std::vector<std::vector<T>> out(size_t(std::max<int64_t>(0, n)));
    for (std::vector<T>& buf : out) {
      if (!free_.empty()) {
        buf = std::move(free_.back());
        free_.pop_back();
      }
      buf.resize(size_t(width_));
    }
    return out;
  }
  // Appends rows[0 .. n), each a buffer of width() values, as the next rows.
  void adopt(std::vector<std::vector<T>>& rows, int64_t n) {
    for (int64_t k = 0; k < n; ++k) rows_.push_back(std::move(rows[size_t(k)]));
    end_ += n;
    peak_ = std::max(peak_, end_ - first_);
  }
  void drop_before(int64_t r) {
    r = std::clamp(r, first_, end_);
    for (; first_ < r; ++first_) {
      free_.push_back(std::move(rows_.front()));
      rows_.pop_front();
    }
    // Spare rows up to the peak: a commit drops a band of finest rows at once, and freeing all but a
    // few of them made the main thread fault fresh pages in for the next ones (1 % of a 16-thread
    // build's samples); rows held plus spares never exceed the peak the memory plan counts.
    const size_t spare = size_t(std::max<int64_t>(64, peak_ - (end_ - first_)));
    while (free_.size() > spare) free_.pop_back();
  }
  template <class Out> void copy_rows(int64_t r0, int64_t n, Out* out) const {
    for (int64_t k = 0; k < n; ++k) std::copy(row(r0 + k), row(r0 + k) + width_, out + k * width_);
  }
  // Moves rows [r0, r1) out (first() <= r0 <= r1 <= end()); the ring is left empty, its spares freed.
  std::vector<std::vector<T>> take(int64_t r0, int64_t r1) {
    std::vector<std::vector<T>> out;
    out.reserve(size_t(r1 - r0));
    for (int64_t r = r0; r < r1; ++r) out.push_back(std::move(rows_[size_t(r - first_)]));
    rows_.clear();
    free_.clear();
    first_ = end_;
    return out;
  }

 private:
  std::deque<std::vector<T>> rows_;
  std::vector<std::vector<T>> free_;
  int64_t width_ = 0, first_ = 0, end_ = 0, peak_ = 0;
};

// A level's rows; 16-bit input keeps its finest level as int16 (the finest level's lag is most of
// the builder's memory).
class LevelRows {
 public:
  void reset(int64_t width, bool narrow, int64_t first = 0) {
    narrow_ = narrow;
    r16_.reset(width, first);
    r32_.reset(width, first);
  }
  void skip_to(int64_t r) { narrow_ ? r16_.skip_to(r) : r32_.skip_to(r); }
  void append(const int32_t* rows, int64_t n) { narrow_ ? r16_.append(rows, n) : r32_.append(rows, n); }
  void copy_rows(int64_t r0, int64_t n, int32_t* out) const {
    narrow_ ? r16_.copy_rows(r0, n, out) : r32_.copy_rows(r0, n, out);
  }
  const void* row(int64_t r) const {
    return narrow_ ? static_cast<const void*>(r16_.row(r)) : static_cast<const void*>(r32_.row(r));
  }
  bool narrow() const { return narrow_; }
  RowRing<int16_t>& narrow_rows() { return r16_; }
  RowRing<int32_t>& wide_rows() { return r32_; }
  int64_t first() const { return narrow_ ? r16_.first() : r32_.first(); }
  int64_t end() const { return narrow_ ? r16_.end() : r32_.end(); }
  int64_t peak() const { return narrow_ ? r16_.peak() : r32_.peak(); }
  void drop_before(int64_t r) { narrow_ ? r16_.drop_before(r) : r32_.drop_before(r); }

 private:
  bool narrow_ = false;
  RowRing<int16_t> r16_;
  RowRing<int32_t> r32_;
};

// Validity rows held one bit per sample, rows without voids not at all (the held finest rows are
// most of the builder's memory).
class MaskRows {
 public:
  void reset(int64_t width) {
    width_ = width;
    first_ = 0;
    rows_.clear();
  }
  // One row's bits as the mask keeps them (empty: no voids).
  static std::vector<uint64_t> pack(const uint8_t* row, int64_t width) {
    std::vector<uint64_t> bits;
    if (std::memchr(row, 0, size_t(width)) != nullptr) {
      bits.assign(size_t((width + 63) / 64), 0);
      for (int64_t x = 0; x < width; ++x)
        if (row[x]) bits[size_t(x / 64)] |= uint64_t(1) << (x % 64);
    }
    return bits;
  }
  // Appends rows packed by pack().
  void adopt(std::vector<std::vector<uint64_t>>& rows, int64_t n) {
    for (int64_t k = 0; k < n; ++k) rows_.push_back(std::move(rows[size_t(k)]));
  }
  // Row r's bits (empty: no voids); the reference stays valid until the row is dropped.
  const std::vector<uint64_t>* row_bits(int64_t r) const { return &rows_[size_t(r - first_)]; }
  static void unpack(const std::vector<uint64_t>& bits, int64_t width, uint8_t* row) {
    if (bits.empty())
      std::fill(row, row + width, uint8_t(1));
    else
      for (int64_t x = 0; x < width; ++x) row[x] = uint8_t((bits[size_t(x / 64)] >> (x % 64)) & 1);
  }
  void drop_before(int64_t r) {
    while (first_ < r && !rows_.empty()) {
      rows_.pop_front();
      ++first_;
    }
  }
  void skip_to(int64_t r) {
    drop_before(r);
    if (rows_.empty() && first_ < r) first_ = r;
  }

 private:
  int64_t width_ = 0, first_ = 0;
  std::deque<std::vector<uint64_t>> rows_;
};

// Input rows held before D exists: its fit's rows, none for a fixed D (the wavelet D, a stripe's
// shared one; the cascade then starts with the first band). The builder and its memory plan agree.
int64_t fit_rows_held(const BuildOptions& opt, int64_t height) {
  return opt.use_fixed_filter ? 0 : std::min(height, opt.fit_rows);
}

// Input bands the builder holds: the one the main thread works on, those the reader thread makes
// ahead of it and (threads > 1) those D's finest thread has not yet read (one, usually).
constexpr int kInputSlots = 4;
// Zero bytes of `valid`. Most inputs have none, which memchr confirms at its vector speed; GCC's
// std::count of bytes widens every byte to a 64-bit sum (a tenth of the input thread's time).
int64_t count_voids(const uint8_t* valid, int64_t n) {
  if (std::memchr(valid, 0, size_t(n)) == nullptr) return 0;
  return std::count(valid, valid + n, uint8_t(0));
}
int input_slots(int threads) { return threads > 1 ? kInputSlots : 1; }

// Smallest band height of a coarse level (one codec macroblock row), where the lag allows it.
constexpr int64_t kMinCoarseBandRows = 16;

// Band heights per level, coarsest first.
std::vector<int64_t> level_band_rows(int level_count, int64_t finest_band_rows) {
  // A band of level l spans band_rows * 2^(m-l) input rows, and the finer levels cannot be coded
  // until it is: halving the band height per coarser level keeps every level's lag near band_rows
  // input rows (memory stays O(width * 2^m) instead of O(width * band_rows * 2^m)). But bands of a
  // few rows code badly (the codec pads them to 16 rows and every band restarts its tiles), so a
  // coarse band gets up to kMinCoarseBandRows rows as long as its lag stays within 4 band_rows input
  // rows: a constant 4096^2 grid's coarsest level costs 8 bands instead of 32.
  const int finest = level_count - 1;
  std::vector<int64_t> rows(static_cast<size_t>(level_count));
  for (int l = 0; l < level_count; ++l) {
    const int shift = std::min(62, finest - l);
    const int64_t halved = finest_band_rows >> shift;
    const int64_t floor_rows =
        std::min({kMinCoarseBandRows, finest_band_rows, (4 * finest_band_rows) >> shift});
    rows[size_t(l)] = std::max<int64_t>({int64_t(1), halved, floor_rows});
  }
  return rows;
}

// The builder's bytes with c bands of each level in flight (plan_build_memory; docs/scale.md
// "Memory model"). Doubles: a 40-level pyramid's shifts overflow int64, the heights bound the rows.
// first: the coarsest level coded (a stripe's fine levels, k + 1, with the coarse ones given; 0 for
// a whole build): the coarser levels hold nothing and set no lag.
double estimate_bytes(const GridInfo& info, const BuildOptions& opt, const std::vector<GridSize>& sizes,
                      const std::vector<int64_t>& band_rows, int c, int64_t* finest_rows = nullptr,
                      int first = 0) {
  const int m = int(sizes.size()) - 1;
  first = std::clamp(first, 0, m);
  const double W = double(info.width), H = double(info.height);
  const double B = double(std::min(opt.fill_band_rows, info.height));
  const auto scale = [m](int l) { return std::ldexp(1.0, m - l); };  // level l's spacing in input rows
  // Finest rows held: every level's band height in input rows (a band of level l waits for its
  // rows, the finer ones for its T^), D's reach (5 rows a level, doubled per level up: 5 * 2^m),
  // U's (2 coarse rows a level), the coarse engines' batches (about 32 input rows each), the group
  // of c bands the finest level codes at once (with threads > 1 twice: the next group's rows
  // arrive while a group is coded) and one fill band (with threads > 1 also those D's finest thread
  // has not reached); at least D's fit rows. The main thread does not read beyond it while a band
  // is in flight.
  const double groups = opt.threads > 1 ? 2 * c - 1 : c - 1;
  const double input_bands = input_slots(opt.threads);
  double lag =
      7 * scale(first) + 32.0 * (m + 1 - first) + groups * double(band_rows[size_t(m)]) + input_bands * B;
  for (int l = first; l <= m; ++l) lag += double(band_rows[size_t(l)]) * scale(l);
  lag = std::min(H, std::max(lag, double(fit_rows_held(opt, info.height)) + B));
  if (finest_rows) *finest_rows = int64_t(lag);
  const bool narrow = info.sample_type == SampleType::Int16 && opt.value_scale == 1.0;
  // Level rows (int16 or int32) and their validity bits.
  double bytes = lag * (W * (narrow ? 2 : 4) + std::ceil(W / 64) * 8);
  const int engine_workers = std::max(1, opt.threads);
  for (int l = first; l <= m; ++l) {
    const double w = double(sizes[size_t(l)].width), h = double(sizes[size_t(l)].height);
    const double S = std::min(h, double(band_rows[size_t(l)]));
    // The bands in flight: R (U's prediction until R is formed in place) and T^ (int32 each), the
    // validity (finest), the stream, the coder's buffer, libcodec's body and its record of the phase
    // tiles' levels (about 2 bytes a sample each).
    bytes += double(c) * S * w * (8 + (l == m ? 1 : 0) + 8);
    if (l < m) {
      // T_l rows not yet coded and T^_l rows the finer level's U still needs, and the copy of
      // those U reads for a group of the finer level.
      const double S_finer = double(band_rows[size_t(l + 1)]);
      const double held = std::min(2 * h, lag / scale(l) + 2 * c * double(band_rows[size_t(l)]) + 8);
      bytes += (held + c * S_finer / 2 + 8) * w * 4;
    }
    if (l >= 1 && l > first) {
      // D engine of level l: its fine rows (int32), a batch of coarse rows (double and int32) and
      // each worker's fold / even / odd / sum rows.
      const double batch = std::max(1.0, std::floor(32.0 / scale(l)));
      const double cw = double(sizes[size_t(l - 1)].width), pw = w + 2 * DownsampleFilter::kRadius;
      bytes += std::min(h, 2 * batch + 16) * w * 4 + batch * cw * 12 +
               std::min(double(engine_workers), batch) * (2 * pw + cw) * 8;
    }
  }
  // The input bands (level integers and validity, 8 rows of samples as read), the rows of those the
  // reader works on ahead as the level keeps them (made on the reader's thread), D's fit windows.
  bytes += input_bands * (B * W * 5 + std::min(B, 8.0) * W * 8) +
           (input_bands - 1) * B * (W * (narrow ? 2 : 4) + std::ceil(W / 64) * 8) + W * 4;
  if (!opt.use_fixed_filter)
    bytes += double(opt.fit.max_windows) * double(opt.fit.window * opt.fit.window) * 16;
  return bytes;
}

BuildMemoryPlan plan_memory(const GridInfo& info, const BuildOptions& opt, const std::vector<GridSize>& sizes,
                            const std::vector<int64_t>& band_rows, bool striped, int first = 0) {
  // A stripe also reads the rows above its own in whole fill bands of samples (8 bytes each).
  const double extra =
      striped ? double(std::min(opt.fill_band_rows, info.height)) * double(info.width) * 8 : 0.0;
  // On top of the items, the heap's slack (freed blocks the allocator keeps, one arena per thread):
  // the peak RSS of a 32768^2 build at 16 and 64 threads was 2-3 % above the items' sum.
  const double per_thread = double(int64_t(256) << 10);
  const auto with_slack = [&](double items) { return items * 1.05 + per_thread * opt.threads; };
  const auto estimate = [&](int c) {
    return with_slack(estimate_bytes(info, opt, sizes, band_rows, c, nullptr, first) + extra);
  };
  BuildMemoryPlan plan;
  const double minimum = estimate(1);
  plan.minimum_bytes = int64_t(std::min(minimum, 9e18));
  int c = opt.threads;
  if (opt.memory_budget > 0) {
    const auto mib = [](double b) { return std::to_string(int64_t(std::ceil(b / 1048576.0))); };
    if (minimum > double(opt.memory_budget))
      throw std::invalid_argument(
          "pyramid: a memory budget of " + mib(double(opt.memory_budget)) + " MiB is below the " +
          mib(minimum) + " MiB a " + std::to_string(info.width) + "-column input of " +
          std::to_string(sizes.size()) +
          " levels needs (the rows each level lags behind the input, docs/scale.md); give at least " +
          mib(minimum) + " MiB, or fewer levels");
    while (c > 1 && estimate(c) > double(opt.memory_budget)) --c;
  }
  plan.bands_in_flight = c;
  plan.estimated_bytes = int64_t(std::min(
      with_slack(estimate_bytes(info, opt, sizes, band_rows, c, &plan.finest_rows, first) + extra), 9e18));
  return plan;
}

// A helper thread of StreamingBuilder::run and what it waits on: `stop` (under `lock`, with `wake`
// notified) asks it to return. Its owner's destructor calls halt(), so that the thread is joined
// before the owner's members that it reads are destroyed.
struct StoppableThread {
  std::mutex lock;
  std::condition_variable wake;
  bool stop = false;
  std::thread thread;
  void halt() {
    if (thread.joinable()) detail::stop_and_join(lock, wake, stop, {&thread, 1});
  }
};

// The coding workers: `threads` threads kept for the whole build that code the bands the
// scheduler hands them (StreamingBuilder::schedule) and the parts the coder splits a band into
// (chunks of its tiles, ResidualCoder::encode_parts), parts first, so that a band started is
// finished soon; among bands, coarser levels first (finer bands wait for their T^ rows). Until
// 2026-12-07 bands were coded in rounds, one round at a time: a round's finest bands ran while the
// coarse bands that the next finest ones need waited for the round's end, and the 16-core host's
// rounds were 58-68 % busy (docs/scale.md). A part never waits; a band waits only for its own parts.
class CodingPool final : public PartRunner, detail::PoolThreads {
 public:
  struct Band {
    int level;
    int64_t y0;
    void* flight;  // the scheduler's
  };
  // Starts the workers; code(band) runs on them and must not throw.
  void start(int threads, std::function<void(const Band&)> code) {
    code_ = std::move(code);
    for (int i = 0; i < threads; ++i) threads_.emplace_back([this] { serve(); });
  }
  // Joins the workers after the bands and parts they run (those queued are dropped).
  void stop() { stop_threads(); }
  ~CodingPool() { stop(); }
  bool started() const { return !threads_.empty(); }
  void submit(const Band& band) {
    {
      const std::lock_guard<std::mutex> hold(lock_);
      ready_.push_back(band);
    }
    wake_.notify_one();
  }
  // The workers' thread-seconds in bands and parts, not waiting (for the build log).
  double busy() {
    const std::lock_guard<std::mutex> hold(lock_);
    return busy_;
  }

  void run(size_t n, const std::function<void(size_t)>& part) override {
    Job job;
    job.part = &part;
    job.n = job.left = n;
    job.errors.assign(n, nullptr);
    const auto t_run = Clock::now();
    std::unique_lock<std::mutex> hold(lock_);
    jobs_.push_back(&job);
    wake_.notify_all();
    // This thread takes its band's parts too, and helps with others' while its own are running.
    while (job.left > 0) {
      Job* take = job.next < job.n ? &job : (jobs_.empty() ? nullptr : jobs_.front());
      if (!take) {
        wake_.wait(hold);
        continue;
      }
      run_part(*take, hold);
    }
    busy_ -= seconds_since(t_run);  // in the band's time: its waits are not busy, its parts counted
    hold.unlock();
    for (const std::exception_ptr& e : job.errors)
      if (e) std::rethrow_exception(e);
  }

 private:
  struct Job {
    const std::function<void(size_t)>* part = nullptr;
    size_t next = 0, n = 0, left = 0;
    std::vector<std::exception_ptr> errors;
  };

  // Runs the next part of `job` (lock held on entry and on return).
  void run_part(Job& job, std::unique_lock<std::mutex>& hold) {
    const size_t c = job.next++;
    if (job.next == job.n) jobs_.erase(std::find(jobs_.begin(), jobs_.end(), &job));
    hold.unlock();
    const auto t = Clock::now();
    try {
      (*job.part)(c);
    } catch (...) {
      job.errors[c] = std::current_exception();
    }
    const double took = seconds_since(t);
    hold.lock();
    busy_ += took;
    if (--job.left == 0) wake_.notify_all();
  }

  void serve() {
    std::unique_lock<std::mutex> hold(lock_);
    for (;;) {
      if (stop_) return;
      if (!jobs_.empty()) {
        run_part(*jobs_.front(), hold);
      } else if (!ready_.empty()) {
        const auto first = std::min_element(ready_.begin(), ready_.end(), [](const Band& a, const Band& b) {
          return a.level != b.level ? a.level < b.level : a.y0 < b.y0;
        });
        const Band band = *first;
        ready_.erase(first);
        hold.unlock();
        const auto t = Clock::now();
        code_(band);
        const double took = seconds_since(t);
        hold.lock();
        busy_ += took;
      } else {
        wake_.wait(hold);
      }
    }
  }

  std::deque<Job*> jobs_;  // jobs with parts not yet taken, oldest first
  std::vector<Band> ready_;
  std::function<void(const Band&)> code_;
  double busy_ = 0;
};

// Which part of a stripe's pyramid a builder makes (the striped build's shared coarse levels,
// docs/scale.md "Cost of the decomposition"): everything (Whole), only the stripe's rows of level k
// (Rows: D's cascade, nothing coded), levels 0..k from the whole T_k (Coarse), or levels k+1..m
// with the whole T^_k given (Fine).
struct Split {
  enum class Kind { Whole, Rows, Coarse, Fine } kind = Kind::Whole;
  int level = -1;                              // k
  const std::vector<int32_t>* grid = nullptr;  // Coarse: T_k; Fine: T^_k (whole level, row-major)
  bool keep_fine = false;                      // Rows: also keep the T_{m-1} rows Fine will need
  const StripeLevelRows* fine = nullptr;       // Fine: those rows (D's finest level is not run again)
};

class StreamingBuilder {
 public:
  StreamingBuilder(const GridInfo& info, const BuildOptions& opt, ResidualCoder& coder, PyramidSink& sink,
                   const BuildStripe& stripe, const Split& split = {})
      : info_(info), opt_(opt), coder_(coder), sink_(sink), split_(split), seek_above_(stripe.seek_above) {
    validate(opt, info);
    sizes_ = pyramid_level_sizes({info.width, info.height}, opt.level_count, opt.min_coarsest_side);
    level_count_ = int(sizes_.size());
    finest_ = level_count_ - 1;
    finest_band_rows_ = coder.band_rows();
    if (finest_band_rows_ < 1) throw std::invalid_argument("pyramid: coder band_rows must be >= 1");
    level_band_rows_ = level_band_rows(level_count_, finest_band_rows_);
    // A stripe's fine levels (Fine) or rows (Rows) hold no coarse lag: the plan counts from there.
    memory_ = plan_memory(info, opt, sizes_, level_band_rows_, stripe.y0 > 0,
                          split_.kind == Split::Kind::Fine || split_.kind == Split::Kind::Rows
                              ? std::max(0, split_.level + 1)
                              : 0);
    if (split_.kind != Split::Kind::Whole) {
      if (split_.level < 0 || split_.level >= finest_)
        throw std::invalid_argument("pyramid: split level " + std::to_string(split_.level) + " outside 0.." +
                                    std::to_string(finest_ - 1));
      if (split_.kind != Split::Kind::Rows &&
          (!split_.grid || int64_t(split_.grid->size()) !=
                               sizes_[size_t(split_.level)].width * sizes_[size_t(split_.level)].height))
        throw std::invalid_argument("pyramid: the given level " + std::to_string(split_.level) +
                                    " does not match its size");
      if (split_.kind == Split::Kind::Coarse && !opt.use_fixed_filter)
        throw std::invalid_argument("pyramid: coarse levels need the fixed filter of the stripes");
    }
    // The coarsest level the D cascade makes, and the level whose rows come in.
    stop_ = cascade_stop(split_.kind);
    entry_ = split_.kind == Split::Kind::Coarse ? split_.level : finest_;
    if (split_.kind == Split::Kind::Rows && split_.keep_fine && split_.level < finest_ - 1) {
      // The rows of T_{m-1} the stripe's Fine build runs its cascade on: its plan's.
      plan_stripe(stripe, Split::Kind::Fine);
      if (read_a_ < read_b_) std::tie(fine_lo_, fine_hi_) = cascade_fine_rows();
    }
    plan_stripe(split_.kind == Split::Kind::Coarse ? BuildStripe{0, info.height} : stripe, split_.kind);
    if (split_.kind == Split::Kind::Fine && split_.fine && split_.level < finest_ - 1 && read_a_ < read_b_) {
      const int64_t w = sizes_[size_t(finest_ - 1)].width;
      std::tie(fine_lo_, fine_hi_) = cascade_fine_rows();
      if (split_.fine->fine_first_row != fine_lo_ ||
          int64_t(split_.fine->fine_rows.size()) != fine_hi_ - fine_lo_ ||
          std::any_of(split_.fine->fine_rows.begin(), split_.fine->fine_rows.end(),
                      [&](const std::vector<int32_t>& row) { return int64_t(row.size()) != w; }))
        throw std::invalid_argument("pyramid: the given level " + std::to_string(finest_ - 1) +
                                    " rows are not this stripe's");
      fed_ = fine_lo_;
      fed_fine_ = true;
      entry_ = finest_ - 1;  // D's finest engine is not needed
    }
    levels_.resize(size_t(level_count_));
    reconstructed_.resize(size_t(level_count_));
    for (int l = 0; l < level_count_; ++l) {
      const bool narrow = l == finest_ && info.sample_type == SampleType::Int16 && opt.value_scale == 1.0;
      // The finest level's rows start at 0 (D's fit reads the top rows); the cascade's at the stripe's.
      levels_[size_t(l)].reset(sizes_[size_t(l)].width, narrow,
                               l == finest_ ? 0 : shift_rows_down(read_a_, finest_ - l));
      reconstructed_[size_t(l)].reset(sizes_[size_t(l)].width, need_lo_[size_t(l)]);
    }
    if (split_.kind == Split::Kind::Fine) {
      // T^_k as given: the rows U reads for the stripe's bands of level k + 1.
      const int k = split_.level;
      const int64_t wk = sizes_[size_t(k)].width;
      reconstructed_[size_t(k)].reset(wk, given_lo_);
      if (given_hi_ > given_lo_)
        reconstructed_[size_t(k)].append(split_.grid->data() + given_lo_ * wk, given_hi_ - given_lo_);
    }
    mask_.reset(info.width);
    row_scratch_.resize(size_t(info.width));
    next_band_ = need_lo_;
    figures_.resize(size_t(level_count_));
    flights_.resize(size_t(level_count_));
    spare_work_.resize(size_t(level_count_));
    work_out_.assign(size_t(level_count_), 0);
    sched_band_ = need_lo_;
    result_.levels.resize(size_t(level_count_));
    header_.levels = sizes_;
    header_.band_rows = finest_band_rows_;
    header_.value_scale = opt.value_scale;
    header_.input = info;
    std::ostringstream s;
    s << "levels " << level_count_ << ":";
    for (auto& g : sizes_) s << " " << g.width << "x" << g.height;
    result_.log.push_back(s.str());
    std::ostringstream mem;
    const auto mib = [](int64_t b) { return (b + (1 << 20) - 1) >> 20; };
    mem << "memory: estimate " << mib(memory_.estimated_bytes) << " MiB with " << memory_.bands_in_flight
        << " band(s) of each level in flight (" << opt.threads << " threads";
    if (opt.memory_budget > 0) mem << ", budget " << (opt.memory_budget >> 20) << " MiB";
    mem << ", at least " << mib(memory_.minimum_bytes) << " MiB; the builder alone)";
    result_.log.push_back(mem.str());
    result_.memory = memory_;
  }

  ~StreamingBuilder() { pool_.stop(); }  // after the bands in flight: they read the builder's rows
  StreamingBuilder(const StreamingBuilder&) = delete;
  StreamingBuilder& operator=(const StreamingBuilder&) = delete;

  // The coarsest level the D cascade of a `kind` build makes (its rows of level k for Rows; levels
  // k + 1 .. m for Fine; every level otherwise).
  int cascade_stop(Split::Kind kind) const {
    return kind == Split::Kind::Rows ? split_.level : kind == Split::Kind::Fine ? split_.level + 1 : 0;
  }

  // Which bands the stripe owns and codes, and which input rows its D cascade runs on (the whole
  // build: every band, all rows). own: the bands whose first row times 2^(m-l) lies in the stripe.
  // need: those plus the coarser bands whose T^ their U windows read, level by level up the
  // pyramid. The cascade runs on input rows [read_a_, read_b_), which reach kDHalo rows beyond the
  // needed rows at every level: D read past the stripe's ends (reflected at its edges, not the
  // input's) makes at most 5 rows wrong at each end of every level (11 taps: coarse row j reads fine
  // rows 2j - 5 .. 2j + 5, so t wrong rows at an end give floor((t + 4) / 2) + 1 coarse ones: 3,
  // 4, 5, 5, ...; the test cuts stripes everywhere and compares bytes). read_a_ and read_b_ are
  // multiples of 2^(m - c), c the coarsest level the cascade makes (each level's rows then keep the
  // input's parity), and of the fill band (a band is filled whole, as in the whole build), or the
  // input's end.
  void plan_stripe(const BuildStripe& stripe, Split::Kind kind) {
    const int64_t H = info_.height;
    if (stripe.y0 < 0 || stripe.y1 < stripe.y0 || stripe.y1 > H)
      throw std::invalid_argument("pyramid: stripe rows " + std::to_string(stripe.y0) + ".." +
                                  std::to_string(stripe.y1) + " outside the input's 0.." + std::to_string(H));
    const size_t L = size_t(level_count_);
    own_lo_.assign(L, 0), own_hi_.assign(L, 0), need_lo_.assign(L, 0), need_hi_.assign(L, 0);
    const auto round_up = [](int64_t v, int64_t m) { return (v + m - 1) / m * m; };
    for (int l = 0; l < level_count_; ++l) {
      const int64_t h = sizes_[size_t(l)].height, S = level_band_rows_[size_t(l)];
      const int shift = finest_ - l;
      own_lo_[size_t(l)] = std::min(h, round_up(shift_rows_up(stripe.y0, shift), S));
      own_hi_[size_t(l)] = std::min(h, round_up(shift_rows_up(stripe.y1, shift), S));
    }
    need_lo_[size_t(finest_)] = own_lo_[size_t(finest_)];
    need_hi_[size_t(finest_)] = own_hi_[size_t(finest_)];
    for (int l = finest_; l >= 1; --l) {
      int64_t lo = own_lo_[size_t(l - 1)], hi = own_hi_[size_t(l - 1)];
      if (need_lo_[size_t(l)] < need_hi_[size_t(l)]) {
        const GridSize fs = sizes_[size_t(l)];
        const Rect w = upsample_required_window(
            Rect{0, need_lo_[size_t(l)], fs.width, need_hi_[size_t(l)] - need_lo_[size_t(l)]}, fs);
        const int64_t S = level_band_rows_[size_t(l - 1)], h = sizes_[size_t(l - 1)].height;
        const int64_t wlo = w.y0 / S * S, whi = std::min(h, round_up(w.y0 + w.height, S));
        if (lo >= hi) lo = wlo, hi = whi;
        lo = std::min(lo, wlo), hi = std::max(hi, whi);
      }
      need_lo_[size_t(l - 1)] = lo, need_hi_[size_t(l - 1)] = hi;
    }
    // The D cascade must make these rows of each level (the whole build: the needed ones).
    std::vector<int64_t> make_lo = need_lo_, make_hi = need_hi_;
    if (kind != Split::Kind::Whole) {
      const int k = split_.level;
      if (kind == Split::Kind::Fine && need_lo_[size_t(k + 1)] < need_hi_[size_t(k + 1)]) {
        const GridSize fs = sizes_[size_t(k + 1)];
        const Rect w = upsample_required_window(
            Rect{0, need_lo_[size_t(k + 1)], fs.width, need_hi_[size_t(k + 1)] - need_lo_[size_t(k + 1)]},
            fs);
        given_lo_ = w.y0, given_hi_ = w.y0 + w.height;
      }
      const int64_t rows_lo = own_lo_[size_t(k)], rows_hi = own_hi_[size_t(k)];
      for (int l = 0; l < level_count_; ++l) {
        const bool coded = kind == Split::Kind::Coarse ? l <= k : kind == Split::Kind::Fine ? l > k : false;
        if (coded) continue;
        // Nothing of this level is coded: its rows are dropped as they come (need = the level's end),
        // except the rows made for export (level k, and level m-1 for the Fine build), which stay.
        const int64_t h = sizes_[size_t(l)].height;
        int64_t lo = 0, hi = 0;
        if (kind == Split::Kind::Rows && l == k) lo = rows_lo, hi = rows_hi;
        if (kind == Split::Kind::Rows && l == finest_ - 1 && l != k) lo = fine_lo_, hi = fine_hi_;
        need_lo_[size_t(l)] = need_hi_[size_t(l)] = lo < hi ? lo : h;
        make_lo[size_t(l)] = lo, make_hi[size_t(l)] = hi;
      }
      if (kind == Split::Kind::Rows) rows_lo_ = rows_lo, rows_hi_ = rows_hi;
    }
    int64_t a = H, b = 0;
    for (int l = 0; l < level_count_; ++l) {
      if (make_lo[size_t(l)] >= make_hi[size_t(l)]) continue;
      const int shift = finest_ - l;
      a = std::min(a, shift_rows_down_to_input(make_lo[size_t(l)] - kDHalo, shift));
      b = std::max(b, shift_rows_down_to_input(make_hi[size_t(l)] + kDHalo, shift));
    }
    if (a >= b) {  // nothing to code: read only the rows D is fitted on
      read_a_ = read_b_ = 0;
      return;
    }
    // The cascade keeps each level's row parity down to the coarsest level it makes: a stripe's Rows
    // build (down to k) needs multiples of 2^(m-k), its Fine build 2^(m-k-1), not 2^m. With 2^m, a
    // 1024-row stripe of 16384^2 (m = 7) ran its Rows cascade on 1280 rows.
    const int shift = finest_ - cascade_stop(kind);
    const int64_t fill = std::min(opt_.fill_band_rows, H);
    const int64_t align = shift >= 40 ? H : std::min(H, std::lcm(int64_t(1) << shift, fill));
    read_a_ = std::max<int64_t>(0, a) / align * align;
    read_b_ = std::min(H, round_up(std::max<int64_t>(0, b), align));
  }

  // The rows of T_{m-1} D's finest engine makes over the cascade's input rows [read_a_, read_b_).
  std::pair<int64_t, int64_t> cascade_fine_rows() const {
    return {read_a_ >> 1, (read_a_ >> 1) + coarse_extent(read_b_ - read_a_)};
  }

  // Level rows -> finest rows (saturated at the input height) and back.
  int64_t shift_rows_down_to_input(int64_t level_row, int shift) const {
    if (level_row <= 0) return 0;
    if (shift >= 40 || level_row > (info_.height >> shift) + 1) return info_.height;
    return level_row << shift;
  }
  static int64_t shift_rows_up(int64_t finest_row, int shift) {
    return shift >= 62 ? (finest_row > 0 ? 1 : 0) : (finest_row + (int64_t(1) << shift) - 1) >> shift;
  }
  static int64_t shift_rows_down(int64_t finest_row, int shift) {
    return shift >= 62 ? 0 : finest_row >> shift;
  }

  BuildResult run(BandReader& input) {
    const auto t_start = Clock::now();
    build_start_ = t_start;
    const double cpu_start = thread_cpu_seconds();
    const int64_t W = info_.width, H = info_.height;
    const int64_t B = std::min(opt_.fill_band_rows, H);
    // With a fixed D a stripe does not convert the rows above it either.
    fit_rows_ = fit_rows_held(opt_, H);
    // A stripe reads no further than its cascade or D's fit needs (whole fill bands).
    const int64_t stop = std::min(H, std::max(read_b_, (fit_rows_ + B - 1) / B * B));
    InputConverter converter(opt_, info_);
    // Reading and converting band k+1 overlaps with processing band k (with threads > 1); the reader
    // and the converter are only ever used by one thread at a time, in band order.
    // The reader's thread also makes the band's rows as the finest level keeps them (int16 or
    // int32 row buffers, recycled from the level, and validity bits), which the main thread then
    // only adopts: that copy was a tenth of the main thread's time at 16 threads.
    struct InputBand {
      std::vector<double> values;
      std::vector<uint8_t> valid;
      std::vector<int32_t> ints;
      std::vector<std::vector<int16_t>> rows16;
      std::vector<std::vector<int32_t>> rows32;
      std::vector<std::vector<uint64_t>> mask;
      int64_t y = 0, rows = 0, voids = 0;
      bool carry = false;  // above a stripe's cascade: only its voids were converted, no rows made
    };
    LevelRows& finest_rows = levels_[size_t(finest_)];
    // Rows [from, from + n) of the band.
    const auto level_rows = [&](InputBand& b, int64_t from, int64_t n) {
      b.mask.resize(size_t(b.rows));
      for (int64_t r = from; r < from + n; ++r) b.mask[size_t(r)] = MaskRows::pack(b.valid.data() + r * W, W);
      const auto fill = [&](auto& rows) {  // rows from take_spares: width W each
        for (int64_t r = from; r < from + n; ++r)
          std::copy_n(b.ints.data() + r * W, W, rows[size_t(r)].begin());
      };
      if (finest_rows.narrow())
        fill(b.rows16);
      else
        fill(b.rows32);
    };
    // The level's spare rows and its store are shared with the workers' commits (sched_).
    const auto take_spares = [&](InputBand& b, int64_t rows) {
      const std::lock_guard<std::mutex> hold(sched_);
      if (finest_rows.narrow())
        b.rows16 = finest_rows.narrow_rows().take_spares(rows);
      else
        b.rows32 = finest_rows.wide_rows().take_spares(rows);
    };
    const auto adopt = [&](InputBand& b) {
      // A stripe's first band, with a fixed D: its rows are dropped once the cascade starts.
      if (b.carry) level_rows(b, 0, b.rows);
      const std::lock_guard<std::mutex> hold(sched_);
      if (finest_rows.narrow())
        finest_rows.narrow_rows().adopt(b.rows16, b.rows);
      else
        finest_rows.wide_rows().adopt(b.rows32, b.rows);
      mask_.adopt(b.mask, b.rows);
    };
    // A band keeps its level integers and validity (5 bytes a sample); the samples as read (8 bytes
    // each) are converted kReadRows rows at a time, so that they are not held for the whole band:
    // the two bands were most of a wide input's memory. The fill still sees the whole band.
    constexpr int64_t kReadRows = 8;
    // One slot without a reader thread (one-thread builds): the others would be 5 bytes a sample of
    // a band each, unused (21 MiB at 16384 columns).
    InputBand bands[kInputSlots];
    const int64_t slots = input_slots(opt_.threads);
    for (int64_t k = 0; k < slots; ++k) {
      InputBand& b = bands[k];
      b.values.resize(size_t(std::min(B, kReadRows) * W));
      b.valid.resize(size_t(B * W));
      b.ints.resize(size_t(B * W));
    }
    // A band above a stripe's cascade and below D's fit rows matters only for the fill's carry,
    // which only a band with voids changes: it is converted only then (read whole, since the fill
    // sees the whole band). Saves a stripe a tenth of its time reading its way down the input.
    std::vector<double> carry_values;
    // Integers in the level's own units straight from the reader, where it decodes them itself: what
    // the conversion would give, without the detour through doubles.
    const bool int_rows = input.reads_int32() && converter.identity();
    // Up to `want` rows as ints (int_rows) or values, and validity; Truncated if the input ends
    // before input row `at`.
    const auto read_some = [&](int64_t at, int64_t want, double* values, int32_t* ints, uint8_t* valid) {
      const int64_t n =
          int_rows ? input.read_rows_int32(want, ints, valid) : input.read_rows(want, values, valid);
      if (n <= 0 || n > want)
        throw Error(ErrorCode::Truncated, "pyramid input: ended after " + std::to_string(at) + " of " +
                                              std::to_string(H) + " rows");
      return n;
    };
    auto produce = [&](InputBand& b, int64_t y) {
      b.y = y;
      b.rows = std::min(B, H - y);
      b.voids = 0;
      b.carry = y >= fit_rows_ && y + b.rows <= read_a_;
      if (b.carry && seek_above_) {
        // Skipped (a seek for raw, .hgt and .bil): only a void fill whose carry comes from these
        // rows needs them, and the converter throws where that happens.
        if (input.skip_rows(b.rows) != b.rows)
          throw Error(ErrorCode::Truncated, "pyramid input: ended after " + std::to_string(y) + " of " +
                                                std::to_string(H) + " rows");
        converter.forget_carry();
        return;
      }
      if (b.carry) {
        if (!int_rows) carry_values.resize(size_t(b.rows * W));
        for (int64_t got = 0; got < b.rows;)
          got += read_some(y + got, b.rows - got, int_rows ? nullptr : carry_values.data() + got * W,
                           b.ints.data() + got * W, b.valid.data() + got * W);
        if (std::find(b.valid.begin(), b.valid.begin() + b.rows * W, uint8_t(0)) !=
            b.valid.begin() + b.rows * W) {
          if (int_rows)
            converter.fill(b.valid.data(), b.rows, b.ints.data());  // read as converted, voids 0
          else
            converter.convert(carry_values.data(), b.valid.data(), y, b.rows, b.ints.data());
        }
        return;
      }
      for (int64_t got = 0; got < b.rows;) {
        const int64_t want = std::min(kReadRows, b.rows - got);
        uint8_t* const valid = b.valid.data() + got * W;
        int32_t* const ints = b.ints.data() + got * W;
        const int64_t n = read_some(y + got, want, b.values.data(), ints, valid);
        b.voids += int_rows ? count_voids(valid, n * W)
                            : converter.convert_rows(b.values.data(), valid, y + got, n, ints);
        // Rows are final as read while the band has no voids: made now, while they are still in
        // cache, instead of in a pass over the whole band (which a void's fill needs, below).
        if (b.voids == 0) level_rows(b, got, n);
        got += n;
      }
      if (b.voids) {
        converter.fill(b.valid.data(), b.rows, b.ints.data());
        level_rows(b, 0, b.rows);
      }
    };
    // The bands with rows below `stop`: band 0 here, the others on a reader thread kept for the whole
    // read (threads > 1) that works up to slots - 1 bands ahead of this one. A thread started per
    // band had to be scheduled among the busy coding threads before it read anything, and this thread
    // waited 0.4-0.5 s of a 16-thread build for it (docs/scale.md).
    const int64_t n_bands = std::max<int64_t>(1, (stop + B - 1) / B);
    const auto band_y = [&](int64_t i) { return i * B; };
    for (int64_t i = 0; i < std::min<int64_t>(slots, n_bands); ++i)
      take_spares(bands[i % slots], std::min(B, H - band_y(i)));
    produce(bands[0], 0);
    struct Reader : StoppableThread {
      // Bands [0, produced) ready; [0, consumed) done with by the main thread, [0, d_consumed) by
      // the finest D's thread (while it has bands: their int32 rows are read there).
      std::atomic<int64_t> produced{1};
      int64_t consumed = 0, d_consumed = std::numeric_limits<int64_t>::max();
      std::atomic<bool> failed{false};
      std::exception_ptr error;
      double busy = 0, waited = 0;  // its thread's seconds producing bands, waiting for a free slot
      ~Reader() { halt(); }
    } reader;
    const bool ahead = opt_.threads > 1 && n_bands > 1;
    if (ahead)
      reader.thread = std::thread([&] {
        for (int64_t i = 1; i < n_bands; ++i) {
          const auto t_wait = Clock::now();
          {
            std::unique_lock<std::mutex> hold(reader.lock);
            reader.wake.wait(hold, [&] {
              return reader.stop || i < std::min(reader.consumed, reader.d_consumed) + slots;
            });
            if (reader.stop) return;
          }
          reader.waited += seconds_since(t_wait);
          const auto t_produce = Clock::now();
          try {
            produce(bands[i % slots], band_y(i));
            reader.busy += seconds_since(t_produce);
          } catch (...) {
            const std::lock_guard<std::mutex> hold(reader.lock);
            reader.error = std::current_exception();
            reader.failed.store(true, std::memory_order_release);
            reader.wake.notify_all();
            main_signal_.notify();
            return;
          }
          reader.produced.store(i + 1, std::memory_order_release);
          main_signal_.notify();
        }
      });
    // D's finest engine on a thread of its own (threads > 1), fed whole input bands: on the main
    // thread its batches were a fork-join among the busy coders, 1.2-1.7 s of a 2.8-3.3 s 16-thread
    // build on the 16-core host (docs/scale.md). Its coarse rows come back through `made`, taken by
    // the main thread (take_coarse), which runs the coarser engines and schedules bands as before, in the
    // same order: the same rows, so the same bytes. Declared after the reader and the bands, so that
    // it stops first: its jobs read the bands' rows and report to the reader.
    struct FinestD : StoppableThread {
      struct Job {
        const int32_t* rows;
        int64_t n;     // 0: a band outside the cascade, only counted
        int64_t band;  // its index, for the reader
      };
      std::deque<Job> jobs;
      bool finish = false;
      std::atomic<bool> finished{false}, has_made{false};
      std::vector<std::vector<int32_t>> made, spare;  // coarse rows for the main thread, buffers
      std::vector<int64_t> made_rows;
      std::exception_ptr error;
      double busy = 0;  // its thread's seconds in the engine
      ~FinestD() { halt(); }
    } fd;
    const bool d_thread_wanted = ahead && !fed_fine_ && finest_ > stop_ && entry_ == finest_;
    d_on_thread_ = d_thread_wanted;
    const auto d_loop = [&] {
      detail::DownsampleEngine& engine = *engines_[size_t(finest_)];
      const int64_t cw = sizes_[size_t(finest_ - 1)].width;
      const auto emit = [&](int64_t, int64_t n, const double* rows) {
        std::vector<int32_t> chunk;
        {
          const std::lock_guard<std::mutex> hold(fd.lock);
          if (!fd.spare.empty()) {
            chunk = std::move(fd.spare.back());
            fd.spare.pop_back();
          }
        }
        chunk.resize(size_t(n * cw));
        // Rounded by the engine's workers (exact int32 values): a cast, as in emit_.
        for (int64_t k = 0; k < n * cw; ++k) chunk[size_t(k)] = static_cast<int32_t>(rows[k]);
        {
          const std::lock_guard<std::mutex> hold(fd.lock);
          fd.made.push_back(std::move(chunk));
          fd.made_rows.push_back(n);
          fd.has_made.store(true, std::memory_order_release);
        }
        main_signal_.notify();
      };
      for (;;) {
        FinestD::Job job{nullptr, 0, -1};
        {
          std::unique_lock<std::mutex> hold(fd.lock);
          fd.wake.wait(hold, [&] { return fd.stop || fd.finish || !fd.jobs.empty(); });
          if (fd.stop) return;
          if (!fd.jobs.empty()) {
            job = fd.jobs.front();
            fd.jobs.pop_front();
          }
        }
        try {
          const auto t = Clock::now();
          if (job.band < 0) {
            engine.finish(emit);
            fd.busy += seconds_since(t);
            fd.finished.store(true, std::memory_order_release);
            main_signal_.notify();
            return;
          }
          if (job.n > 0) engine.push_rows(job.rows, job.n, emit);
          fd.busy += seconds_since(t);
        } catch (...) {
          {
            const std::lock_guard<std::mutex> hold(fd.lock);
            fd.error = std::current_exception();
          }
          fd.finished.store(true, std::memory_order_release);
          main_signal_.notify();
          return;
        }
        {
          const std::lock_guard<std::mutex> hold(reader.lock);
          reader.d_consumed = job.band + 1;
        }
        reader.wake.notify_all();
      }
    };
    const auto d_give = [&](FinestD::Job job) {
      {
        const std::lock_guard<std::mutex> hold(fd.lock);
        if (job.band < 0)
          fd.finish = true;
        else
          fd.jobs.push_back(job);
      }
      fd.wake.notify_one();
    };
    // The coarse rows D's thread has made, into level m - 1 (and the coarser engines), in order.
    const auto take_coarse = [&] {
      if (!fd.has_made.load(std::memory_order_acquire) && !fd.finished.load(std::memory_order_acquire))
        return;
      std::vector<std::vector<int32_t>> got;
      std::vector<int64_t> rows;
      {
        const std::lock_guard<std::mutex> hold(fd.lock);
        if (fd.error) std::rethrow_exception(fd.error);
        got.swap(fd.made);
        rows.swap(fd.made_rows);
        fd.has_made.store(false, std::memory_order_relaxed);
      }
      const auto t = Clock::now();
      for (size_t k = 0; k < got.size(); ++k) take_rows(finest_ - 1, got[k].data(), rows[k]);
      main_.cascade += seconds_since(t);
      const std::lock_guard<std::mutex> hold(fd.lock);
      for (std::vector<int32_t>& c : got) fd.spare.push_back(std::move(c));
    };
    // What the main thread waits for wakes it also for D's rows (and a failed band), which it serves
    // meanwhile.
    // It looks first: D's thread waits for the band the main thread is waiting for.
    const auto serve_until = [&](const auto& done) {
      for (;;) {
        if (done()) return;
        if (fd.thread.joinable()) take_coarse();
        if (filter_ready_) pump(false);
        if (done()) return;
        main_signal_.wait([&] {
          return done() || fd.has_made.load(std::memory_order_acquire) ||
                 fd.finished.load(std::memory_order_acquire) || failed_.load(std::memory_order_acquire);
        });
      }
    };
    for (int64_t i = 0; i < n_bands; ++i) {
      InputBand& cur = bands[i % slots];
      if (i > 0 && ahead) {
        const auto t_wait = Clock::now();
        serve_until([&] {
          return reader.produced.load(std::memory_order_acquire) > i ||
                 reader.failed.load(std::memory_order_acquire);
        });
        if (reader.produced.load(std::memory_order_acquire) <= i) {
          const std::lock_guard<std::mutex> hold(reader.lock);
          std::rethrow_exception(reader.error);
        }
        wait_reader_ += seconds_since(t_wait);
      } else if (i > 0) {
        produce(cur, band_y(i));
      }
      // Rows above a stripe's cascade serve only D's fit (and the fill's carry, in the converter).
      const bool in_cascade = cur.y + cur.rows > read_a_ && cur.y < read_b_;
      if (in_cascade) result_.void_count += cur.voids;
      // The coders are behind: holding more rows would exceed the memory plan.
      while (must_wait_for_coders()) {
        const auto t_wait = Clock::now();
        wait_for_commit();
        wait_coders_ += seconds_since(t_wait);
        pump(false);
      }
      if (filter_ready_ && d_thread_wanted && !fd.thread.joinable() && engines_[size_t(finest_)]) {
        // From this band on every band goes to D's thread (counted there for the reader).
        {
          const std::lock_guard<std::mutex> hold(reader.lock);
          reader.d_consumed = i;
        }
        fd.thread = std::thread(d_loop);
      }
      if (!filter_ready_) {
        adopt(cur);
        if (levels_[size_t(finest_)].end() >= fit_rows_) start_cascade();
      } else if (fd.thread.joinable()) {
        // D's thread first (it reads the band's int32 rows, the level adopts its own copy).
        d_give({cur.ints.data(), in_cascade ? cur.rows : 0, i});
        if (in_cascade) {
          const auto t_append = Clock::now();
          adopt(cur);
          main_.append += seconds_since(t_append);
          const std::lock_guard<std::mutex> hold(sched_);
          drop_halo_rows(finest_);
        }
        take_coarse();
      } else if (in_cascade) {
        const auto t_append = Clock::now();
        adopt(cur);
        main_.append += seconds_since(t_append);
        // A few rows at a time, scheduling the bands they make ready as they come (bands made ready
        // early in a fill band would wait for D to run on all of it).
        constexpr int64_t kPushRows = 8;
        for (int64_t r = 0; r < cur.rows; r += kPushRows) {
          const int64_t n = std::min(kPushRows, cur.rows - r);
          const auto t_push = Clock::now();
          if (fed_fine_)
            feed_fine((cur.y + r + n) >> 1);
          else if (finest_ > stop_)
            engines_[size_t(finest_)]->push_rows(cur.ints.data() + r * W, n, emit_[size_t(finest_)]);
          main_.cascade += seconds_since(t_push);
          if (r + n < cur.rows) pump(false);
        }
        const std::lock_guard<std::mutex> hold(sched_);
        drop_halo_rows(finest_);
      }
      if (filter_ready_) pump(false);
      // The slot's next band: its row buffers are allocated here (RowRing::take_spares says why).
      if (i + slots < n_bands) take_spares(cur, std::min(B, H - band_y(i + slots)));
      if (ahead) {
        {
          const std::lock_guard<std::mutex> hold(reader.lock);
          reader.consumed = i + 1;
        }
        reader.wake.notify_all();
      }
    }
    if (!filter_ready_) start_cascade();
    if (fd.thread.joinable()) {
      const auto t_wait = Clock::now();
      d_give({nullptr, 0, -1});
      serve_until([&] { return fd.finished.load(std::memory_order_acquire); });
      take_coarse();
      fd.thread.join();
      finest_d_busy_ = fd.busy;
      finest_d_wait_ = seconds_since(t_wait);
    }
    if (read_a_ < read_b_)
      for (int l = finest_; l > stop_; --l) {
        if (l == finest_ && fd.finished.load(std::memory_order_acquire)) continue;
        if (l == finest_ && fed_fine_) {
          feed_fine(fine_hi_);
          continue;
        }
        engines_[size_t(l)]->finish(emit_[size_t(l)]);
      }
    const auto t_final = Clock::now();
    const double cpu_read = thread_cpu_seconds() - cpu_start, wall_read = seconds_since(t_start);
    if (ahead) reader_busy_ = reader.busy, reader_waited_ = reader.waited;
    busy_when_read_ = coders_busy();
    pump(true);
    const double wall_final = seconds_since(t_final);
    for (int l = 0; l < level_count_; ++l)
      if (next_band_[size_t(l)] != need_hi_[size_t(l)])
        throw std::logic_error("pyramid: level not completed");
    if (split_.kind == Split::Kind::Rows && rows_lo_ < rows_hi_) {
      const LevelRows& tk = levels_[size_t(split_.level)];
      if (tk.first() > rows_lo_ || tk.end() < rows_hi_)
        throw std::logic_error("pyramid: level rows not made");
      rows_out_.resize(size_t((rows_hi_ - rows_lo_) * sizes_[size_t(split_.level)].width));
      tk.copy_rows(rows_lo_, rows_hi_ - rows_lo_, rows_out_.data());
    }
    if (split_.kind == Split::Kind::Rows && fine_lo_ < fine_hi_) {
      const LevelRows& tf = levels_[size_t(finest_ - 1)];
      if (tf.first() > fine_lo_ || tf.end() < fine_hi_)
        throw std::logic_error("pyramid: level rows not made");
      // Moved out of the level's store, not copied: they are a quarter of the stripe's samples.
      fine_out_ = levels_[size_t(finest_ - 1)].wide_rows().take(fine_lo_, fine_hi_);
    }
    return finish_result(t_start, wall_read, cpu_read, wall_final);
  }

  // Coarse: codes levels 0..k from the whole T_k (split_.grid) with the stripes' fixed filter, through
  // the same engines and scheduler as the whole build, so the same bands.
  BuildResult run_coarse() {
    const auto t_start = Clock::now();
    build_start_ = t_start;
    const double cpu_start = thread_cpu_seconds();
    const int k = split_.level;
    filter_ = opt_.fixed_filter;
    header_.filter = filter_;
    result_.filter_report.reason = "fixed filter given by the caller";
    sink_.begin(header_);
    make_engines();
    filter_ready_ = true;
    const int64_t wk = sizes_[size_t(k)].width, hk = sizes_[size_t(k)].height;
    constexpr int64_t kPushRows = 8;
    for (int64_t r = 0; r < hk; r += kPushRows) {
      const int64_t n = std::min(kPushRows, hk - r);
      const int32_t* rows = split_.grid->data() + r * wk;
      {
        const std::lock_guard<std::mutex> hold(sched_);
        levels_[size_t(k)].append(rows, n);
      }
      if (k > 0) engines_[size_t(k)]->push_rows(rows, n, emit_[size_t(k)]);
      pump(false);
    }
    for (int l = k; l >= 1; --l) engines_[size_t(l)]->finish(emit_[size_t(l)]);
    const double cpu_read = thread_cpu_seconds() - cpu_start, wall_read = seconds_since(t_start);
    const auto t_final = Clock::now();
    pump(true);
    const double wall_final = seconds_since(t_final);
    for (int l = 0; l < level_count_; ++l)
      if (next_band_[size_t(l)] != need_hi_[size_t(l)])
        throw std::logic_error("pyramid: level not completed");
    return finish_result(t_start, wall_read, cpu_read, wall_final);
  }

  // Rows: the stripe's rows of level k, from rows_first() on; with keep_fine, those of level m-1.
  std::vector<int32_t>& rows_out() { return rows_out_; }
  int64_t rows_first() const { return rows_lo_; }
  std::vector<std::vector<int32_t>>& fine_out() { return fine_out_; }
  int64_t fine_first() const { return fine_lo_; }

 private:
  // The figures and the build log, once everything is coded.
  BuildResult finish_result(Clock::time_point t_start, double wall_read, double cpu_read, double wall_final) {
    for (int l = 0; l < level_count_; ++l)
      result_.levels[size_t(l)] = figures_[size_t(l)].stats(sizes_[size_t(l)]);
    result_.header = header_;
    std::ostringstream held;
    held << "rows held at most (level rows / decoded rows), coarsest first:";
    for (int l = 0; l < level_count_; ++l)
      held << " " << levels_[size_t(l)].peak() << "/" << reconstructed_[size_t(l)].peak();
    result_.log.push_back(held.str());
    // Where a many-thread build's wall time goes (docs/scale.md): while the input is read, the main
    // thread reads ahead, converts and runs D; it waits when the coders or the reader are behind.
    std::ostringstream main_thread;
    main_thread.precision(3);
    // The coding: the bands, the span from the first band scheduled to the last committed, the
    // thread-seconds the workers spent in bands and parts (the rest of the span's thread-seconds is
    // workers idle: no band ready), and the time spent handing bands to the sink (within those).
    std::ostringstream coding;
    coding.precision(3);
    const double busy = coders_busy();
    coding << "coding: " << coding_.count << " bands from " << std::max(0.0, first_band_at_) << " s for "
           << coding_.wall << " s, the workers busy " << busy << " thread-seconds of "
           << coding_.wall * opt_.threads << " ("
           << (coding_.wall > 0 ? 100 * busy / (coding_.wall * opt_.threads) : 0) << " %, " << coding_.deliver
           << " s of it writing bands out; " << busy_when_read_ << " thread-seconds busy by the input's end)";
    result_.log.push_back(coding.str());
    main_thread << "main thread: reading the input " << wall_read << " s (" << cpu_read
                << " s CPU; D cascade " << main_.cascade << " s, adopting rows " << main_.append
                << " s, scheduling bands " << main_.pump << " s, waiting " << wait_coders_
                << " s for the coders and " << wait_reader_ << " s for the reader), then coding the rest "
                << wall_final << " s";
    if (reader_busy_ >= 0)
      main_thread << "; the reader thread: " << reader_busy_ << " s reading and converting, "
                  << reader_waited_ << " s waiting for a free slot";
    if (finest_d_busy_ >= 0)
      main_thread << "; D's finest level on its own thread: " << finest_d_busy_
                  << " s in the engine, its last rows waited for " << finest_d_wait_ << " s";
    result_.log.push_back(main_thread.str());
    if (result_.void_count)
      result_.log.push_back("nodata: " + std::to_string(result_.void_count) +
                            " void samples filled by push-pull");
    result_.seconds_pass_residual = seconds_since(t_start) - result_.seconds_pass_input;
    return std::move(result_);
  }

  // Rows beyond the needed ones a stripe's cascade runs on, at every level (see plan_stripe).
  // 6: the 5 wrong rows and one to spare; at the coarsest level it costs 6 * 2^m input rows of D
  // per stripe edge, most of a stripe's extra work.
  static constexpr int64_t kDHalo = 6;
  double wait_coders_ = 0, wait_reader_ = 0;  // the main thread's waits, for the build log
  // The reader thread's seconds producing bands and waiting for a free slot (-1: no reader thread),
  // and the coders' busy thread-seconds when the input was all read (for the build log).
  double reader_busy_ = -1, reader_waited_ = 0, busy_when_read_ = 0;
  bool d_on_thread_ = false;  // D's finest engine runs on a thread of its own (run)
  // D's finest thread: its seconds in the engine, and the main thread's wait for its last rows.
  double finest_d_busy_ = -1, finest_d_wait_ = 0;
  // Wakes the main thread when anything it waits for happens (the reader's next band, D's coarse
  // rows, a band committed): one condition for all, so that waiting for one it serves the others. A
  // notifier changes its state first, then passes through the lock, so no wake-up is lost.
  struct MainSignal {
    std::mutex lock;
    std::condition_variable cv;
    void notify() {
      { const std::lock_guard<std::mutex> hold(lock); }
      cv.notify_all();
    }
    template <class Ready> void wait(const Ready& ready) {
      std::unique_lock<std::mutex> hold(lock);
      cv.wait(hold, ready);
    }
  } main_signal_;
  // The coding's bands, span (first band scheduled to last committed) and delivery, for the build log.
  struct CodingFigures {
    int64_t count = 0;
    double wall = 0, deliver = 0;
  } coding_;
  // The main thread's wall time in each of its jobs while the input is read, for the build log.
  struct MainFigures {
    double append = 0, cascade = 0, pump = 0;
  } main_;
  Clock::time_point build_start_;
  double first_band_at_ = -1;

  // Fits D on the top fit_rows rows (all still held: nothing is coded before the filter exists),
  // then starts the D cascade with every row received so far.
  void start_cascade() {
    const auto t = Clock::now();
    const int64_t W = info_.width;
    if (opt_.use_fixed_filter) {
      filter_ = opt_.fixed_filter;
      result_.filter_report.reason =
          filter_.is_wavelet() ? "the (4,4) lifting wavelet's low pass, the dual of U (fixed)"
          : filter_.is_point()
              ? "point sampling: coarse samples are the fine level's even-even samples (fixed)"
              : "fixed filter given by the caller";
      result_.log.push_back(result_.filter_report.summary());
    } else {
      const std::vector<Rect> windows = filter_fit_windows({W, fit_rows_}, opt_.fit);
      std::vector<std::vector<int32_t>> data;
      for (const Rect& r : windows) {
        std::vector<int32_t> d(size_t(r.width * r.height));
        for (int64_t yy = 0; yy < r.height; ++yy) {
          levels_[size_t(finest_)].copy_rows(r.y0 + yy, 1, row_scratch_.data());
          std::copy(row_scratch_.data() + r.x0, row_scratch_.data() + r.x0 + r.width,
                    d.begin() + yy * r.width);
        }
        data.push_back(std::move(d));
      }
      filter_ = fit_optimal_filter(windows, data, opt_.fit, &result_.filter_report);
      result_.log.push_back(result_.filter_report.summary() + " (fitted on the top " +
                            std::to_string(fit_rows_) + " rows)");
    }
    header_.filter = filter_;
    // Output starts now: nothing is coded before the filter exists.
    sink_.begin(header_);
    make_engines();
    filter_ready_ = true;
    result_.seconds_pass_input += seconds_since(t);
    levels_[size_t(finest_)].skip_to(read_a_);
    mask_.skip_to(read_a_);
    if (fed_fine_) {
      feed_fine(std::min(levels_[size_t(finest_)].end(), read_b_) >> 1);
    } else if (finest_ > stop_ && read_a_ < read_b_) {
      const LevelRows& tm = levels_[size_t(finest_)];
      for (int64_t r = tm.first(); r < std::min(tm.end(), read_b_); ++r) {
        tm.copy_rows(r, 1, row_scratch_.data());
        engines_[size_t(finest_)]->push_rows(row_scratch_.data(), 1, emit_[size_t(finest_)]);
      }
    }
    const std::lock_guard<std::mutex> hold(sched_);
    drop_halo_rows(finest_);
  }

  // The D engines of levels entry_ .. stop_ + 1, each feeding the next coarser one.
  void make_engines() {
    engines_.resize(size_t(level_count_));
    emit_.resize(size_t(level_count_));
    emitted_.resize(size_t(level_count_));
    // The cascade runs on the stripe's rows [read_a_, read_b_) as on a grid of its own (the whole
    // build: the input); read_a_ is a multiple of 2^(m - stop_), so level l's rows start at
    // read_a_ >> (m - l).
    int64_t cascade_height = read_b_ - read_a_;
    // Level l's samples lie within +-bound (int16 input: the finest level as read and filled, less
    // the integer offset; each coarser one D's gain times more): lets the wavelet D add pairs as
    // integers.
    int64_t bound = levels_[size_t(finest_)].narrow() ? 32768 + int64_t(std::abs(opt_.value_offset)) : 0;
    for (int l = finest_; l > stop_ && cascade_height > 0;
         --l, bound = detail::DownsampleEngine::coarse_bound(filter_, bound)) {
      if (l > entry_) {
        cascade_height = coarse_extent(cascade_height);
        continue;
      }
      // Coarse engines emit in small batches for the same reason as the band heights.
      const int64_t batch = std::max<int64_t>(1, int64_t(32) >> std::min(62, finest_ - l));
      // With D's finest engine on a thread of its own the coders have every core, and the engines'
      // workers only take cores from them and from the reader: two for the finest engine, none for
      // the coarser ones (a quarter of its rows and less; on the main thread). On the 16-core host
      // at 16 threads: 16 each 0.89-0.91 s a build, these 0.86-0.88 s and a third of the context
      // switches (docs/scale.md).
      const int workers = !d_on_thread_ ? opt_.threads : std::min(opt_.threads, l == finest_ ? 2 : 1);
      engines_[size_t(l)] = std::make_unique<detail::DownsampleEngine>(
          filter_, GridSize{sizes_[size_t(l)].width, cascade_height}, workers, batch, true, bound);
      cascade_height = coarse_extent(cascade_height);
      emit_[size_t(l)] = [this, l](int64_t, int64_t n, const double* rows) {
        const int64_t cw = sizes_[size_t(l - 1)].width;
        std::vector<int32_t>& out = emitted_[size_t(l - 1)];
        out.resize(size_t(n * cw));
        // Rounded by the engine's workers (exact int32 values): a cast, not a serial rounding.
        for (int64_t k = 0; k < n * cw; ++k) out[size_t(k)] = static_cast<int32_t>(rows[k]);
        take_rows(l - 1, out.data(), n);
      };
    }
  }

  // The next n rows of level l (made by D, or given): kept for coding, and D's next engine runs on them.
  void take_rows(int l, const int32_t* rows, int64_t n) {
    {
      const std::lock_guard<std::mutex> hold(sched_);
      levels_[size_t(l)].append(rows, n);
      drop_halo_rows(l);
    }
    if (l > stop_) engines_[size_t(l)]->push_rows(rows, n, emit_[size_t(l)]);
  }

  // Fed T_{m-1} (Fine with the Rows build's rows): the given rows up to level row `end`, in step with
  // the input rows read (input row r gives level row r / 2), so the levels hold what they would.
  void feed_fine(int64_t end) {
    end = std::min(end, fine_hi_);
    if (end <= fed_) return;
    for (; fed_ < end; ++fed_)
      take_rows(finest_ - 1, split_.fine->fine_rows[size_t(fed_ - fine_lo_)].data(), 1);
  }

  // A stripe's rows above its first needed band only feed D (its halo): once the cascade has them,
  // the level does not keep them (held, they were a third more memory on the last of two stripes).
  // sched_ held.
  void drop_halo_rows(int l) {
    levels_[size_t(l)].drop_before(need_lo_[size_t(l)]);
    if (l == finest_) mask_.drop_before(need_lo_[size_t(l)]);
  }

  // Last row of T^_{l-1} that U needs for fine rows [y0, y1) of level l, plus one.
  int64_t coarse_rows_needed(int l, int64_t y0, int64_t y1) const {
    const Rect need =
        upsample_required_window(Rect{0, y0, sizes_[size_t(l)].width, y1 - y0}, sizes_[size_t(l)]);
    return need.y0 + need.height;
  }

  bool band_ready(int l, int64_t y0, int64_t rows) const {
    if (levels_[size_t(l)].end() < y0 + rows) return false;
    return l == 0 || reconstructed_[size_t(l - 1)].end() >= coarse_rows_needed(l, y0, y0 + rows);
  }

  // A band scheduled and not yet committed: its work (recycled per level, with its buffers and its
  // copy of the T^_{l-1} rows U reads, which cwin names).
  struct Flight {
    int level = 0;
    std::unique_ptr<BandWork> work;
    CoarseWindow cwin;
    bool coded = false;
    std::exception_ptr error;
  };

  // Codes every band that can be coded now. A band of level l is ready once its rows of T_l exist
  // and T^_{l-1} is committed as far as its U reads, and each level has at most bands_in_flight
  // bands scheduled and not committed. With threads > 1 the workers code them in the background
  // (CodingPool), coarser levels first, and the worker that finishes a band commits every band it
  // completes in its level's order and schedules the bands that makes ready (advance): no round
  // waits for its slowest band, and a coarse band coded early unblocks finer ones at once. With
  // one thread they are coded here, coarser levels first. Bands are committed (delivered, their
  // T^ rows kept for the finer level) in each level's order whichever thread coded them, so the
  // output and the statistics do not depend on the thread count or on the timing. final: returns
  // once everything is coded.
  void pump(bool final) {
    struct Count {  // while the input is read (the final pump is the build log's "coding the rest")
      double* to;
      Clock::time_point from;
      ~Count() {
        if (to) *to += seconds_since(from);
      }
    } count{final ? nullptr : &main_.pump, Clock::now()};
    if (opt_.threads == 1) {
      for (;;) {
        schedule();
        Flight* next = nullptr;
        for (int l = 0; l < level_count_ && !next; ++l)
          for (const std::unique_ptr<Flight>& f : flights_[size_t(l)])
            if (!f->coded) {
              next = f.get();
              break;
            }
        if (!next) break;
        const auto t = Clock::now();
        code_flight(*next);
        coding_busy_ += seconds_since(t);
        next->coded = true;
        advance();
        deliver_committed();
        if (sched_error_) std::rethrow_exception(sched_error_);
      }
      return;
    }
    {
      const std::lock_guard<std::mutex> hold(sched_);
      if (sched_error_) std::rethrow_exception(sched_error_);
      if (!pool_.started())
        pool_.start(opt_.threads, [this](const CodingPool::Band& b) { code_on_worker(b); });
      schedule();
      if (!final || (in_flight_ == 0 && undelivered_.load(std::memory_order_acquire) == 0)) return;
    }
    // Every row exists now: once no band is in flight, none can be scheduled (the caller checks
    // that every level is complete).
    main_signal_.wait([&] {
      if (failed_.load(std::memory_order_acquire)) return true;
      const std::lock_guard<std::mutex> hold(sched_);  // no notifier holds it (code_on_worker)
      return in_flight_ == 0 && undelivered_.load(std::memory_order_acquire) == 0;
    });
    const std::lock_guard<std::mutex> hold(sched_);
    if (sched_error_) std::rethrow_exception(sched_error_);
  }

  // Waits until a band is committed after must_wait_for_coders looked (or a band failed).
  void wait_for_commit() {
    main_signal_.wait([&] {
      return commits_.load(std::memory_order_acquire) != seen_commits_ ||
             failed_.load(std::memory_order_acquire);
    });
    const std::lock_guard<std::mutex> hold(sched_);
    if (sched_error_) std::rethrow_exception(sched_error_);
  }

  // True while the main thread should not read further: bands are in flight and the finest level
  // already holds the rows the memory plan allows (the rows of the bands in flight included).
  bool must_wait_for_coders() {
    const std::lock_guard<std::mutex> hold(sched_);
    seen_commits_ = commits_.load(std::memory_order_relaxed);
    const LevelRows& tm = levels_[size_t(finest_)];
    return in_flight_ > 0 && tm.end() - next_band_[size_t(finest_)] >= memory_.finest_rows;
  }

  // A worker's band: coded, then committed with whatever it completes (sched_ taken here).
  void code_on_worker(const CodingPool::Band& b) {
    Flight& f = *static_cast<Flight*>(b.flight);
    code_flight(f);
    {
      const std::lock_guard<std::mutex> hold(sched_);
      f.coded = true;
      advance();
    }
    deliver_committed();
    main_signal_.notify();
  }

  // Hands the committed bands to the sink in commit order, one call at a time, outside sched_ (the
  // sink's writing held the main thread's row appends and the other workers' commits before). A
  // thread that finds another delivering leaves its bands to it: the deliverer looks again after
  // letting go.
  void deliver_committed() {
    int64_t returned = 0;
    for (;;) {
      std::unique_lock<std::mutex> delivering(delivering_, std::try_to_lock);
      if (!delivering.owns_lock()) return;
      for (;;) {
        Delivery d;
        {
          const std::lock_guard<std::mutex> hold(deliveries_lock_);
          if (deliveries_.empty()) break;
          d = std::move(deliveries_.front());
          deliveries_.pop_front();
        }
        if (!failed_.load(std::memory_order_acquire)) {
          const auto t = Clock::now();
          try {
            deliver_band(d.level, *d.work);  // the sink's errors (a full disk) are the build's
          } catch (...) {
            const std::lock_guard<std::mutex> hold(sched_);
            if (!sched_error_) sched_error_ = std::current_exception();
            failed_.store(true, std::memory_order_release);
          }
          coding_.deliver += seconds_since(t);
        }
        {
          const std::lock_guard<std::mutex> hold(deliveries_lock_);
          spare_work_[size_t(d.level)].push_back(std::move(d.work));
          --work_out_[size_t(d.level)];
        }
        ++returned;
      }
      delivering.unlock();
      if (returned > 0) {
        // The band work given back may be what a ready band waits for; the bands count as
        // undelivered until that is scheduled, so that pump(true) does not stop in between.
        {
          const std::lock_guard<std::mutex> hold(sched_);
          schedule();
        }
        undelivered_.fetch_sub(returned, std::memory_order_release);
        returned = 0;
      }
      const std::lock_guard<std::mutex> hold(deliveries_lock_);
      if (deliveries_.empty()) return;
    }
  }

  // Codes a scheduled band (its exception kept for the scheduler, which rethrows it on the main thread).
  void code_flight(Flight& f) {
    try {
      const int l = f.level;
      const int64_t fw = sizes_[size_t(l)].width;
      const bool finest = l == finest_;
      BandWork& bw = *f.work;
      const int64_t n = bw.rows * fw;
      bw.res.resize(size_t(n)), bw.rhat.resize(size_t(n));
      bw.valid.resize(finest ? size_t(n) : 0);
      if (finest)
        for (int64_t r = 0; r < bw.rows; ++r)
          MaskRows::unpack(*bw.src_mask[size_t(r)], fw, bw.valid.data() + r * fw);
      code_band(l, f.cwin, bw, opt_.threads > 1 ? &pool_ : nullptr);
    } catch (...) {
      f.error = std::current_exception();
    }
  }

  // Schedules every ready band (sched_ held with threads > 1).
  void schedule() {
    if (failed_.load(std::memory_order_relaxed)) return;
    for (int l = 0; l < level_count_; ++l) {
      const GridSize fs = sizes_[size_t(l)];
      const int64_t h = fs.height, S = level_band_rows_[size_t(l)], end = need_hi_[size_t(l)];
      std::deque<std::unique_ptr<Flight>>& q = flights_[size_t(l)];
      for (;;) {
        const int64_t y0 = sched_band_[size_t(l)];
        if (y0 >= end || !band_ready(l, y0, std::min(S, h - y0))) break;
        auto f = std::make_unique<Flight>();
        f->level = l;
        {
          // At most bands_in_flight bands' work per level, delivered or not (the memory plan's).
          const std::lock_guard<std::mutex> hold(deliveries_lock_);
          if (work_out_[size_t(l)] >= memory_.bands_in_flight) break;
          ++work_out_[size_t(l)];
          std::vector<std::unique_ptr<BandWork>>& spare = spare_work_[size_t(l)];
          if (!spare.empty()) {
            f->work = std::move(spare.back());
            spare.pop_back();
          }
        }
        if (!f->work) f->work = std::make_unique<BandWork>();
        BandWork& bw = *f->work;
        bw.y0 = y0;
        bw.rows = std::min(S, end - y0);
        bw.src.resize(size_t(bw.rows));
        bw.src_mask.resize(l == finest_ ? size_t(bw.rows) : 0);
        for (int64_t r = 0; r < bw.rows; ++r) {
          bw.src[size_t(r)] = levels_[size_t(l)].row(y0 + r);
          if (l == finest_) bw.src_mask[size_t(r)] = mask_.row_bits(y0 + r);
        }
        if (l > 0) {
          const GridSize cs = sizes_[size_t(l - 1)];
          const Rect need = upsample_required_window(Rect{0, y0, fs.width, bw.rows}, fs);
          bw.window.resize(size_t(need.height * cs.width));
          reconstructed_[size_t(l - 1)].copy_rows(need.y0, need.height, bw.window.data());
          f->cwin = CoarseWindow{bw.window.data(), cs.width, need, cs};
        } else {
          f->cwin = CoarseWindow{nullptr, 0, Rect{0, 0, 0, 0}, GridSize{0, 0}};
        }
        sched_band_[size_t(l)] = y0 + bw.rows;
        if (first_band_at_ < 0) first_band_at_ = seconds_since(build_start_);
        Flight* raw = f.get();
        q.push_back(std::move(f));
        ++in_flight_;
        if (opt_.threads > 1) pool_.submit({l, y0, raw});
      }
    }
  }

  // Commits the coded bands at the head of each level's queue, in order, then schedules what that
  // makes ready (sched_ held with threads > 1). A failed band stops the build: its error is rethrown
  // on the main thread, and nothing more is scheduled.
  void advance() {
    if (failed_.load(std::memory_order_relaxed)) return;
    bool committed = false;
    for (int l = 0; l < level_count_; ++l) {
      std::deque<std::unique_ptr<Flight>>& q = flights_[size_t(l)];
      while (!q.empty() && q.front()->coded) {
        Flight& f = *q.front();
        if (f.error) {
          sched_error_ = f.error;
          failed_.store(true, std::memory_order_release);
          return;
        }
        commit_band(l, *f.work);
        {
          const std::lock_guard<std::mutex> hold(deliveries_lock_);
          deliveries_.push_back({l, std::move(f.work)});
        }
        undelivered_.fetch_add(1, std::memory_order_relaxed);
        q.pop_front();
        --in_flight_;
        ++coding_.count;
        committed = true;
      }
    }
    if (!committed) return;
    coding_.wall = seconds_since(build_start_) - first_band_at_;
    commits_.fetch_add(1, std::memory_order_release);
    schedule();
  }

  // Hands a coded band to the sink, with its figures (sched_ held: one sink call at a time, each
  // level's bands in order).
  void deliver_band(int l, BandWork& bw) {
    const int64_t fw = sizes_[size_t(l)].width;
    const bool finest = l == finest_;
    // A stripe's halo bands are coded only for the T^ rows finer bands read.
    if (bw.y0 >= own_lo_[size_t(l)] && bw.y0 < own_hi_[size_t(l)]) {
      if (finest) sink_.mask_rows(bw.y0, bw.rows, bw.valid.data());
      figures_[size_t(l)].add(bw.figures, bw.bytes.size());
      sink_.band_figures(l, bw.y0, bw.figures);
      sink_.band(l, bw.y0, bw.rows, std::move(bw.bytes));
      if (sink_.wants_reconstruction(l)) sink_.reconstructed_rows(l, bw.y0, bw.rows, fw, bw.rhat.data());
    }
    bw.bytes = {};
  }

  // Takes a delivered band's T^ rows and drops the rows nothing needs any more.
  void commit_band(int l, const BandWork& bw) {
    const GridSize fs = sizes_[size_t(l)];
    const int64_t fw = fs.width, gy1 = bw.y0 + bw.rows;
    const bool finest = l == finest_;
    if (!finest) reconstructed_[size_t(l)].append(bw.rhat.data(), bw.rows);
    next_band_[size_t(l)] = gy1;
    levels_[size_t(l)].drop_before(gy1);
    if (finest) mask_.drop_before(gy1);
    if (l > 0) {
      const int64_t keep = gy1 < fs.height ? upsample_required_window(Rect{0, gy1, fw, 1}, fs).y0
                                           : reconstructed_[size_t(l - 1)].end();
      reconstructed_[size_t(l - 1)].drop_before(keep);
    }
  }

  // The figures of one row without voids where U = T_l - R: the scalar loop's sums, lane k & 3 of
  // the four partial sums taking the samples k = 0, 4, 8, ... in the same order (so the same
  // doubles), but in blocks of four that the compiler vectorises. The reconstruction T^ = U + R^ is
  // summed in int32 with an overflow check; false (nothing changed) if it overflowed somewhere,
  // for the scalar loop's saturation. k0: the row's first sample's index in the band.
  static bool figures_fast_row(const int32_t* t, const int32_t* res, int32_t* rhat, int64_t k0, int64_t w,
                               double res_sq[4], double err_sq[4], int64_t& res_max, int64_t& err_max) {
    const int32_t* r = res + k0;
    int32_t* h = rhat + k0;
    uint32_t overflow = 0;
    for (int64_t x = 0; x < w; ++x) {
      const uint32_t pred = uint32_t(t[x]) - uint32_t(r[x]), q = uint32_t(h[x]), rec = pred + q;
      overflow |= (~(pred ^ q)) & (pred ^ rec);
    }
    if (overflow >> 31) return false;
    double rs[4], es[4], rm[4] = {0, 0, 0, 0}, em[4] = {0, 0, 0, 0};
    for (int j = 0; j < 4; ++j) rs[j] = res_sq[j], es[j] = err_sq[j];
    // Sample x into lane j = (k0 + x) & 3 (its largest magnitudes too, merged at the end).
    const auto sample = [&](int64_t x, size_t j) {
      const int32_t rec = int32_t(uint32_t(t[x]) - uint32_t(r[x]) + uint32_t(h[x]));
      const double rd = double(r[x]), ed = double(t[x]) - double(rec);
      rs[j] += rd * rd;
      es[j] += ed * ed;
      rm[j] = std::max(rm[j], std::fabs(rd));
      em[j] = std::max(em[j], std::fabs(ed));
      h[x] = rec;
    };
    // A scalar head up to a multiple of four, blocks of four (one sample a lane), a tail.
    int64_t x = 0;
    for (; x < w && ((k0 + x) & 3) != 0; ++x) sample(x, size_t((k0 + x) & 3));
    for (; x + 4 <= w; x += 4)
      for (size_t j = 0; j < 4; ++j) sample(x + int64_t(j), j);
    for (; x < w; ++x) sample(x, size_t((k0 + x) & 3));
    for (int j = 0; j < 4; ++j) {
      res_sq[j] = rs[j], err_sq[j] = es[j];
      res_max = std::max(res_max, int64_t(rm[j]));
      err_max = std::max(err_max, int64_t(em[j]));
    }
    return true;
  }

  // Codes one band; its parts on `workers` (null: on this thread alone).
  void code_band(int l, const CoarseWindow& cwin, BandWork& bw, CodingPool* workers) {
    const GridSize fs = sizes_[size_t(l)];
    const int64_t n = bw.rows * fs.width;
    const bool with_mask = l == finest_;
    // U's prediction goes into the residual's buffer and R = T_l - U is formed in place: the band
    // holds no prediction beside R and T^ (4 of its bytes a sample in flight); U is recovered below
    // as T_l - R, or computed again for a band where that does not give it back (voids, saturation).
    const Rect band{0, bw.y0, fs.width, bw.rows};
    const auto predict = [&](const Rect& r, int32_t* out) {
      if (l > 0)
        upsample_region(cwin, fs, r, out, fs.width, bw.scratch);
      else
        std::fill(out, out + r.height * fs.width, 0);
    };
    predict(band, bw.res.data());
    // T_l is read from the level's rows (a copy of the band was a sixth of its bytes in flight).
    const int64_t fw = fs.width;
    const bool narrow = levels_[size_t(l)].narrow();
    bw.t.resize(size_t(fw));
    const auto t_row = [&](int64_t r) {
      if (narrow) {
        const int16_t* in = static_cast<const int16_t*>(bw.src[size_t(r)]);
        std::copy(in, in + fw, bw.t.begin());
      } else {
        const int32_t* in = static_cast<const int32_t*>(bw.src[size_t(r)]);
        std::copy(in, in + fw, bw.t.begin());
      }
      return bw.t.data();
    };
    bool exact = true;  // T_l - R == U everywhere
    for (int64_t r = 0; r < bw.rows; ++r) {
      const int32_t* t = t_row(r);
      int32_t* u = bw.res.data() + r * fw;
      // In int32 with an overflow check (vectorised), the row again with saturation if it overflowed.
      uint32_t overflow = 0;
      for (int64_t x = 0; x < fw; ++x) {
        const uint32_t a = uint32_t(t[x]), b = uint32_t(u[x]), d = a - b;
        overflow |= (a ^ b) & (a ^ d);
        u[x] = int32_t(d);
      }
      if (!(overflow >> 31)) continue;
      for (int64_t x = 0; x < fw; ++x) {  // u[x] is t - U wrapped: U = t - u[x] (mod 2^32)
        const int32_t pred = int32_t(uint32_t(t[x]) - uint32_t(u[x]));
        const int64_t d = int64_t(t[x]) - pred;
        u[x] = saturate(d);
        exact &= u[x] == d;
      }
    }
    // Voids are restored from the mask, so their residual carries no information.
    const bool any_void =
        with_mask && std::find(bw.valid.begin(), bw.valid.end(), uint8_t(0)) != bw.valid.end();
    if (any_void) {
      exact = false;
      for (int64_t k = 0; k < n; ++k)
        if (!bw.valid[size_t(k)]) bw.res[size_t(k)] = 0;
    }
    // Parts of about kPartSamples (the coder splits by runs of whole tiles), at most two per worker:
    // small enough that the last bands of a level end together, few enough that a part's own scratch and
    // hand-over stay a small cost.
    constexpr int64_t kPartSamples = int64_t(1) << 16;
    const int parts =
        int(std::clamp<int64_t>((n + kPartSamples - 1) / kPartSamples, 1, 2 * int64_t(opt_.threads)));
    bw.bytes = workers
                   ? coder_.encode_parts(bw.res.data(), fs.width, bw.rows, bw.rhat.data(), finest_ - l,
                                         l == 0, parts, *workers)
                   : coder_.encode(bw.res.data(), fs.width, bw.rows, bw.rhat.data(), finest_ - l, l == 0, 1);
    // Four partial sums in a fixed order: deterministic, and no single floating-point add chain.
    double res_sq[4] = {0, 0, 0, 0}, err_sq[4] = {0, 0, 0, 0};
    int64_t res_max = 0, err_max = 0, counted = 0;
    const int32_t* res = bw.res.data();
    int32_t* rhat = bw.rhat.data();
    if (!exact) bw.pred_row.resize(size_t(fw));
    for (int64_t row = 0; row < bw.rows; ++row) {
      const int32_t* t = t_row(row);
      if (exact && !any_void &&
          figures_fast_row(t, res, rhat, row * fw, fw, res_sq, err_sq, res_max, err_max)) {
        counted += fw;
        continue;
      }
      if (!exact) predict(Rect{0, bw.y0 + row, fw, 1}, bw.pred_row.data());
      for (int64_t x = 0, k = row * fw; x < fw; ++x, ++k) {
        const int32_t pred = exact ? int32_t(int64_t(t[x]) - res[k]) : bw.pred_row[size_t(x)];
        const int32_t rec = saturate(int64_t(pred) + rhat[k]);
        if (!any_void || bw.valid[size_t(k)]) {
          const int64_t r = res[k], e = int64_t(t[x]) - rec;
          res_sq[k & 3] += double(r) * double(r);
          err_sq[k & 3] += double(e) * double(e);
          res_max = std::max(res_max, r < 0 ? -r : r);
          err_max = std::max(err_max, e < 0 ? -e : e);
          ++counted;
        }
        rhat[k] = rec;  // now T^ of this band
      }
    }
    bw.figures.res_sq = (res_sq[0] + res_sq[1]) + (res_sq[2] + res_sq[3]);
    bw.figures.err_sq = (err_sq[0] + err_sq[1]) + (err_sq[2] + err_sq[3]);
    bw.figures.res_max = res_max, bw.figures.err_max = err_max, bw.figures.counted = counted;
  }

  const GridInfo info_;
  const BuildOptions& opt_;
  ResidualCoder& coder_;
  PyramidSink& sink_;
  std::vector<GridSize> sizes_;
  int level_count_ = 0;           // L = m + 1
  int finest_ = 0;                // m, the index of the finest level (the input)
  int64_t finest_band_rows_ = 0;  // S, the coder's band height at the finest level
  int64_t fit_rows_ = 0;
  std::vector<int64_t> level_band_rows_;
  BuildMemoryPlan memory_;
  DownsampleFilter filter_;
  bool filter_ready_ = false;
  PyramidHeader header_;
  std::vector<LevelRows> levels_;                // T_l: rows of each level not yet coded
  std::vector<RowRing<int32_t>> reconstructed_;  // T^_l: decoded rows U still needs for level l+1
  MaskRows mask_;
  std::vector<int32_t> row_scratch_;
  std::vector<std::unique_ptr<detail::DownsampleEngine>> engines_;
  std::vector<detail::DownsampleEngine::Emit> emit_;
  std::vector<std::vector<int32_t>> emitted_;
  std::vector<int64_t> next_band_;  // per level: first row not yet coded
  // Per level: the stripe's own bands [own_lo_, own_hi_) and the rows it codes [need_lo_, need_hi_).
  std::vector<int64_t> own_lo_, own_hi_, need_lo_, need_hi_;
  int64_t read_a_ = 0, read_b_ = 0;  // input rows the D cascade runs on
  const Split split_;
  const bool seek_above_;
  int stop_ = 0;                         // the coarsest level the D cascade makes
  int entry_ = 0;                        // the level whose rows come in (the input's, but for Coarse)
  int64_t given_lo_ = 0, given_hi_ = 0;  // Fine: the rows of T^_k held
  int64_t rows_lo_ = 0, rows_hi_ = 0;    // Rows: the rows of level k made
  std::vector<int32_t> rows_out_;
  std::vector<std::vector<int32_t>> fine_out_;
  // T_{m-1} rows: kept by Rows (keep_fine), fed by Fine (fed_fine_: up to fed_) instead of D's finest engine.
  int64_t fine_lo_ = 0, fine_hi_ = 0, fed_ = 0;
  bool fed_fine_ = false;
  std::vector<LevelFigures> figures_;
  // The scheduler's state (pump): sched_ guards it, the levels' and the mask's rows, T^ rows,
  // next_band_ and the figures while workers run (threads > 1); the main thread takes it to append
  // or drop rows.
  std::mutex sched_;
  std::vector<std::deque<std::unique_ptr<Flight>>> flights_;  // per level: bands not committed, in order
  std::vector<std::vector<std::unique_ptr<BandWork>>> spare_work_;  // per level: recycled (deliveries_lock_)
  // Bands committed and not yet delivered, in commit order (deliver_committed).
  struct Delivery {
    int level = 0;
    std::unique_ptr<BandWork> work;
  };
  std::mutex deliveries_lock_, delivering_;  // the queue and the spares; the one thread delivering
  std::deque<Delivery> deliveries_;
  std::atomic<int64_t> undelivered_{0};
  std::vector<int> work_out_;        // per level: band work taken and not yet given back (deliveries_lock_)
  std::vector<int64_t> sched_band_;  // per level: first row not scheduled
  int64_t in_flight_ = 0;
  std::exception_ptr sched_error_;
  std::atomic<bool> failed_{false};
  std::atomic<uint64_t> commits_{0};
  uint64_t seen_commits_ = 0;  // commits_ when must_wait_for_coders last looked (main thread)
  double coding_busy_ = 0;     // one thread: seconds coding bands
  // The coders' thread-seconds in bands and parts so far (the pool's workers, or this thread alone).
  double coders_busy() { return opt_.threads > 1 ? pool_.busy() : coding_busy_; }
  CodingPool pool_;  // threads > 1, started with the first band; stopped first in ~StreamingBuilder
  BuildResult result_;
};

}  // namespace

BuildMemoryPlan plan_build_memory(const GridInfo& input, const BuildOptions& options, int64_t band_rows,
                                  bool striped, int first_level) {
  validate(options, input);
  if (band_rows < 1) throw std::invalid_argument("pyramid: coder band_rows must be >= 1");
  const std::vector<GridSize> sizes =
      pyramid_level_sizes({input.width, input.height}, options.level_count, options.min_coarsest_side);
  return plan_memory(input, options, sizes, level_band_rows(int(sizes.size()), band_rows), striped,
                     first_level);
}

BuildResult build_pyramid(BandReader& input, const BuildOptions& opt, ResidualCoder& coder,
                          PyramidSink& sink) {
  StreamingBuilder builder(input.info(), opt, coder, sink, BuildStripe{0, input.info().height});
  return builder.run(input);
}

BuildResult build_pyramid_stripe(BandReader& input, const BuildOptions& opt, const BuildStripe& stripe,
                                 ResidualCoder& coder, PyramidSink& sink) {
  StreamingBuilder builder(input.info(), opt, coder, sink, stripe);
  return builder.run(input);
}

BuildResult build_stripe_level_rows(BandReader& input, const BuildOptions& opt, const BuildStripe& stripe,
                                    int level, ResidualCoder& coder, StripeLevelRows& out, bool keep_fine) {
  CountingSink none;
  StreamingBuilder builder(input.info(), opt, coder, none, stripe,
                           Split{Split::Kind::Rows, level, nullptr, keep_fine, nullptr});
  BuildResult r = builder.run(input);
  out.first_row = builder.rows_first();
  out.width = r.header.levels[size_t(level)].width;
  out.rows = std::move(builder.rows_out());
  out.fine_first_row = builder.fine_first();
  out.fine_rows = std::move(builder.fine_out());
  return r;
}

BuildResult build_pyramid_coarse_levels(const GridInfo& input, const BuildOptions& opt, int level,
                                        const std::vector<int32_t>& level_grid, ResidualCoder& coder,
                                        PyramidSink& sink) {
  StreamingBuilder builder(input, opt, coder, sink, BuildStripe{0, input.height},
                           Split{Split::Kind::Coarse, level, &level_grid});
  return builder.run_coarse();
}

BuildResult build_pyramid_stripe_fine_levels(BandReader& input, const BuildOptions& opt,
                                             const BuildStripe& stripe, int level,
                                             const std::vector<int32_t>& coarse_reconstruction,
                                             ResidualCoder& coder, PyramidSink& sink,
                                             const StripeLevelRows* fine) {
  StreamingBuilder builder(input.info(), opt, coder, sink, stripe,
                           Split{Split::Kind::Fine, level, &coarse_reconstruction, false,
                                 fine && !fine->fine_rows.empty() ? fine : nullptr});
  return builder.run(input);
}

void LevelFigures::add(const BandFigures& band, uint64_t bytes) {
  res_sq_ += band.res_sq, err_sq_ += band.err_sq, counted_ += band.counted;
  res_max_ = std::max(res_max_, band.res_max);
  err_max_ = std::max(err_max_, band.err_max);
  bytes_ += bytes;
}

LevelBuildStats LevelFigures::stats(GridSize size) const {
  LevelBuildStats st;
  st.size = size;
  st.residual_rms = counted_ ? std::sqrt(res_sq_ / double(counted_)) : 0.0;
  st.error_rms = counted_ ? std::sqrt(err_sq_ / double(counted_)) : 0.0;
  st.residual_max_abs = res_max_;
  st.error_max_abs = err_max_;
  st.bytes = bytes_;
  return st;
}

namespace {

class MemoryBandReader final : public BandReader {
 public:
  MemoryBandReader(const Heightmap& map, int64_t max_rows)
      : map_(map), max_rows_(std::max<int64_t>(1, max_rows)) {
    const int64_t n = map.width() * map.height();
    if (map.width() < 0 || map.height() < 0 || int64_t(map.values.size()) != n ||
        (!map.valid.empty() && int64_t(map.valid.size()) != n))
      throw std::invalid_argument("pyramid: heightmap arrays do not match its dimensions");
  }
  const GridInfo& info() const override { return map_.info; }
  int64_t read_rows(int64_t rows, double* values, uint8_t* valid) override {
    const int64_t w = map_.width();
    const int64_t n = std::min({rows, max_rows_, map_.height() - rows_read_});
    if (n <= 0) return 0;
    const size_t off = size_t(rows_read_ * w), cnt = size_t(n * w);
    std::copy(map_.values.begin() + off, map_.values.begin() + off + cnt, values);
    if (map_.valid.empty())
      std::fill(valid, valid + cnt, uint8_t(1));
    else
      std::copy(map_.valid.begin() + off, map_.valid.begin() + off + cnt, valid);
    rows_read_ += n;
    return n;
  }

 private:
  const Heightmap& map_;
  int64_t max_rows_;
};

}  // namespace

std::unique_ptr<BandReader> make_memory_band_reader(const Heightmap& map, int64_t max_rows_per_call) {
  return std::make_unique<MemoryBandReader>(map, max_rows_per_call);
}

std::vector<int32_t> to_level_grid(const Heightmap& map, const BuildOptions& options,
                                   std::vector<uint8_t>* valid) {
  validate(options, map.info);
  MemoryBandReader reader(map, int64_t(1) << 40);
  const int64_t W = map.width(), H = map.height();
  std::vector<int32_t> out(size_t(W * H));
  std::vector<double> values(size_t(W * H));
  std::vector<uint8_t> mask(size_t(W * H));
  reader.read_rows(H, values.data(), mask.data());
  InputConverter converter(options, map.info);
  const int64_t B = options.fill_band_rows;
  for (int64_t y = 0; y < H; y += B)
    converter.convert(values.data() + y * W, mask.data() + y * W, y, std::min(B, H - y), out.data() + y * W);
  if (valid) *valid = std::move(mask);
  return out;
}

BuildResult build_pyramid(const Heightmap& map, const BuildOptions& options, ResidualCoder& coder,
                          PyramidSink& sink) {
  MemoryBandReader reader(map, int64_t(1) << 40);
  return build_pyramid(reader, options, coder, sink);
}

}  // namespace terrain
