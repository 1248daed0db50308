// Nodata mask coding: the row-major mask as alternating run lengths (data, void, data, ...),
// starting with a data run that may be empty, every later run non-empty, each an LEB128 varint.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace terrain::container::mask_runs {

// Appends v as an unsigned LEB128 varint.
void put_varint(std::vector<uint8_t>& out, uint64_t v);

// Checks that the runs cover exactly `samples` samples with `voids` of them void and that the
// stream is canonical; returns an empty string if so, else what is wrong.
std::string check(const uint8_t* runs, size_t size, uint64_t samples, uint64_t voids);

// Expands samples [first, first + count) of checked runs into out[0 .. count) as 1 = data,
// 0 = void. Runs are scanned from the start: O(runs before the range + count).
void expand(const uint8_t* runs, size_t size, uint64_t first, uint64_t count, uint8_t* out);

}  // namespace terrain::container::mask_runs
