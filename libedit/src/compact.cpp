// Compaction: the current version of an edited file rewritten as pyramid-build lays a file out (each
// level's streams back to back before a BND2 band table), so no dead bytes remain. The streams are
// copied, not re-coded: the result decodes identically. What is copied is checked first: the new
// file gets fresh level blob CRCs, so a damaged stream copied verbatim would lose the blob CRC that
// caught it (only the stream's own CRCs would remain), and compaction is not a repair.
#include <algorithm>
#include <string>

#include "codec/codec.h"
#include "container/container.h"
#include "container/pyramid_file.h"
#include "core/error.h"
#include "edit/pyramid_edit.h"

namespace terrain::edit {
namespace {

// Every checksum that covers the bytes compaction copies, without decoding: the level blobs' CRCs
// (a 2.1 blob holds its level's streams) and, per band stream (an edited file's streams may lie in
// earlier generations' blobs, covered by no blob CRC), its libcodec header, index and tile-row CRCs,
// the level's width and the record's rows. Throws Error(ChecksumMismatch) for a CRC, else
// Error(CorruptData), naming the file, level and band record (as PyramidFile::verify).
void check_copied_bytes(const container::PyramidFile& f) {
  f.container().verify();
  for (int l = 0; l < f.level_count(); ++l) {
    const auto& views = f.bands(l);
    for (size_t b = 0; b < views.size(); ++b) {
      const container::BandView& v = views[b];
      if (v.empty()) continue;
      const std::string what = f.path() + ": level " + std::to_string(l) + ", band record " +
                               std::to_string(b) + " (rows " + std::to_string(v.y0) + ".." +
                               std::to_string(v.y0 + v.rows - 1) + ", stream of " + std::to_string(v.size) +
                               " bytes at file offset " + std::to_string(f.container().offset_of(v.data)) +
                               "): cannot compact: ";
      const auto fail = [&](codec::Status s, const std::string& why) {
        return Error(
            s == codec::Status::ChecksumMismatch ? ErrorCode::ChecksumMismatch : ErrorCode::CorruptData,
            what + why + ": " + codec::status_name(s));
      };
      codec::HeaderInfo h;
      std::vector<codec::TileEntry> entries;
      std::vector<codec::RowChecksum> rows;
      codec::Status s = codec::read_header(v.data, v.size, &h);
      if (s == codec::Status::Ok) s = codec::read_tile_index(v.data, v.size, h, &entries, &rows);
      if (s != codec::Status::Ok) throw fail(s, "the stream does not open");
      if (h.width != f.level_size(l).width || h.height != v.rows)
        throw Error(ErrorCode::CorruptData, what + "the stream codes " + std::to_string(h.width) + "x" +
                                                std::to_string(h.height) + " samples, the band is " +
                                                std::to_string(f.level_size(l).width) + "x" +
                                                std::to_string(v.rows));
      // A stream of one tile row has no row CRC: read_header's stream CRC covered its payloads.
      for (const codec::RowChecksum& r : rows)
        if (h.tiles_y > 1 && codec::crc32c(v.data + r.offset, size_t(r.size)) != r.crc)
          throw fail(codec::Status::ChecksumMismatch, "tile row " + std::to_string(r.tile_row));
    }
  }
}

}  // namespace

CompactStats compact(const std::string& path) {
  CompactStats stats;
  {
    const auto f = container::PyramidFile::open(path);
    const container::Container& c = f->container();
    check_copied_bytes(*f);
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
