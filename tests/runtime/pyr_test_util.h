// Byte-level editing of .pyr files for tests (and the fuzz target's mutator) that forge fields:
// little-endian access, locating every level blob, band table and libcodec stream, and resealing
// every checksum after an edit (the layouts are restated from docs/format.md and docs/codec.md on
// purpose, so that the reader under test is not its own reference). Nothing here throws or reads
// out of bounds on any bytes: what cannot be located is left as it is.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "codec/codec.h"
#include "codec/crc32c.h"

namespace pyrtest {

inline uint64_t get_le(const std::vector<uint8_t>& b, size_t at, int bytes) {
  uint64_t v = 0;
  for (int i = bytes - 1; i >= 0; --i) v = v << 8 | b[at + size_t(i)];
  return v;
}
inline void put_le(std::vector<uint8_t>& b, size_t at, uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) b[at + size_t(i)] = uint8_t(v >> (8 * i));
}
inline void put_f64(std::vector<uint8_t>& b, size_t at, double v) {
  uint64_t u;
  std::memcpy(&u, &v, 8);
  put_le(b, at, u, 8);
}

// Superblock field offsets from docs/format.md.
constexpr size_t kSbMajor = 8, kSbMinor = 10, kSbFileSize = 16, kSbIndexOffset = 24, kSbIndexSize = 32,
                 kSbIndexCrc = 40, kSbCrc = 60;

// Makes the index and superblock checksums match the (edited) bytes again, where the superblock
// still locates the index inside the file.
inline void reseal(std::vector<uint8_t>& b) {
  const uint64_t offset = get_le(b, kSbIndexOffset, 8), size = get_le(b, kSbIndexSize, 8);
  if (offset <= b.size() && size <= b.size() - offset)
    put_le(b, kSbIndexCrc, codec::crc32c(b.data() + offset, size_t(size)), 4);
  put_le(b, kSbCrc, codec::crc32c(b.data(), kSbCrc), 4);
}

// Index fields (offsets within the info block and a level record) from docs/format.md.
constexpr size_t kInfoSize = 0, kInfoLevelCount = 4, kInfoRecordSize = 8, kInfoMaskOffset = 216,
                 kInfoMaskSize = 224, kInfoMaskCrc = 240, kInfoMetadataCrc = 244, kInfoMetadataOffset = 248,
                 kInfoMetadataSize = 256, kInfoBlock = 320;  // 2.1 (264 in 2.0)
constexpr size_t kRecBlobOffset = 16, kRecBlobSize = 24, kRecBlobCrc = 32, kRecFlags = 36, kRecMin = 40;
constexpr size_t kBandFooter = 12;  // u32 table size, "BND2", u32 CRC-32C of the table

inline bool inside(uint64_t offset, uint64_t size, size_t file_size) {
  return offset <= file_size && size <= file_size - offset;
}

// An unsigned LEB128 varint of at most 10 bytes at p (< end); false when it does not fit.
inline bool read_varint(const uint8_t*& p, const uint8_t* end, uint64_t* v) {
  *v = 0;
  for (int shift = 0; p < end && shift < 70; shift += 7) {
    const uint8_t byte = *p++;
    *v |= shift < 64 ? uint64_t(byte & 0x7f) << shift : 0;
    if (!(byte & 0x80)) return true;
  }
  return false;
}

// One band stream (a libcodec stream) and the parts of it a mutator aims at, as file offsets.
struct StreamAt {
  size_t offset = 0, size = 0;
  size_t header_end = 0;   // D: the payloads start here
  size_t index_begin = 0;  // X = D + P: the tile index starts here
  uint64_t width = 0, height = 0, tile = 0;
  bool parsed = false;  // header and index located (else only offset and size are known)
};
// One level: its record in the index, its blob, band table and streams.
struct LevelAt {
  size_t record = 0;  // file offset of the level record
  size_t blob = 0, blob_size = 0;
  size_t table = 0, table_size = 0;  // the band table's records (the footer follows)
  bool has_table = false;
  std::vector<StreamAt> streams;
};

