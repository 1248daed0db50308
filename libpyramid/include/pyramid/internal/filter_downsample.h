// Row engine of the 11x11 downsampling filter D, shared by the in-memory wrapper, the filter fit and
// the streaming builder (so all three compute bit-identical coarse samples).
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "pyramid/pyramid.h"

namespace terrain::detail {

// Mirror reflection without repeating the edge sample, folded as often as needed (n >= 1).
inline int64_t reflect_index(int64_t i, int64_t n) {
  if (n == 1) return 0;
  const int64_t period = 2 * (n - 1);
  i %= period;
  if (i < 0) i += period;
  return i < n ? i : period - i;
}

// Fine rows go in top to bottom; coarse rows (real-valued D, unrounded) come out in batches as soon
// as the rows they read have arrived. Holds O(batch + filter height) fine rows.
class DownsampleEngine {
 public:
  // emit(first_coarse_row, rows, data) with data = rows x coarse width doubles.
  using Emit = std::function<void(int64_t, int64_t, const double*)>;

  // rounded: the coarse rows come out as round_to_int32 of D (still doubles, each an exact int32),
  // rounded on the workers that compute them rather than by the caller, one thread.
  // max_abs: a bound on every pushed sample's magnitude (0: none known); below 2^30 it lets the
  // wavelet D add sample pairs as integers (the same results, less work).
  DownsampleEngine(const DownsampleFilter& filter, GridSize fine, int threads, int64_t batch_rows = 32,
                   bool rounded = false, int64_t max_abs = 0);
  // A bound on the magnitude of the coarse samples that `filter` makes from samples within +-max_abs,
  // rounded (0: none, when max_abs is 0 or the bound passes 2^40).
  static int64_t coarse_bound(const DownsampleFilter& filter, int64_t max_abs);
  // The next `count` fine rows (count x fine width, row-major), read during the call only: the coarse
  // rows they complete are emitted before it returns, and the rows later ones need are kept. Throws
  // std::invalid_argument past the grid's height.
  void push_rows(const int32_t* rows, int64_t count, const Emit& emit);
  // Emits the remaining coarse rows; every fine row must have been pushed.
  void finish(const Emit& emit);
  GridSize coarse() const { return coarse_; }

 private:
  struct Scratch {
    std::vector<double> fold, even, odd, acc;
  };
  // Fine row as int32, unpadded: a held row, or during push_rows one of the caller's; the workers
  // convert and reflect what they read (a fifth of a 16-thread build's main thread was converting
  // every fine row to padded doubles here).
  const int32_t* fine_row(int64_t fine_row) const;
  // dst[0 .. padded_width_) = double(row) with D's mirror padding.
  void pad_row(const int32_t* row, double* dst) const;
  // Fills the 2 R padding columns of a padded row whose centre columns are set (the mirror rule).
  void reflect_padding(double* padded) const;
  int64_t min_row_needed(int64_t j) const;
  // 1 + highest fine row read by coarse rows next_coarse_ .. j_end - 1. Asked after every pushed row
  // with the same arguments until the batch is computed, so the answer is kept (the loop over the
  // batch's 32 x 11 reflected rows was a quarter of the whole build's CPU time).
  int64_t rows_needed_through(int64_t j_end);
  void compute(int64_t j0, int64_t j1, const Emit& emit);
  void compute_row(int64_t j, Scratch& s, double* out) const;

  DownsampleFilter filter_;
  bool symmetric_;
  // The wavelet D (its taps exactly): rows then columns with the 1-D taps, a quarter of the 2-D
  // folded path's arithmetic; chosen by the taps alone, so every caller gets the same samples.
  bool separable_;
  bool int_pairs_;  // separable_ with samples below 2^30 in magnitude: wavelet_columns<true>
  bool rounded_;
  bool fused_round_ = false;  // int_pairs_, rounded_, outputs below 2^30 in magnitude: wavelet_rows<true>
  GridSize fine_, coarse_;
  int threads_;
  int64_t batch_;
  int64_t padded_width_;
  std::vector<int32_t> rows_;  // capacity_ fine rows, ring-free: rows base_.. base_+count_-1
  int64_t capacity_ = 0, base_ = 0, count_ = 0, pushed_ = 0, next_coarse_ = 0;
  // During push_rows: the caller's rows, fine rows block_first_ .. pushed_ - 1 (the held rows end at
  // block_first_).
  const int32_t* block_ = nullptr;
  int64_t block_first_ = 0;
  int64_t needed_from_ = -1, needed_to_ = -1, needed_rows_ = 0;  // rows_needed_through's last answer
  std::vector<Scratch> scratch_;
  std::vector<double> out_;
};

// round(x) half away from zero, saturated to int32.
int32_t round_to_int32(double x);
// out[i] = double(round_to_int32(out[i])) for i in [0, n), vectorised where every |out[i]| < 2^30.
void round_row(double* out, int64_t n);

// Real-valued D over a whole in-memory grid (filter design).
void downsample_real(const DownsampleFilter& filter, const int32_t* fine, GridSize fine_level, double* coarse,
                     int threads = 1);

}  // namespace terrain::detail
