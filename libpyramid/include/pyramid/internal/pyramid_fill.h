// Nodata fill before filtering (push-pull), so voids do not pollute their neighbours through D.
#pragma once

#include <cstdint>
#include <vector>

namespace terrain::detail {

struct PushPullScratch {
  std::vector<int64_t> sum, count;
};

// Fills the void samples (valid == 0) of a band of rows (w x h, row-major) in place. The band is cut
// into tiles of `tile` x h; each tile is filled by push-pull: valid samples are averaged up a 2x2
// pyramid (sums and counts) and every void takes the rounded mean of the smallest enclosing block
// that has valid samples. A tile without any valid sample takes the mean of the previous non-empty
// tile of the band (left to right), else *carry. *carry is updated to the last non-empty tile's mean,
// so results depend only on the band's contents and the carry (deterministic, streamable).
void fill_voids(int32_t* values, const uint8_t* valid, int64_t w, int64_t h, int64_t tile, int32_t* carry,
                PushPullScratch& scratch);

}  // namespace terrain::detail
