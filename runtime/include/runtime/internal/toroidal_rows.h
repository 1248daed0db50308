// Rows of the clipmap's toroidal storage (an n x n level, sample x of a row at row[x mod n]) read or
// written as contiguous runs. Internal to runtime: the clipmap and the height source that reads the
// clipmap's coarser level.
#pragma once

#include <algorithm>
#include <cstdint>

namespace terrain::runtime {

// Where a run of level columns x0 .. x0 + count - 1, clamped to the clip region's columns c0 .. c1,
// lies in a toroidal row of n samples (sample x at row[x mod n]): the repeated edge samples and at
// most two contiguous runs. Computed once per rectangle, applied to each of its rows, so that a row
// costs copies only (thin strips have many short rows).
struct RowRuns {
  int64_t count, in0, in1;  // dst[0, in0) repeat column c0, dst[in1, count) column c1
  int64_t start, run1;      // dst[in0, in0 + run1) from row[start ..], the rest from row[0 ..]
  int64_t left, right;      // storage columns of c0 and c1
  RowRuns(int64_t n, int64_t x0, int64_t count_, int64_t c0, int64_t c1) : count(count_) {
    auto wrap = [n](int64_t v) { return ((v % n) + n) % n; };
    in0 = std::clamp<int64_t>(c0 - x0, 0, count);
    in1 = std::clamp<int64_t>(c1 + 1 - x0, in0, count);
    start = wrap(x0 + in0);
    run1 = std::min(in1 - in0, n - start);
    left = wrap(c0);
    right = wrap(c1);
  }
  // Columns without clamping (they lie in the clip region): count <= n.
  RowRuns(int64_t n, int64_t x0, int64_t count_) : RowRuns(n, x0, count_, x0, x0 + count_ - 1) {}
  template <typename T> void gather(const T* row, T* dst) const {
    std::fill(dst, dst + in0, row[left]);
    std::copy_n(row + start, run1, dst + in0);
    std::copy_n(row, in1 - in0 - run1, dst + in0 + run1);
    std::fill(dst + in1, dst + count, row[right]);
  }
  template <typename T> void scatter(const T* src, T* row) const {  // the inverse, for unclamped runs
    std::copy_n(src, run1, row + start);
    std::copy_n(src + run1, count - run1, row);
  }
};

}  // namespace terrain::runtime
