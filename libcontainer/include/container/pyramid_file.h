// A compressed pyramid on disk: the container (runtime/container.h) whose level blobs hold a
// level's bands. Each band is one libcodec stream covering rows [y0, y0 + rows) of the level, or
// no stream when its residual is all zero; a band table at the end of the blob locates them
// (docs/format.md, "Level blobs").
//
// PyramidFileWriter is the PyramidSink the builder writes into; PyramidFile opens a finished file
// (mmap, validated) and gives the band streams of each level without copying.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "container/container.h"
#include "pyramid/pyramid.h"

namespace terrain::container {

// Streams the builder's output into a ContainerWriter (temporary file until finish()). Bands may
// arrive with levels interleaved, each level top to bottom; each level's blob is complete once its
// last band arrives, and the ContainerWriter puts the blobs in level order. Not thread-safe.
class PyramidFileWriter final : public PyramidSink {
 public:
  // Throws Error(WriteFailed) if the temporary file cannot be created.
  explicit PyramidFileWriter(const std::string& path);
  ~PyramidFileWriter() override;

  void begin(const PyramidHeader& header) override;
  // Throws std::logic_error for a band before begin(), of an unknown level or out of row order;
  // Error(WriteFailed) when writing fails. No bytes: an all-zero band (ResidualCoder::encode).
  void band(int level, int64_t y0, int64_t rows, std::vector<uint8_t>&& bytes) override;
  // Throws std::logic_error for rows out of order.
  void mask_rows(int64_t y0, int64_t rows, const uint8_t* valid) override;

  // Completes the file: `info` supplies what the builder does not know (quantisation, units,
  // georeference); levels, filter and stats are taken from `result`. Renames onto the target.
  // Throws as ContainerWriter::finish (std::invalid_argument when a level is incomplete).
  void finish(const BuildResult& result, ContainerInfo info, const std::string& metadata_json);
  uint64_t bytes_written() const { return bytes_; }

  // Experimental (the striped build's parallel assembly): level `level` whole, in place of its
  // band() calls: `bands` gives each band's rows and stream size, top to bottom; their streams are
  // written by others (ContainerWriter::reserve_level) consecutively from the returned file offset,
  // and their CRC-32C (the streams concatenated in band order) comes through set_bands_crc before
  // finish(). Levels in order, each once. Throws std::logic_error before begin(), for a level out of
  // order or rows that do not cover the level, Error(WriteFailed) as band().
  struct PlacedBand {
    int64_t rows = 0;
    uint64_t size = 0;  // 0: an all-zero band
  };
  uint64_t place_level(int level, const std::vector<PlacedBand>& bands);
  void set_bands_crc(int level, uint32_t crc) { writer_.set_reserved_crc(uint32_t(level), crc); }
  // The temporary file the output is written to (renamed onto the target by finish()).
  const std::string& temp_path() const { return writer_.temp_path(); }
  // See ContainerWriter::set_level_memory_limit.
  void set_level_memory_limit(size_t bytes) { writer_.set_level_memory_limit(bytes); }

 private:
  struct BandRecord {
    uint64_t size, rows;  // size 0: an all-zero band, no stream
  };
  struct LevelBands {
    std::vector<BandRecord> bands;  // the band table, written after the level's last band
    int64_t next_row = 0;
  };
  void close_level(int level);
  ContainerWriter writer_;
  PyramidHeader header_;
  std::vector<LevelBands> levels_;
  int64_t next_mask_row_ = 0;
  uint64_t bytes_ = 0;
};

// One band of a level. size 0 (data null): an all-zero residual band, stored as its table record only.
struct BandView {
  int64_t y0 = 0, rows = 0;
  const uint8_t* data = nullptr;
  size_t size = 0;
  bool empty() const { return size == 0; }
};

class PyramidFile {
 public:
  // Opens and validates the container and every level's band table; throws Error.
  static std::shared_ptr<const PyramidFile> open(const std::string& path);

  const Container& container() const { return container_; }
  const ContainerInfo& info() const { return container_.info(); }
  int level_count() const { return int(container_.level_count()); }
  GridSize level_size(int level) const;
  // The D filter the builder used: the stored 11x11 taps, or DownsampleFilter::default_filter()
  // when the file stores none (the builder omits the default it fell back to; other sizes are not
  // written by this builder and also give the default).
  DownsampleFilter downsample_filter() const;
  // Bands of a level, top to bottom, covering every row exactly once (a run of all-zero bands is
  // one view without a stream).
  const std::vector<BandView>& bands(int level) const { return bands_.at(size_t(level)); }
  // Index of the band holding row y of the level.
  size_t band_of_row(int level, int64_t y) const;
  const std::string& path() const { return container_.path(); }
  // Everything open() leaves to the decoder, for `terrain-info --verify`: every level blob's CRC
  // (Container::verify), then for every band record with a stream that the stream opens (libcodec
  // header, tile index, stream CRC), that it codes the level's width and the record's rows, that
  // every tile row's payload CRC holds and that every tile decodes. A band table that is consistent
  // in itself but wrong (resealed after forging) fails here. Throws Error (CorruptData, or
  // ChecksumMismatch for a CRC) naming the file, level, band record and the field or libcodec status.
  // Memory: one tile row of one band. checks = Checksums stops short of decoding: the same checks
  // except that each tile row's payload CRC is compared instead of the row being decoded (what
  // libedit's compaction needs before it copies streams under fresh level blob CRCs).
  enum class VerifyDepth { Decode, Checksums };
  void verify(VerifyDepth checks = VerifyDepth::Decode) const;
  // 2.2 editing: bytes of the committed file that the current version uses (superblock and its tail
  // copy, level blobs, the band streams their band maps point at, mask, metadata, index) and the
  // rest (earlier generations' streams, band maps and indices), which compaction drops.
  uint64_t live_bytes() const { return live_bytes_; }
  uint64_t dead_bytes() const { return container_.committed_size() - live_bytes_; }
  // A level's bytes wherever they lie: its band streams plus its band table and footer.
  uint64_t level_bytes(int level) const { return level_bytes_.at(size_t(level)); }

 private:
  explicit PyramidFile(Container&& c) : container_(std::move(c)) {}
  uint64_t count_live_bytes() const;
  Container container_;
  std::vector<std::vector<BandView>> bands_;
  uint64_t live_bytes_ = 0;
  std::vector<uint64_t> level_bytes_;
};

// Band-map blobs (2.2, written by an edit): the band table's stream records carry the stream's file
// offset, so a level can keep most of its streams where an earlier generation wrote them.
inline constexpr uint32_t kBandMapMagic = 0x33444e42;    // "BND3"
inline constexpr uint32_t kBandTableMagic = 0x32444e42;  // "BND2"
// One band of a band map: rows, and the stream's file offset and size (size 0: a run of all-zero
// bands of `rows` rows each, `run` of them).
struct BandMapRecord {
  uint64_t rows = 0, run = 1, offset = 0, size = 0;
};
// The blob of a band map: table records, then the 12-byte footer (table size, "BND3", CRC-32C).
std::vector<uint8_t> encode_band_map(const std::vector<BandMapRecord>& records);
// A BND2 band table blob's table and footer for streams laid out back to back before it (compaction).
std::vector<uint8_t> encode_band_table(const std::vector<BandMapRecord>& records);

// Parses a level blob's band table (exposed for tests); throws Error(Corrupt) naming `what`.
std::vector<BandView> parse_band_table(const uint8_t* blob, size_t size, int64_t level_height,
                                       const std::string& what);

}  // namespace terrain::container
