// In-memory sink and the coarse-to-fine decoder over it (tests and small inputs; the runtime decodes
// regions from the container with the same upsample_region and coder).
#include <algorithm>
#include <limits>
#include <stdexcept>

#include "pyramid/pyramid.h"

namespace terrain {

void MemoryPyramid::begin(const PyramidHeader& h) {
  header = h;
  bands.assign(h.levels.size(), {});
  mask.clear();
}

void MemoryPyramid::band(int level, int64_t y0, int64_t rows, std::vector<uint8_t>&& bytes) {
  if (size_t(level) >= bands.size()) bands.resize(size_t(level) + 1);
  bands[size_t(level)].push_back({y0, rows, std::move(bytes)});
}

void MemoryPyramid::mask_rows(int64_t y0, int64_t rows, const uint8_t* valid) {
  const size_t width = size_t(header.levels.back().width), n = size_t(rows) * width;
  if (!mask.empty() && mask.size() != size_t(y0) * width)
    throw std::logic_error("MemoryPyramid: mask rows out of order");
  // Rows before the first void are not stored: an input without voids keeps an empty mask.
  if (mask.empty()) {
    if (std::find(valid, valid + n, uint8_t(0)) == valid + n) return;
    mask.assign(size_t(y0) * width, uint8_t(1));
  }
  mask.insert(mask.end(), valid, valid + n);
}

void MemoryPyramid::reconstructed_rows(int level, int64_t y0, int64_t rows, int64_t width,
                                       const int32_t* data) {
  if (size_t(level) >= recon.size()) recon.resize(size_t(level) + 1);
  auto& r = recon[size_t(level)];
  r.resize(size_t((y0 + rows) * width));
  std::copy(data, data + rows * width, r.begin() + y0 * width);
}

uint64_t MemoryPyramid::total_bytes() const {
  uint64_t n = 0;
  for (auto& level : bands)
    for (auto& b : level) n += b.bytes.size();
  return n;
}

std::vector<int32_t> decode_pyramid(const MemoryPyramid& p, ResidualCoder& coder, int up_to_level,
                                    std::vector<uint8_t>* valid) {
  const auto& levels = p.header.levels;
  if (up_to_level < 0 || up_to_level >= int(levels.size()) || p.bands.size() != levels.size())
    throw Error(ErrorCode::CorruptData, "pyramid: level " + std::to_string(up_to_level) + " not present");
  std::vector<int32_t> prev, cur, rhat;
  UpsampleScratch scratch;
  for (int l = 0; l <= up_to_level; ++l) {
    const GridSize fs = levels[size_t(l)];
    cur.assign(size_t(fs.width * fs.height), 0);
    if (l > 0) {
      const GridSize cs = levels[size_t(l - 1)];
      const CoarseWindow w{prev.data(), cs.width, Rect{0, 0, cs.width, cs.height}, cs};
      upsample_region(w, fs, Rect{0, 0, fs.width, fs.height}, cur.data(), fs.width, scratch);
    }
    int64_t covered = 0;
    for (const auto& b : p.bands[size_t(l)]) {
      if (b.y0 != covered || b.rows <= 0 || b.y0 + b.rows > fs.height)
        throw Error(ErrorCode::CorruptData, "pyramid: bands of level " + std::to_string(l) + " out of order");
      rhat.resize(size_t(b.rows * fs.width));
      if (!coder.decode(b.bytes.data(), b.bytes.size(), fs.width, b.rows, rhat.data()))
        throw Error(ErrorCode::CorruptData, "pyramid: bad residual band at level " + std::to_string(l) +
                                                ", row " + std::to_string(b.y0));
      int32_t* row = cur.data() + b.y0 * fs.width;
      for (size_t k = 0; k < rhat.size(); ++k)
        row[k] = int32_t(std::clamp<int64_t>(int64_t(row[k]) + rhat[k], std::numeric_limits<int32_t>::min(),
                                             std::numeric_limits<int32_t>::max()));
      covered += b.rows;
    }
    if (covered != fs.height)
      throw Error(ErrorCode::CorruptData, "pyramid: level " + std::to_string(l) + " is incomplete");
    prev.swap(cur);
  }
  if (valid) {
    const GridSize fs = levels[size_t(up_to_level)];
    const bool finest = up_to_level == int(levels.size()) - 1;
    if (finest && !p.mask.empty() && p.mask.size() != size_t(fs.width * fs.height))
      throw Error(ErrorCode::CorruptData, "pyramid: validity mask incomplete");
    if (finest && !p.mask.empty())
      *valid = p.mask;
    else
      valid->assign(size_t(fs.width * fs.height), 1);
  }
  return prev;
}

}  // namespace terrain
