// Shared plumbing of the heightmap readers/writers (io_*.cpp): error helpers, fixed-layout sample
// streams, per-format probes and the write-to-temporary-then-rename helper. Not a public header.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "readers/heightmap.h"

namespace terrain::io {

// Throws Error(code, "<path>: <problem>") so that every message names the file.
[[noreturn]] void fail(ErrorCode code, const std::string& path, const std::string& problem);

std::string to_lower(std::string s);
bool ends_with_ci(const std::string& s, const std::string& suffix);
// Size in bytes of an existing regular file; throws NotFound when it is missing or not a file.
uint64_t existing_file_size(const std::string& path);
bool file_exists(const std::string& path);

// How samples are laid out on disk in the fixed-layout formats (raw, .hgt, .bil/.flt).
enum class StoredType { UInt8, Int16, UInt16, Int32, Float32 };
int stored_bytes(StoredType t);
StoredType stored_type_for(SampleType t);  // Int16->Int16 ... TerrainRGB->Int32

struct RawLayout {
  GridInfo info;
  StoredType stored = StoredType::Int16;
  bool big_endian = false;
  uint64_t data_offset = 0;  // bytes to skip before row 0
  bool gzip = false;         // stream through zlib's gzread
};

// Bytes the samples of `layout` need; DimensionMismatch if the dimensions are not positive, overflow,
// or the rows are wider than kMaxRowSamples.
uint64_t layout_bytes(const std::string& path, const RawLayout& layout);
// Band reader over a fixed-layout file (fread at the data offset, or gzread for gzip streams).
std::unique_ptr<BandReader> open_raw_stream(const std::string& path, const RawLayout& layout);
// The whole of a small side file (JSON sidecar, ESRI .hdr and .prj): MissingField when it is larger
// than `limit` bytes (memory stays bounded whatever the file), NotFound when it is not a regular file.
std::string read_small_text_file(const std::string& path, size_t limit);
inline constexpr size_t kSideFileLimit = size_t(1) << 16;

// The ESRI .prj beside a grid (ignored when missing): its WKT becomes crs_text (and crs_epsg where
// it names one, epsg_from_wkt); a geographic CRS turns spacing (degrees) into arc-seconds.
void apply_prj(const std::string& prj, GridInfo& g);
// Rows of at most kMaxRowSamples samples (docs/io.md, "Limits"): readers and the builder hold a band
// of rows, so memory is O(width x band) and a wider row is refused from the header alone.
inline constexpr int64_t kMaxRowSamples = int64_t(1) << 20;
// DimensionMismatch naming `path` and the limit when `width` is above kMaxRowSamples.
void check_row_width(const std::string& path, int64_t width);
// The most bytes the image library may hold to decode one row (a strip, a row of tiles, the whole
// of an interlaced PNG: terrain_image_header::decode_unit_bytes).
inline constexpr int64_t kMaxImageDecodeBytes = int64_t(256) << 20;

// Overrides every format honours: spacing, vertical scale/offset, nodata.
void apply_common_overrides(GridInfo& info, const ReadOptions& options);

// Per-format probes; each validates what it can without reading samples.
RawLayout probe_hgt_layout(const std::string& path, const ReadOptions& options);
RawLayout probe_raw_layout(const std::string& path, const ReadOptions& options);
RawLayout probe_esri_layout(const std::string& path, const ReadOptions& options);
GridInfo probe_image(const std::string& path, const ReadOptions& options);
// ESRI ASCII grids (.asc): header keywords, then whitespace-separated values, streamed.
GridInfo probe_ascii_grid(const std::string& path, const ReadOptions& options);
std::unique_ptr<BandReader> open_ascii_grid(const std::string& path, const ReadOptions& options);
std::unique_ptr<BandReader> open_image_reader(const std::string& path, const ReadOptions& options);

// The EPSG code a WKT text names for its outermost CRS: its AUTHORITY["EPSG","n"] / ID["EPSG",n],
// else the ESRI names GCS_WGS_1984 (4326) and WGS_1984_UTM_Zone_nN/S (326nn/327nn); nullopt otherwise.
std::optional<int> epsg_from_wkt(const std::string& wkt);

// Shortest decimal text that reads back as exactly the same double (locale independent).
std::string format_double(double v);

// Writes go to a temporary file beside the target, created exclusively under a random name with the
// same extension (so OpenImageIO picks the same writer; core/file.h create_temp_beside); commit()
// renames it over the target. Destroying an uncommitted one removes the temporary.
class AtomicOutput {
 public:
  explicit AtomicOutput(std::string target);
  ~AtomicOutput();
  AtomicOutput(const AtomicOutput&) = delete;
  AtomicOutput& operator=(const AtomicOutput&) = delete;
  const std::string& temp_path() const { return temp_; }
  const std::string& target() const { return target_; }
  void commit();

 private:
  std::string target_, temp_;
  bool committed_ = false;
};

// Native value of sample (x, y) converted for writing: voids become the nodata value; WriteFailed
// when a void has no nodata value to stand for it.
double value_for_writing(const Heightmap& map, int64_t x, int64_t y, const std::string& path);

}  // namespace terrain::io
