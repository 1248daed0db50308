// Every level of a .pyr decoded whole, in level units (tests that compare files level by level).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "container/pyramid_file.h"
#include "runtime/region_decoder.h"

namespace pyrtest {

// Level 0 (coarsest) first, each row-major at its level's width.
inline std::vector<std::vector<int32_t>> decode_all(const std::string& path) {
  const auto f = terrain::container::PyramidFile::open(path);
  terrain::runtime::RegionDecoder d(f, 0);
  std::vector<std::vector<int32_t>> out;
  for (int l = 0; l < f->level_count(); ++l) {
    const terrain::GridSize s = f->level_size(l);
    out.emplace_back(size_t(s.width * s.height));
    d.decode_units(l, terrain::Rect{0, 0, s.width, s.height}, out.back().data(), s.width);
  }
  return out;
}

}  // namespace pyrtest
