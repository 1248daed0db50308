// libFuzzer target for the pyramid file open path: container validation (superblock, index,
// level records, mask runs, metadata), the band tables of every level, and region decoding.
//
// Each input is tried twice: as given (the CRCs must reject almost every mutation), and with
// every container checksum recomputed (superblock, index, mask, metadata, level blobs; layout
// from docs/format.md) so that mutations reach the index validation, the band tables and the
// libcodec streams behind them. Any Error is fine; crashes, sanitizer reports, leaks and
// other exception types are not. When a file opens, small regions of every level are decoded
// (units and metres), and a decode of a sub-rectangle must agree with the larger decode.
//   Run: fuzz_pyramid_open -max_len=65536 -max_total_time=600 [corpus_dir]
#include <algorithm>
#include <cstring>
#include <vector>

#include "container/container.h"
#include "container/pyramid_file.h"
#include "fuzz_io_common.h"
#include "runtime/region_decoder.h"

namespace {

uint32_t get_u32(const uint8_t* p) {
  return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}
uint64_t get_u64(const uint8_t* p) { return uint64_t(get_u32(p)) | uint64_t(get_u32(p + 4)) << 32; }
void put_u32(uint8_t* p, uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = uint8_t(v >> (8 * i));
}
bool in_file(uint64_t offset, uint64_t size, size_t file_size) {
  return offset <= file_size && size <= file_size - offset;
}

void fix_checksums(std::vector<uint8_t>& f) {
  using terrain::container::crc32c;
  if (f.size() < 64) return;
  const uint64_t index_offset = get_u64(f.data() + 24), index_size = get_u64(f.data() + 32);
  if (in_file(index_offset, index_size, f.size()) && index_size >= 264) {
    uint8_t* info = f.data() + index_offset;
    const uint32_t info_size = get_u32(info), levels = get_u32(info + 4), record_size = get_u32(info + 8);
    const uint64_t mask_offset = get_u64(info + 216), mask_size = get_u64(info + 224);
    if (in_file(mask_offset, mask_size, f.size()))
      put_u32(info + 240, crc32c(f.data() + mask_offset, mask_size));
    const uint64_t meta_offset = get_u64(info + 248), meta_size = get_u64(info + 256);
    if (in_file(meta_offset, meta_size, f.size()))
      put_u32(info + 244, crc32c(f.data() + meta_offset, meta_size));
    for (uint64_t l = 0; l < std::min<uint32_t>(levels, 64); ++l) {
      const uint64_t r = uint64_t(info_size) + l * record_size;
      if (record_size < 40 || r + 40 > index_size) break;
      uint8_t* rec = info + r;
      const uint64_t blob_offset = get_u64(rec + 16), blob_size = get_u64(rec + 24);
      if ((get_u32(rec + 36) & 1) && in_file(blob_offset, blob_size, f.size()))
        put_u32(rec + 32, crc32c(f.data() + blob_offset, blob_size));
    }
    put_u32(f.data() + 40, crc32c(info, index_size));
  }
  put_u32(f.data() + 60, crc32c(f.data(), 60));
}

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
    file->container().verify();
  } catch (const Error&) {
  }
  RegionDecoder decoder(file, size_t(4) << 20);
  std::vector<int32_t> big(48 * 48), small(16 * 16);
  std::vector<float> metres(48 * 48);
  for (int level = 0; level < file->level_count(); ++level) {
    const terrain::GridSize g = file->level_size(level);
    const int64_t w = std::min<int64_t>(g.width, 48), h = std::min<int64_t>(g.height, 48);
    const terrain::Rect r{(g.width - w) / 2, (g.height - h) / 2, w, h};
    try {
      decoder.decode_units(level, r, big.data(), w);
    } catch (const Error&) {
      continue;
    }
    // A nested rectangle, decoded without the cache, must give the same samples.
    const int64_t sw = std::min<int64_t>(w, 16), sh = std::min<int64_t>(h, 16);
    const terrain::Rect s{r.x0 + (w - sw) / 2, r.y0 + (h - sh) / 2, sw, sh};
    RegionDecoder uncached(file, 0);
    uncached.decode_units(level, s, small.data(), sw);
    for (int64_t y = 0; y < sh; ++y)
      for (int64_t x = 0; x < sw; ++x)
        if (small[size_t(y * sw + x)] != big[size_t((s.y0 - r.y0 + y) * w + s.x0 - r.x0 + x)]) std::abort();
    if (level + 1 == file->level_count()) decoder.decode_metres(level, r, metres.data(), w);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = fuzz_io::write_file("input.pyr", data, size);
  decode_some(path);
  std::vector<uint8_t> copy(data, data + size);
  fix_checksums(copy);
  if (size > 0 && std::memcmp(copy.data(), data, size) != 0) {
    fuzz_io::write_file("input.pyr", copy.data(), copy.size());
    decode_some(path);
  }
  fuzz_io::remove_file("input.pyr");
  return 0;
}
