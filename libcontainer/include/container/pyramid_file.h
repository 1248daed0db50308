// A compressed pyramid on disk: the container (runtime/container.h) whose level blobs hold a
// level's bands. Each band is one libcodec stream covering rows [y0, y0 + rows) of the level; a
// band table at the end of the blob locates them (docs/format.md, "Level blob").
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

namespace terrain::runtime {

// Streams the builder's output into a ContainerWriter (temporary file until finish()).
class PyramidFileWriter final : public PyramidSink {
 public:
  explicit PyramidFileWriter(const std::string& path);
  ~PyramidFileWriter() override;

  void begin(const PyramidHeader& header) override;
  void band(int level, int64_t y0, int64_t rows, std::vector<uint8_t>&& bytes) override;
  void mask_band(int64_t y0, int64_t rows, std::vector<uint8_t>&& bytes) override;

  // Completes the file: `info` supplies what the builder does not know (quantisation, units,
  // georeference); levels, filter and stats are taken from `result`. Renames onto the target.
  void finish(const BuildResult& result, ContainerInfo info, const std::string& metadata_json);
  uint64_t bytes_written() const { return bytes_; }

 private:
  void close_level();
  ContainerWriter writer_;
  PyramidHeader header_;
  int open_level_ = -1;
  struct BandRecord {
    uint64_t offset, size, y0, rows;
  };
  std::vector<BandRecord> bands_;
  uint64_t level_bytes_ = 0, bytes_ = 0;
  std::vector<uint8_t> mask_scratch_;
};

struct BandView {
  int64_t y0 = 0, rows = 0;
  const uint8_t* data = nullptr;
  size_t size = 0;
};

class PyramidFile {
 public:
  // Opens and validates the container and every level's band table; throws Error.
  static std::shared_ptr<const PyramidFile> open(const std::string& path);

  const Container& container() const { return container_; }
  const ContainerInfo& info() const { return container_.info(); }
  int level_count() const { return int(container_.level_count()); }
  GridSize level_size(int level) const;
  // Bands of a level, top to bottom, covering every row exactly once.
  const std::vector<BandView>& bands(int level) const { return bands_.at(size_t(level)); }
  // Index of the band holding row y of the level.
  size_t band_of_row(int level, int64_t y) const;
  const std::string& path() const { return container_.path(); }

 private:
  explicit PyramidFile(Container&& c) : container_(std::move(c)) {}
  Container container_;
  std::vector<std::vector<BandView>> bands_;
};

// Parses a level blob's band table (exposed for tests); throws Error(Corrupt) naming `what`.
std::vector<BandView> parse_band_table(const uint8_t* blob, size_t size, int64_t level_height,
                                       const std::string& what);

}  // namespace terrain::runtime
