#include "container/internal/container_mask.h"

#include <algorithm>
#include <cstring>

#include "core/bytes.h"

namespace terrain::container::mask_runs {
namespace {

// Reads one varint at runs[pos] and moves pos past it; false if it is cut off or beyond 64 bits.
bool get_varint(const uint8_t* runs, size_t size, size_t& pos, uint64_t& v) {
  const uint8_t* p = runs + pos;
  const bool ok = bytes::get_varint(p, runs + size, &v);
  pos = size_t(p - runs);
  return ok;
}

}  // namespace

void put_varint(std::vector<uint8_t>& out, uint64_t v) { bytes::put_varint(out, v); }

std::string check(const uint8_t* runs, size_t size, uint64_t samples, uint64_t voids) {
  size_t pos = 0;
  uint64_t covered = 0, void_total = 0;
  bool is_void = false;
  for (bool first = true; pos < size; first = false, is_void = !is_void) {
    uint64_t run;
    if (!get_varint(runs, size, pos, run)) return "mask run stream is cut off or malformed";
    if (run == 0 && !first) return "mask has an empty run";
    if (run > samples - covered) return "mask runs cover more samples than the grid has";
    covered += run;
    if (is_void) void_total += run;
  }
  if (covered != samples) return "mask runs cover fewer samples than the grid has";
  if (void_total != voids) return "mask void count does not match its runs";
  return {};
}

void expand(const uint8_t* runs, size_t size, uint64_t first, uint64_t count, uint8_t* out) {
  const uint64_t end = first + count;
  size_t pos = 0;
  uint64_t run_start = 0;  // sample index where the current run begins
  bool is_void = false;
  while (pos < size && run_start < end) {
    uint64_t run;
    if (!get_varint(runs, size, pos, run)) break;
    // Clip the run to the requested range; a checked stream never overruns `end` by wrapping.
    const uint64_t lo = std::max(run_start, first);
    const uint64_t hi = std::min(run_start + run, end);
    if (lo < hi) std::memset(out + (lo - first), is_void ? 0 : 1, size_t(hi - lo));
    run_start += run;
    is_void = !is_void;
  }
}

}  // namespace terrain::container::mask_runs
