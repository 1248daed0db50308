// Compaction: the current version of an edited file rewritten as pyramid-build lays a file out (each
// level's streams back to back before a BND2 band table), so no dead bytes remain. The streams are
// copied, not re-coded: the result decodes identically. What is copied is checked first: the new
// file gets fresh level blob CRCs, so a damaged stream copied verbatim would lose the blob CRC that
// caught it (only the stream's own CRCs would remain), and compaction is not a repair.
#include <algorithm>
#include <string>

#include "container/container.h"
#include "container/pyramid_file.h"
#include "core/error.h"
#include "edit/pyramid_edit.h"

namespace terrain::edit {

CompactStats compact(const std::string& path) {
  CompactStats stats;
  {
    const auto f = container::PyramidFile::open(path);
    const container::Container& c = f->container();
    // Every checksum over the bytes copied below, without decoding (an edited file's streams may lie
    // in earlier generations' blobs, which no blob CRC covers any more).
    try {
      f->verify(container::PyramidFile::VerifyDepth::Checksums);
    } catch (const Error& e) {
      throw Error(e.code(), std::string(e.what()) + " (cannot compact a damaged file)");
    }
    stats.bytes_before = c.committed_size() + c.uncommitted_bytes();
    container::ContainerWriter w(path);
    w.set_info(c.info());
    for (int l = 0; l < f->level_count(); ++l) {
      std::vector<container::BandMapRecord> records;
      for (const container::BandView& v : f->bands(l)) {
        if (!v.empty()) w.append_level(uint32_t(l), v.data, v.size);
        records.push_back({uint64_t(v.rows), 1, 0, v.size});
      }
      const std::vector<uint8_t> table = container::encode_band_table(records);
      w.append_level(uint32_t(l), table.data(), table.size());
      w.end_level(uint32_t(l));
    }
    if (c.info().void_count > 0) {
      const uint64_t width = c.info().width, rows_per = std::max<uint64_t>(1, (uint64_t(1) << 22) / width);
      std::vector<uint8_t> valid;
      for (uint64_t y = 0; y < c.info().height; y += rows_per) {
        const uint64_t rows = std::min(rows_per, c.info().height - y);
        valid.resize(size_t(rows * width));
        c.mask_rows(y, rows, valid.data());
        w.append_mask(valid.data(), valid.size());
      }
    }
    w.set_metadata_json(std::string(c.metadata_json()));
    w.finish();  // renames over `path`; the open mapping keeps the old inode until f goes
  }
  stats.bytes_after = container::Container::open(path).committed_size();
  return stats;
}

}  // namespace terrain::edit
