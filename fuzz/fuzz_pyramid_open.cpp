// libFuzzer target for the pyramid file open path: container validation (superblock, index,
// level records, mask runs, metadata), the band tables of every level, PyramidFile::verify, and
// region decoding under both damage policies.
//
// Inputs come from a structure-aware mutator (pyr_mutator.h: one field or a few payload bytes of
// a located section, every checksum recomputed). Each input is tried as given and, when that
// differs, with every checksum recomputed (band streams, band tables, blobs, mask, metadata,
// index, superblock; tests/runtime/pyr_test_util.h) so that mutations reach the validation and the
// libcodec streams behind the CRCs. Any Error is fine under DamagePolicy::Throw; crashes,
// sanitizer reports, leaks, other exception types, and any Error from a decode under
// DamagePolicy::Degrade are not. When a file opens, small regions of every level are decoded
// (units and metres; whole levels of 128x128 and more through the bulk path): a decode of a
// sub-rectangle must agree with the larger one, a degraded decode
// with a strict one that succeeded, and every damage report must lie inside its level and the file.
//   Run: fuzz_pyramid_open -max_len=65536 -max_total_time=600 [corpus_dir]
//   Seeds: scripts/fuzz-seeds DIR (small pyramids covering every container section)
#include <algorithm>
#include <cstring>
#include <filesystem>
#include <vector>

#include "container/container.h"
#include "container/pyramid_file.h"
#include "fuzz_io_common.h"
#include "pyr_mutator.h"
#include "runtime/pyr_test_util.h"
#include "runtime/region_decoder.h"

namespace {

void decode_some(const std::string& path) {
  using namespace terrain::runtime;
  using namespace terrain::container;
  using terrain::Error;
  using terrain::ErrorCode;
  std::shared_ptr<const PyramidFile> file;
  try {
    file = PyramidFile::open(path);
  } catch (const Error&) {
    return;
  }
  try {
    (void)file->container().mask();
    file->verify();
  } catch (const Error&) {
  }
  RegionDecoder decoder(file, size_t(4) << 20);
  const RegionDecoder degraded(file, size_t(4) << 20, DamagePolicy::Degrade);
  std::vector<int32_t> big(48 * 48), small(16 * 16), shown(48 * 48);
  std::vector<float> metres(48 * 48);
  for (int level = 0; level < file->level_count(); ++level) {
    const terrain::GridSize g = file->level_size(level);
    const int64_t w = std::min<int64_t>(g.width, 48), h = std::min<int64_t>(g.height, 48);
    const terrain::Rect r{(g.width - w) / 2, (g.height - h) / 2, w, h};
    // Degrade never throws Error: damage is left out and reported.
    degraded.decode_units(level, r, shown.data(), w);
    try {
      decoder.decode_units(level, r, big.data(), w);
    } catch (const Error&) {
      continue;
    }
    if (!std::equal(big.begin(), big.begin() + w * h, shown.begin())) std::abort();
    // A nested rectangle, decoded without the cache, must give the same samples.
    const int64_t sw = std::min<int64_t>(w, 16), sh = std::min<int64_t>(h, 16);
    const terrain::Rect s{r.x0 + (w - sw) / 2, r.y0 + (h - sh) / 2, sw, sh};
    RegionDecoder uncached(file, 0);
    uncached.decode_units(level, s, small.data(), sw);
    for (int64_t y = 0; y < sh; ++y)
      for (int64_t x = 0; x < sw; ++x)
        if (small[size_t(y * sw + x)] != big[size_t((s.y0 - r.y0 + y) * w + s.x0 - r.x0 + x)]) std::abort();
    if (level + 1 == file->level_count()) decoder.decode_metres(level, r, metres.data(), w);
    // Whole levels of at least 128x128 take the region decoder's bulk path (tiles added straight
    // into the output, not cached): it must give the window's samples too, or throw Error.
    if (g.width >= 128 && g.height >= 128 && g.width * g.height <= (int64_t(1) << 18)) {
      std::vector<int32_t> whole(size_t(g.width * g.height));
      RegionDecoder bulk(file, size_t(4) << 20);
      try {
        bulk.decode_units(level, terrain::Rect{0, 0, g.width, g.height}, whole.data(), g.width);
      } catch (const Error&) {
        continue;
      }
      for (int64_t y = 0; y < h; ++y)
        for (int64_t x = 0; x < w; ++x)
          if (whole[size_t((r.y0 + y) * g.width + r.x0 + x)] != big[size_t(y * w + x)]) std::abort();
    }
  }
  const uint64_t file_size = uint64_t(std::filesystem::file_size(path));
  for (const DamagedTile& d : degraded.damaged_tiles()) {
    const terrain::GridSize g = file->level_size(d.level);
    if (d.area.x0 < 0 || d.area.y0 < 0 || d.area.width < 1 || d.area.height < 1 ||
        d.area.x0 + d.area.width > g.width || d.area.y0 + d.area.height > g.height ||
        d.file_offset > file_size || d.bytes > file_size - d.file_offset || d.message.empty())
      std::abort();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = fuzz_io::write_file("input.pyr", data, size);
  decode_some(path);
  std::vector<uint8_t> copy(data, data + size);
  pyrtest::reseal_all(copy);
  if (size > 0 && std::memcmp(copy.data(), data, size) != 0) {
    fuzz_io::write_file("input.pyr", copy.data(), copy.size());
    decode_some(path);
  }
  fuzz_io::remove_file("input.pyr");
  return 0;
}

extern "C" size_t LLVMFuzzerCustomMutator(uint8_t* data, size_t size, size_t max_size, unsigned int seed) {
  return pyr_mutator::mutate(data, size, max_size, seed);
}