// Locates a libcodec stream's header and index (docs/codec.md, "Container").
inline StreamAt locate_stream(const std::vector<uint8_t>& b, size_t offset, size_t size) {
  StreamAt s;
  s.offset = offset;
  s.size = size;
  const uint8_t *p = b.data() + offset, *end = p + size;
  if (size < 10 || std::memcmp(p, "TPTC", 4) != 0) return s;
  // libcodec's own parser where the header reads (format 7's phase model lies between E and P);
  // the plain varints of formats 4-5 otherwise, for streams whose header was forged.
  codec::HeaderInfo h;
  if (codec::read_header(p, size, &h) == codec::Status::Ok) {
    s.width = uint64_t(h.width);
    s.height = uint64_t(h.height);
    s.tile = h.tile_size;
    s.header_end = offset + h.data_offset;
    s.index_begin = offset + h.index_offset;
    s.parsed = true;
    return s;
  }
  p += 6;
  uint64_t tile16, flags, step, e = 0, payload;
  if (!read_varint(p, end, &s.width) || !read_varint(p, end, &s.height) || !read_varint(p, end, &tile16) ||
      !read_varint(p, end, &flags) || !read_varint(p, end, &step))
    return s;
  if ((flags & 1) && !read_varint(p, end, &e)) return s;
  if (!read_varint(p, end, &payload)) return s;
  s.header_end = size_t(p - b.data());
  if (payload > uint64_t(end - p) || s.width == 0 || s.height == 0 || tile16 == 0 || tile16 > 64 ||
      s.width > (uint64_t(1) << 40) || s.height > (uint64_t(1) << 40))
    return s;
  s.tile = tile16 * 16;
  s.index_begin = s.header_end + size_t(payload);
  s.parsed = true;
  return s;
}

// Every level blob, band table and band stream that the index and the tables locate.
inline std::vector<LevelAt> locate_levels(const std::vector<uint8_t>& b) {
  std::vector<LevelAt> out;
  if (b.size() < 64) return out;
  const uint64_t index = get_le(b, kSbIndexOffset, 8), index_size = get_le(b, kSbIndexSize, 8);
  if (!inside(index, index_size, b.size()) || index_size < kInfoBlock) return out;
  const uint64_t info_size = get_le(b, size_t(index) + kInfoSize, 4);
  const uint64_t levels = std::min<uint64_t>(get_le(b, size_t(index) + kInfoLevelCount, 4), 64);
  const uint64_t record_size = get_le(b, size_t(index) + kInfoRecordSize, 4);
  for (uint64_t l = 0; l < levels && record_size >= kRecMin; ++l) {
    const uint64_t r = info_size + l * record_size;
    if (r > index_size || record_size > index_size - r) break;
    LevelAt lv;
    lv.record = size_t(index + r);
    const uint64_t blob = get_le(b, lv.record + kRecBlobOffset, 8),
                   size = get_le(b, lv.record + kRecBlobSize, 8);
    if (!inside(blob, size, b.size())) {
      out.push_back(lv);
      continue;
    }
    lv.blob = size_t(blob);
    lv.blob_size = size_t(size);
    if (size >= kBandFooter && std::memcmp(b.data() + blob + size - 8, "BND2", 4) == 0) {
      const uint64_t table_size = get_le(b, size_t(blob + size - kBandFooter), 4);
      if (table_size <= size - kBandFooter) {
        lv.has_table = true;
        lv.table = size_t(blob + size - kBandFooter - table_size);
        lv.table_size = size_t(table_size);
        // Records: varint rows, varint code (size << 1, or a run of all-zero bands with bit 0 set).
        const uint8_t *p = b.data() + lv.table, *end = p + table_size;
        uint64_t at = blob;
        while (p < end) {
          uint64_t rows, code;
          if (!read_varint(p, end, &rows) || !read_varint(p, end, &code)) break;
          if (code & 1) continue;
          const uint64_t stream = code >> 1;
          if (stream > lv.table - at) break;
          lv.streams.push_back(locate_stream(b, size_t(at), size_t(stream)));
          at += stream;
        }
      }
    }
    out.push_back(lv);
  }
  return out;
}

