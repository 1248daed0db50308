// Level blobs as band tables: writer side (a PyramidSink over ContainerWriter) and reader side.
//
// Level blob layout (container format 2, little endian; docs/format.md "Level blobs"):
//   band streams, back to back (an all-zero band has none)
//   band table: records of varint rows, varint code: code = size << 1 for a band with a stream of
//               `size` bytes, (n - 1) << 1 | 1 for n consecutive all-zero bands of `rows` rows each
//   footer:     u32 table size, u32 magic "BND2", u32 CRC-32C of the band table
// The table sits at the end because bands arrive one by one while the blob is being streamed.
#include "container/pyramid_file.h"

#include <algorithm>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "codec/codec.h"
#include "core/bytes.h"

namespace terrain::container {
namespace {

using bytes::get_u32;
using bytes::put_u32;

constexpr uint32_t kBandMagic = kBandTableMagic;
constexpr size_t kFooterSize = 12;

// Table records then the footer (u32 table size, u32 magic, u32 CRC-32C of the table). A record is
// varint rows, varint code: size << 1 for one band with a stream (a band map follows it with the
// varint file offset), (k - 1) << 1 | 1 for k consecutive all-zero bands of `rows` rows each.
std::vector<uint8_t> encode_table(const std::vector<BandMapRecord>& records, bool with_offsets) {
  std::vector<uint8_t> table;
  for (const BandMapRecord& r : records) {
    bytes::put_varint(table, r.rows);
    bytes::put_varint(table, r.size ? r.size << 1 : ((r.run - 1) << 1) | 1);
    if (r.size && with_offsets) bytes::put_varint(table, r.offset);
  }
  const size_t table_bytes = table.size();
  table.resize(table_bytes + kFooterSize);
  put_u32(table.data() + table_bytes, uint32_t(table_bytes));
  put_u32(table.data() + table_bytes + 4, with_offsets ? kBandMapMagic : kBandMagic);
  put_u32(table.data() + table_bytes + 8, crc32c(table.data(), table_bytes));
  return table;
}

}  // namespace

PyramidFileWriter::PyramidFileWriter(const std::string& path) : writer_(path) {}
PyramidFileWriter::~PyramidFileWriter() = default;

void PyramidFileWriter::begin(const PyramidHeader& header) {
  header_ = header;
  levels_.assign(header.levels.size(), {});
  next_mask_row_ = 0;
}

void PyramidFileWriter::close_level(int level) {
  LevelBands& lb = levels_[size_t(level)];
  std::vector<BandMapRecord> records;
  for (const BandRecord& b : lb.bands) {
    // A run of all-zero bands of the same height is one record.
    if (b.size == 0 && !records.empty() && records.back().size == 0 && records.back().rows == b.rows)
      ++records.back().run;
    else
      records.push_back({b.rows, 1, 0, b.size});
  }
  const std::vector<uint8_t> table = encode_table(records, false);
  writer_.append_level(uint32_t(level), table.data(), table.size());
  writer_.end_level(uint32_t(level));
  bytes_ += table.size();
  std::vector<BandRecord>().swap(lb.bands);
}

std::vector<uint8_t> encode_band_map(const std::vector<BandMapRecord>& records) {
  return encode_table(records, true);
}
std::vector<uint8_t> encode_band_table(const std::vector<BandMapRecord>& records) {
  return encode_table(records, false);
}

void PyramidFileWriter::band(int level, int64_t y0, int64_t rows, std::vector<uint8_t>&& bytes) {
  if (level < 0 || size_t(level) >= levels_.size())
    throw std::logic_error("pyramid writer: band of level " + std::to_string(level) +
                           (levels_.empty() ? " before begin()" : ", which the header does not have"));
  LevelBands& lb = levels_[size_t(level)];
  const int64_t height = header_.levels[size_t(level)].height;
  if (y0 != lb.next_row || rows < 1 || rows > height - y0)
    throw std::logic_error("pyramid writer: level " + std::to_string(level) + " band at row " +
                           std::to_string(y0) + " out of order (next row " + std::to_string(lb.next_row) +
                           ")");
  lb.bands.push_back({bytes.size(), uint64_t(rows)});
  if (!bytes.empty()) writer_.append_level(uint32_t(level), bytes.data(), bytes.size());
  bytes_ += bytes.size();
  lb.next_row = y0 + rows;
  if (lb.next_row == height) close_level(level);
}

uint64_t PyramidFileWriter::place_level(int level, const std::vector<PlacedBand>& bands) {
  if (level < 0 || size_t(level) >= levels_.size())
    throw std::logic_error("pyramid writer: placed level " + std::to_string(level) +
                           (levels_.empty() ? " before begin()" : ", which the header does not have"));
  LevelBands& lb = levels_[size_t(level)];
  const int64_t height = header_.levels[size_t(level)].height;
  uint64_t size = 0;
  int64_t rows = 0;
  for (const PlacedBand& b : bands) {
    if (b.rows < 1 || b.rows > height - rows)
      throw std::logic_error("pyramid writer: placed level " + std::to_string(level) +
                             " has bands beyond row " + std::to_string(height));
    rows += b.rows;
    size += b.size;
  }
  if (lb.next_row != 0 || rows != height)
    throw std::logic_error("pyramid writer: placed level " + std::to_string(level) + " covers " +
                           std::to_string(rows) + " of " + std::to_string(height) + " rows");
  const uint64_t offset = writer_.reserve_level(uint32_t(level), size);
  for (const PlacedBand& b : bands) lb.bands.push_back({b.size, uint64_t(b.rows)});
  lb.next_row = height;
  bytes_ += size;
  close_level(level);
  return offset;
}

void PyramidFileWriter::mask_rows(int64_t y0, int64_t rows, const uint8_t* valid) {
  if (y0 != next_mask_row_ || header_.levels.empty())
    throw std::logic_error("pyramid writer: mask rows at " + std::to_string(y0) + " out of order");
  writer_.append_mask(valid, size_t(rows * header_.levels.back().width));
  next_mask_row_ = y0 + rows;
}

void PyramidFileWriter::finish(const BuildResult& result, ContainerInfo info,
                               const std::string& metadata_json) {
  const auto& levels = result.header.levels;
  info.width = uint64_t(levels.back().width);
  info.height = uint64_t(levels.back().height);
  info.levels.clear();
  for (size_t l = 0; l < levels.size(); ++l) {
    LevelInfo li;
    li.width = uint64_t(levels[l].width);
    li.height = uint64_t(levels[l].height);
    const LevelBuildStats& s = result.levels[l];
    // The builder measures residuals about zero: rms and the largest magnitude.
    li.stats.rms = s.residual_rms;
    li.stats.variance = s.residual_rms * s.residual_rms;
    li.stats.min = -double(s.residual_max_abs);
    li.stats.max = double(s.residual_max_abs);
    li.error = LevelError{s.error_rms, double(s.error_max_abs)};
    info.levels.push_back(li);
  }
  // The default filter the builder fell back to and the wavelet D are implied by the provenance, so
  // they are not stored (968 bytes: a third of a constant 4096^2 grid's file).
  const DownsampleFilter& f = result.header.filter;
  const bool wavelet = f.is_wavelet(), point = f.is_point();
  const bool implied = result.filter_report.fallback || wavelet || point;
  info.filter_size = implied ? 0 : DownsampleFilter::kSize;
  if (!implied) info.filter.assign(f.taps.begin(), f.taps.end());
  info.filter_provenance = wavelet                         ? FilterProvenance::Wavelet
                           : point                         ? FilterProvenance::Point
                           : result.filter_report.fallback ? FilterProvenance::Fallback
                                                           : FilterProvenance::Optimal;
  writer_.set_info(info);
  writer_.set_metadata_json(metadata_json);
  writer_.finish();
}

namespace {

// Both table kinds. A band map (file non-null) reads each stream's file offset from its record and
// finds the bytes through the container; a BND2 table's streams fill the blob before the table.
std::vector<BandView> parse_table(const uint8_t* blob, size_t size, int64_t level_height,
                                  const std::string& what, const Container* file) {
  auto corrupt = [&](const std::string& why) { return Error(ErrorCode::CorruptData, what + ": " + why); };
  if (size < kFooterSize) throw corrupt("level blob too small for its band table");
  const uint8_t* footer = blob + size - kFooterSize;
  const uint32_t magic = get_u32(footer + 4);
  if (magic != kBandMagic && !(file && magic == kBandMapMagic)) throw corrupt("band table magic missing");
  const bool map = magic == kBandMapMagic;
  const uint32_t table_bytes = get_u32(footer);
  if (table_bytes > size - kFooterSize)
    throw corrupt("band table size " + std::to_string(table_bytes) + " too large");
  const uint8_t* table = footer - table_bytes;
  if (crc32c(table, table_bytes) != get_u32(footer + 8))
    throw Error(ErrorCode::ChecksumMismatch, what + ": band table checksum mismatch");
  const uint64_t data_end = uint64_t(table - blob);
  // One view per record: a run of all-zero bands is one view (no stream to find), so the views'
  // memory is bounded by the table's size.
  const uint8_t* p = table;
  std::vector<BandView> out;
  uint64_t next_row = 0, offset = 0;
  for (size_t i = 0; p != footer; ++i) {
    uint64_t rows = 0, code = 0, at = 0;
    if (!bytes::get_varint(p, footer, &rows) || !bytes::get_varint(p, footer, &code) ||
        (map && !(code & 1) && !bytes::get_varint(p, footer, &at)))
      throw corrupt("band table ends inside record " + std::to_string(i));
    const uint64_t left = uint64_t(level_height) - next_row;
    const uint64_t run = code & 1 ? (code >> 1) + 1 : 1, sz = code & 1 ? 0 : code >> 1;
    if (rows == 0 || rows > left || run > left / rows)
      throw corrupt("band record " + std::to_string(i) + " rows do not tile the level");
    const uint8_t* data = nullptr;
    if (!(code & 1) && map) {
      data = sz == 0 ? nullptr : file->file_bytes(at, sz);
      if (!data || at < 64) throw corrupt("band record " + std::to_string(i) + " lies outside the file");
      // Streams of one level never share bytes (each is one band's, written once).
      if (!out.empty() && out.back().data && data < out.back().data + out.back().size &&
          data + sz > out.back().data)
        throw corrupt("band record " + std::to_string(i) + " overlaps the band before it");
    } else if (!(code & 1)) {
      if (sz == 0 || sz > data_end - offset)
        throw corrupt("band record " + std::to_string(i) + " lies outside the blob");
      data = blob + offset;
      offset += sz;
    }
    out.push_back(BandView{int64_t(next_row), int64_t(rows * run), data, size_t(sz)});
    next_row += rows * run;
  }
  if (out.empty()) throw corrupt("band table is empty");
  if (!map && offset != data_end) throw corrupt("band streams do not fill the blob");
  if (next_row != uint64_t(level_height)) throw corrupt("bands do not cover the level");
  return out;
}

}  // namespace

std::vector<BandView> parse_band_table(const uint8_t* blob, size_t size, int64_t level_height,
                                       const std::string& what) {
  return parse_table(blob, size, level_height, what, nullptr);
}

std::shared_ptr<const PyramidFile> PyramidFile::open(const std::string& path) {
  std::shared_ptr<PyramidFile> f(new PyramidFile(Container::open(path)));
  const int n = f->level_count();
  f->bands_.resize(size_t(n));
  for (int l = 0; l < n; ++l) {
    const LevelView v = f->container_.level(uint32_t(l));
    f->bands_[size_t(l)] =
        parse_table(v.data, v.size, int64_t(v.height), path + ": level " + std::to_string(l),
                    f->container_.edited() ? &f->container_ : nullptr);
  }
  for (int l = 0; l < n; ++l) {
    const LevelView v = f->container_.level(uint32_t(l));
    uint64_t bytes = kFooterSize + get_u32(v.data + v.size - kFooterSize);  // parse_table checked it
    for (const BandView& b : f->bands_[size_t(l)]) bytes += b.size;
    f->level_bytes_.push_back(bytes);
  }
  f->live_bytes_ = f->count_live_bytes();
  return f;
}

void PyramidFile::verify(VerifyDepth checks) const {
  container_.verify();
  codec::Scratch scratch;
  std::vector<int32_t> row;
  for (int l = 0; l < level_count(); ++l) {
    const auto& views = bands(l);
    for (size_t b = 0; b < views.size(); ++b) {
      const BandView& v = views[b];
      if (v.empty()) continue;
      const uint64_t offset = container_.offset_of(v.data);
      const std::string what = path() + ": level " + std::to_string(l) + ", band record " +
                               std::to_string(b) + " (rows " + std::to_string(v.y0) + ".." +
                               std::to_string(v.y0 + v.rows - 1) + ", stream of " + std::to_string(v.size) +
                               " bytes at file offset " + std::to_string(offset) + ")";
      const auto fail = [&](codec::Status s, const std::string& why) {
        return Error(
            s == codec::Status::ChecksumMismatch ? ErrorCode::ChecksumMismatch : ErrorCode::CorruptData,
            what + ": " + why + ": " + codec::status_name(s));
      };
      codec::Decoder d;
      if (const codec::Status s = d.open(v.data, v.size); s != codec::Status::Ok)
        throw fail(
            s,
            "the stream does not open (its size in the band table, or its header or tile index, is wrong)");
      const codec::HeaderInfo& h = d.header();
      if (h.width != level_size(l).width)
        throw Error(ErrorCode::CorruptData, what + ": the stream codes width " + std::to_string(h.width) +
                                                ", the level is " + std::to_string(level_size(l).width) +
                                                " wide");
      if (h.height != v.rows)
        throw Error(ErrorCode::CorruptData, what + ": band table rows " + std::to_string(v.rows) +
                                                ", but the stream codes " + std::to_string(h.height) +
                                                " rows");
      if (checks == VerifyDepth::Checksums) {
        std::vector<codec::TileEntry> entries;
        std::vector<codec::RowChecksum> rows;
        if (const codec::Status s = codec::read_tile_index(v.data, v.size, h, &entries, &rows);
            s != codec::Status::Ok)
          throw fail(s, "the stream's tile index does not read");
        // A stream of one tile row has no row CRC: the stream CRC (checked by open) covered it.
        for (const codec::RowChecksum& r : rows)
          if (h.tiles_y > 1 && codec::crc32c(v.data + r.offset, size_t(r.size)) != r.crc)
            throw fail(codec::Status::ChecksumMismatch, "tile row " + std::to_string(r.tile_row));
        continue;
      }
      row.resize(size_t(h.width) * h.tile_size);
      for (int64_t ty = 0; ty < h.tiles_y; ++ty) {
        const int64_t rows = std::min<int64_t>(h.tile_size, h.height - ty * h.tile_size);
        const codec::Status s =
            d.decode_region(codec::Rect{0, ty * h.tile_size, h.width, rows}, row.data(), h.width, scratch);
        if (s != codec::Status::Ok) throw fail(s, "tile row " + std::to_string(ty));
      }
    }
  }
}

uint64_t PyramidFile::count_live_bytes() const {
  // Union of the live ranges: band maps may point into earlier generations' blobs.
  const ContainerInfo& i = info();
  std::vector<std::pair<uint64_t, uint64_t>> ranges;  // [begin, end)
  const uint64_t committed = container_.committed_size();
  ranges.push_back({0, 64});
  if (container_.edited()) ranges.push_back({committed - 64, committed});
  for (int l = 0; l < level_count(); ++l) {
    const LevelInfo& li = i.levels[size_t(l)];
    ranges.push_back({li.blob_offset, li.blob_offset + li.blob_size});
    for (const BandView& v : bands(l))
      if (v.data) ranges.push_back({container_.offset_of(v.data), container_.offset_of(v.data) + v.size});
  }
  ranges.push_back(
      {container_.metadata_offset(), container_.metadata_offset() + container_.metadata_json().size()});
  if (const auto m = container_.mask_bytes(); m > 0)
    ranges.push_back({container_.mask_offset(), container_.mask_offset() + m});
  ranges.push_back({container_.index_offset(), container_.index_offset() + container_.index_size()});
  std::sort(ranges.begin(), ranges.end());
  uint64_t live = 0, end = 0;
  for (const auto& [b, e] : ranges) {
    if (e <= end) continue;
    live += e - std::max(b, end);
    end = e;
  }
  if (!container_.edited()) return committed;  // padding between regions counts as live: nothing to drop
  return live;
}

GridSize PyramidFile::level_size(int level) const {
  const LevelInfo& li = info().levels.at(size_t(level));
  return GridSize{int64_t(li.width), int64_t(li.height)};
}

DownsampleFilter PyramidFile::downsample_filter() const {
  const ContainerInfo& i = info();
  if (i.filter_size != DownsampleFilter::kSize)
    return i.filter_provenance == FilterProvenance::Wavelet ? DownsampleFilter::wavelet()
           : i.filter_provenance == FilterProvenance::Point ? DownsampleFilter::impulse()
                                                            : DownsampleFilter::default_filter();
  DownsampleFilter f;
  f.kind = DownsampleFilter::Kind::Custom;
  std::copy(i.filter.begin(), i.filter.end(), f.taps.begin());
  return f;
}

size_t PyramidFile::band_of_row(int level, int64_t y) const {
  const auto& b = bands(level);
  size_t lo = 0, hi = b.size();
  while (hi - lo > 1) {
    const size_t mid = (lo + hi) / 2;
    (b[mid].y0 <= y ? lo : hi) = mid;
  }
  return lo;
}

}  // namespace terrain::container