// Recomputes a stream's row CRCs and its stream CRC (docs/codec.md: one CRC-32C per tile row with
// payload after the index records, none when there is one tile row; the stream CRC over header and
// index, or over everything before it when there is one tile row).
inline void reseal_stream(std::vector<uint8_t>& b, const StreamAt& s) {
  if (!s.parsed || s.size < 4) return;
  const uint64_t tiles_x = (s.width + s.tile - 1) / s.tile, tiles_y = (s.height + s.tile - 1) / s.tile;
  const size_t crc_at = s.offset + s.size - 4;
  if (tiles_y == 1) {
    put_le(b, crc_at, codec::crc32c(b.data() + s.offset, s.size - 4), 4);
    return;
  }
  if (s.index_begin > crc_at) return;
  // The index records: payload bytes per tile row.
  const uint8_t* q = b.data() + s.index_begin;
  const uint8_t* const index_end = b.data() + crc_at;
  struct Row {
    uint64_t tile_row, start, bytes;  // payload offset of the row's first byte, and its length
  };
  std::vector<Row> rows;  // the rows with payload, top to bottom
  uint64_t tile_no = 0, payload_at = 0;
  while (tile_no < tiles_x * tiles_y && q < index_end) {
    uint64_t code;
    if (!read_varint(q, index_end, &code)) return;
    if (code & 1) {
      tile_no += (code >> 1) + 1;
      continue;
    }
    const uint64_t row = tile_no / tiles_x, size = code >> 1;
    if (rows.empty() || rows.back().tile_row != row) rows.push_back(Row{row, payload_at, 0});
    rows.back().bytes += size;
    payload_at += size;
    ++tile_no;
  }
  const size_t crcs = size_t(q - b.data());
  if (crcs + 4 * rows.size() != crc_at) return;  // row CRCs must end at the stream CRC
  for (size_t i = 0; i < rows.size(); ++i)
    if (rows[i].start + rows[i].bytes <= s.index_begin - s.header_end)
      put_le(b, crcs + 4 * i, codec::crc32c(b.data() + s.header_end + rows[i].start, size_t(rows[i].bytes)),
             4);
  const uint32_t head = codec::crc32c(b.data() + s.offset, s.header_end - s.offset);
  put_le(b, crc_at, codec::crc32c(b.data() + s.index_begin, crc_at - s.index_begin, head), 4);
}

// Reseals everything after an edit, innermost first: every band stream's CRCs (unless `streams` is
// false: a forged band table locates the streams wrongly), every band table's CRC, every level
// blob's CRC (where its record says it has one), the mask and metadata CRCs, then the index and
// superblock (reseal).
inline void reseal_all(std::vector<uint8_t>& b, bool streams = true) {
  if (b.size() < 64) return;
  for (const LevelAt& lv : locate_levels(b)) {
    if (streams)
      for (const StreamAt& s : lv.streams) reseal_stream(b, s);
    if (lv.has_table)
      put_le(b, lv.blob + lv.blob_size - 4, codec::crc32c(b.data() + lv.table, lv.table_size), 4);
    if (lv.blob > 0 && (get_le(b, lv.record + kRecFlags, 4) & 1))
      put_le(b, lv.record + kRecBlobCrc, codec::crc32c(b.data() + lv.blob, lv.blob_size), 4);
  }
  const uint64_t index = get_le(b, kSbIndexOffset, 8), index_size = get_le(b, kSbIndexSize, 8);
  if (inside(index, index_size, b.size()) && index_size >= kInfoBlock) {
    const size_t i = size_t(index);
    const uint64_t mask = get_le(b, i + kInfoMaskOffset, 8), mask_size = get_le(b, i + kInfoMaskSize, 8);
    if (inside(mask, mask_size, b.size()))
      put_le(b, i + kInfoMaskCrc, codec::crc32c(b.data() + mask, size_t(mask_size)), 4);
    const uint64_t meta = get_le(b, i + kInfoMetadataOffset, 8),
                   meta_size = get_le(b, i + kInfoMetadataSize, 8);
    if (inside(meta, meta_size, b.size()))
      put_le(b, i + kInfoMetadataCrc, codec::crc32c(b.data() + meta, size_t(meta_size)), 4);
  }
  reseal(b);
}

}  // namespace pyrtest
