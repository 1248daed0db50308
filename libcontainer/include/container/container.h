// The single-file pyramid container (".pyr"): the "container" stage of the data flow.
//
// A container holds one opaque byte blob per pyramid level (a libcodec stream; this file knows
// nothing of its contents) plus everything needed to interpret the pyramid: dimensions, spacing,
// vertical quantum, georeference, the D filter, the quantisation, per-level residual statistics,
// the nodata mask and a free-form JSON metadata string. docs/format.md gives the byte layout.
//
// Writing is streamed (blobs may be gigabytes) into a temporary file that is renamed onto the
// target only by finish(), so a file at the target path is always complete. Reading maps the file
// read-only and hands out zero-copy views of the blobs; every offset, size, checksum and the level
// dimension chain are validated on open, so bad input gives Error, never a crash.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "codec/crc32c.h"
#include "core/error.h"

namespace terrain::container {

// ---------------------------------------------------------------------------------------------
// Checksum used throughout the format: CRC-32C (Castagnoli, reflected polynomial 0x82F63B78,
// initial value and final xor 0xFFFFFFFF). Exposed so tools and tests can check files independently.

// libcodec's implementation (one for the project): pass a previous result as `crc` to continue.
using codec::crc32c;
using codec::crc32c_combine;
using codec::crc32c_portable;

// ---------------------------------------------------------------------------------------------
// Contents

// Format version written by this library. A reader accepts any minor version of its major
// version (minor versions only append fields) and rejects other majors. 2.0: level blobs with
// compact band tables and all-zero bands without a stream, libcodec format 4 streams; its level
// records are those of 1.1 (with the error figures). 1.x files must be rebuilt. 2.1 adds the
// georeference's full geotransform and its CRS (EPSG code, CRS text); 2.0 files still open. 2.2
// adds copy-on-write editing (an edited flag and generation in the superblock, a tail copy of it,
// dead bytes between regions, band-map level blobs: docs/format.md "Editing (2.2)"). 3.0 has 2.2's
// layout; its band streams may be libcodec format 5 (the residual transform), so 2.x readers must
// refuse it; this reader reads 2.0-2.2 and 3.x. 3.1 adds filter provenance 2 (D is
// DownsampleFilter::wavelet(), not stored); 3.0 readers refuse such a file ("unknown filter
// provenance 2") and read every other 3.1 file. 3.2 adds provenance 3 (point sampling), whose band
// streams are libcodec format 6; 3.3 replaces those by format 7 (phase tiles with static token
// tables): this reader refuses 3.2 files of provenance 3 (rebuild them) and reads all other 3.x.
// 3.4's phase streams are format 8 (two interleaved rANS states per tile), which 3.3 readers refuse
// at the first such band; this reader reads 3.3's format 7 as well.
inline constexpr uint16_t kFormatMajor = 3;
inline constexpr uint16_t kFormatMinor = 4;
inline constexpr uint32_t kMaxLevels = 64;
inline constexpr uint32_t kMaxFilterSize = 63;
inline constexpr size_t kMaxUnitsLength = 31;  // units strings are stored in 32-byte fields

// How the builder chose D; Fallback, Wavelet and Point store no taps (readers know them). Wavelet
// came with 3.1, Point (point sampling, DownsampleFilter::impulse()) with 3.2.
enum class FilterProvenance : uint32_t { Optimal = 0, Fallback = 1, Wavelet = 2, Point = 3 };
// "optimal", "fallback", "wavelet" or "point".
const char* filter_provenance_name(FilterProvenance provenance);
// What the quantiser step was chosen for; stored as a u32. Also the build's option (BuildFileOptions).
enum class ErrorMode : uint32_t { Rms = 0, MaxError = 1, Step = 2, Lossless = 3 };
// "rms", "max-error", "step" or "lossless" (the pyramid-build option that chose it).
const char* error_mode_name(ErrorMode mode);

// Statistics of one level's residual image, in quantisation units (used later for synthesis).
struct ResidualStats {
  double mean = 0, variance = 0, rms = 0, min = 0, max = 0;
};

// How far the stored level is from what it encodes, T_l - T^_l in quantisation units, as the builder
// measured it over the whole level (valid samples only at the finest level; float input counts as
// rounded to its quantum, so add up to half a quantum against the float values).
struct LevelError {
  double rms = 0;
  double max_abs = 0;
};

struct LevelInfo {
  uint64_t width = 0;
  uint64_t height = 0;
  ResidualStats stats;
  std::optional<LevelError> error;  // absent in version 1.0 files
  // Filled in by the reader only.
  uint64_t blob_offset = 0;
  uint64_t blob_size = 0;
  bool has_blob_crc = false;
  uint32_t blob_crc = 0;
};

struct Georeference {
  // GDAL's affine geotransform of pixel corners in `units`: x = gt[0] + col * gt[1] + row * gt[2],
  // y = gt[3] + col * gt[4] + row * gt[5] (finest level). gt[1], gt[5] finite and non-zero; the
  // rotation terms gt[2], gt[4] are 0 (rotated grids are not stored). A 2.0 file's is derived from
  // its origin and spacing (north-up).
  std::array<double, 6> geotransform{0, 1, 0, 0, 0, -1};
  std::string units;      // e.g. "degree", "m"
  uint32_t crs_epsg = 0;  // EPSG code of the CRS; 0 unknown (always 0 in 2.0 files)
  std::string crs_text;   // WKT / PROJ text of the CRS, empty when unknown; is_crs_text (core/text.h)
  // Longitude/easting and latitude/northing of the north-west sample centre (2.0's origin fields).
  double origin_x() const { return geotransform[0] + 0.5 * geotransform[1]; }
  double origin_y() const { return geotransform[3] + 0.5 * geotransform[5]; }
};

struct Quantisation {
  double step_units = 1;   // quantisation step in the integer quantum (native units)
  double step_metres = 1;  // the same step in metres
  ErrorMode mode = ErrorMode::Lossless;
  double target = 0;  // the rms target / max error / step requested, as given to the builder
};

// Everything in a container except the blobs, the mask samples and the JSON metadata.
struct ContainerInfo {
  uint64_t width = 0;  // finest level
  uint64_t height = 0;
  std::vector<LevelInfo> levels;  // 0 = coarsest .. size()-1 = finest; w_{l-1} = ceil(w_l / 2)
  double spacing_x = 1;
  double spacing_y = 1;
  std::string horizontal_units = "m";
  std::string vertical_units = "m";
  double vertical_scale = 1;  // metres = value * vertical_scale + vertical_offset
  double vertical_offset = 0;
  std::optional<Georeference> georeference;
  uint32_t filter_size = 0;    // the D filter is filter_size x filter_size (0: none stored)
  std::vector<double> filter;  // row-major coefficients
  FilterProvenance filter_provenance = FilterProvenance::Optimal;
  Quantisation quantisation;
  uint64_t void_count = 0;  // filled in by the reader: samples marked nodata
};

// Level `level`'s recorded error in metres (the figures times |vertical_scale|); empty for a level
// without them (version 1.0 files). Throws std::out_of_range for a level outside info.levels.
std::optional<LevelError> level_error_metres(const ContainerInfo& info, size_t level);

// Throws std::invalid_argument naming the problem if info is not a consistent description of a
// pyramid (dimension chain, finite spacing, units lengths, filter size), ignoring reader-only fields.
void validate_info(const ContainerInfo& info);

// ---------------------------------------------------------------------------------------------
// Writer

namespace detail {
class HeldBytes;
}

// Not thread-safe: one producer thread drives a writer.
class ContainerWriter {
 public:
  // A held level keeps this many bytes in memory before it spills (see append_level): enough for
  // the coarse levels of any pyramid, while a level that big is cheap to copy through a file.
  static constexpr size_t kDefaultLevelMemoryLimit = size_t(4) << 20;

  // Creates `path + ".tmp.<pid>"` (with a further ".N" if another writer of this process holds
  // that name); throws Error(WriteFailed) if it cannot.
  explicit ContainerWriter(std::string path);
  // Removes the temporary file unless finish() succeeded.
  ~ContainerWriter();
  ContainerWriter(const ContainerWriter&) = delete;
  ContainerWriter& operator=(const ContainerWriter&) = delete;

  // Sets the description; may be called any time before finish(). info.levels gives the level
  // count and each level's dimensions and stats; reader-only fields are ignored.
  void set_info(const ContainerInfo& info);
  // Keep (default) or omit the whole-blob CRC of each level first written from now on.
  void set_level_checksums(bool enabled) { level_checksums_ = enabled; }
  // Memory a level held back may use before it spills (levels held from now on; 0: spill at once).
  void set_level_memory_limit(size_t bytes) { level_memory_limit_ = bytes; }

  // Streams level `level`'s blob in pieces: any number of append_level, then end_level, once per
  // level. Levels may be streamed interleaved and in any order, each level's pieces in its own
  // order; the file holds the blobs contiguous, level 0 first, whatever the arrival order. The
  // lowest level not yet ended goes straight to the file; later ones are held until it ends: in
  // memory up to the level memory limit, the rest in an unnamed spill file in the target's
  // directory (O_TMPFILE, else a random name unlinked at once, so none outlives the writer).
  // Throws std::invalid_argument for a level index >= kMaxLevels or a level already ended, and
  // Error(WriteFailed) when the file or a spill file cannot be written or read back.
  void append_level(uint32_t level, const uint8_t* data, size_t size);
  void end_level(uint32_t level);
  // A whole blob in one piece: append_level then end_level.
  void add_level(uint32_t level, const uint8_t* data, size_t size);
  // Experimental (the striped build's parallel assembly): makes the first `size` bytes of level
  // `level`'s blob a hole that other writers fill (threads or processes that open temp_path() and
  // pwrite there) and returns its file offset; append_level/end_level go on after it. The level must
  // have nothing yet and be the one streaming to the file (every lower level ended). The hole's
  // CRC-32C comes later through set_reserved_crc, before finish(); finish() fsyncs the file, so the
  // other writers must have written their bytes (and, on a network filesystem, closed the file)
  // by then. Throws std::logic_error when the level is not next or already has bytes,
  // Error(WriteFailed) when the file cannot be extended.
  uint64_t reserve_level(uint32_t level, uint64_t size);
  void set_reserved_crc(uint32_t level, uint32_t crc);

  // Appends `count` further mask samples in row-major order (non-zero = data, 0 = void). Call it for all
  // width*height samples or not at all (no call: no voids). Encoded on the fly, O(runs) memory;
  // a mask without voids is not stored.
  void append_mask(const uint8_t* valid, size_t count);
  // Opaque UTF-8 string (tool version, options, source file, timings ...).
  void set_metadata_json(std::string json);

  // Writes mask, metadata and index, fsyncs, renames onto the target path and fsyncs the directory.
  // Throws std::invalid_argument if info/levels/mask are incomplete or inconsistent, and
  // std::logic_error for a level appended to but never ended.
  void finish();
  const std::string& path() const { return path_; }
  const std::string& temp_path() const { return temp_path_; }

 private:
  struct LevelRecord {
    LevelRecord();
    ~LevelRecord();
    LevelRecord(LevelRecord&&) noexcept;
    LevelRecord& operator=(LevelRecord&&) noexcept;
    bool started = false;  // appended to or ended: has_crc is fixed
    bool ended = false;
    bool placed = false;  // its offset is fixed and its bytes go straight to the file
    uint64_t offset = 0, size = 0;
    uint32_t crc = 0;  // of the bytes appended (those after the reserved hole)
    bool has_crc = false;
    uint64_t reserved = 0;  // the hole at the blob's start (reserve_level)
    uint32_t reserved_crc = 0;
    bool reserved_crc_set = false;
    std::unique_ptr<detail::HeldBytes> held;  // bytes waiting for the levels before it
  };
  LevelRecord& start_level(uint32_t level);
  void place_level(uint32_t level);
  void write_bytes(const void* data, size_t size);
  void pad_to_alignment();
  void fail(const std::string& what);

  std::string path_, temp_path_, directory_;
  int fd_ = -1;
  bool finished_ = false, finish_started_ = false;
  uint64_t position_ = 0;  // bytes written so far (the file is written sequentially)
  std::optional<ContainerInfo> info_;
  std::vector<LevelRecord> records_;  // indexed by level
  uint32_t next_level_ = 0;           // levels before it are complete in the file
  bool level_checksums_ = true;
  size_t level_memory_limit_ = kDefaultLevelMemoryLimit;
  // Mask as alternating run lengths (valid, void, valid, ...), LEB128 varints.
  std::vector<uint8_t> mask_runs_;
  uint64_t mask_samples_ = 0, mask_voids_ = 0, current_run_ = 0;
  bool current_run_valid_ = true;
  std::string metadata_json_;
};

// ---------------------------------------------------------------------------------------------
// Reader

// One level's blob, pointing into the read-only mapping (valid while the Container lives).
struct LevelView {
  const uint8_t* data = nullptr;  // 8-byte aligned
  size_t size = 0;
  uint64_t width = 0, height = 0;
};

class MappedFile;

// True when `path` starts with the container's magic bytes (reads 8 bytes; false when it cannot be
// read): lets a tool tell a .pyr from a heightmap by content rather than by name.
bool is_container_file(const std::string& path);

class Container {
 public:
  // Maps and validates the file; throws Error whose message names the file and the problem.
  // The file must not be modified in place while open (the writer only ever renames over it).
  static Container open(const std::string& path);
  Container(Container&&) noexcept;
  Container& operator=(Container&&) noexcept;
  ~Container();

  // All methods are const and the object is immutable after open: safe for concurrent readers.
  const ContainerInfo& info() const { return info_; }
  uint32_t level_count() const { return uint32_t(info_.levels.size()); }
  // Throws std::out_of_range for a level >= level_count().
  LevelView level(uint32_t level) const;
  std::string_view metadata_json() const { return metadata_json_; }
  // width*height samples (1 = data, 0 = void), or empty when the pyramid has no voids.
  std::vector<uint8_t> mask() const;
  // Rows [first_row, first_row + row_count) of the mask into out (row_count * width bytes,
  // 1 = data, 0 = void; all 1 without voids). Throws std::out_of_range past the last row.
  void mask_rows(uint64_t first_row, uint64_t row_count, uint8_t* out) const;
  // Checks every stored per-level CRC (the mask, metadata and index were checked on open);
  // throws Error(ChecksumMismatch) naming the first bad level.
  void verify() const;
  // False if level's stored CRC does not match; true if it matches or none is stored.
  bool level_checksum_ok(uint32_t level) const;
  const std::string& path() const { return path_; }
  uint16_t major_version() const { return major_version_; }
  uint16_t minor_version() const { return minor_version_; }
  // 2.2 editing: whether the file has been edited, its edit generation (0 unedited), the bytes the
  // current version spans (file_size in its superblock) and those past it (an interrupted edit's
  // uncommitted tail), and whether the superblock at offset 0 failed and its tail copy was used.
  bool edited() const { return edited_; }
  uint64_t generation() const { return generation_; }
  uint64_t committed_size() const { return committed_size_; }
  uint64_t uncommitted_bytes() const { return file_bytes_ - committed_size_; }
  bool from_tail_superblock() const { return from_tail_superblock_; }
  // Bytes [offset, offset + size) of the committed file (band maps point at streams anywhere in it);
  // nullptr when the range is not inside it.
  const uint8_t* file_bytes(uint64_t offset, uint64_t size) const;
  // The file offset of a pointer into the mapping (a band view's data).
  uint64_t offset_of(const uint8_t* p) const;
  // The metadata and mask regions as the index places them (the editor carries them over).
  uint64_t metadata_offset() const { return metadata_offset_; }
  uint32_t metadata_crc() const { return metadata_crc_; }
  uint64_t mask_offset() const { return mask_offset_; }
  uint64_t mask_bytes() const { return mask_runs_size_; }
  uint64_t index_offset() const { return index_offset_; }
  uint64_t index_size() const { return index_size_; }
  uint32_t mask_crc() const { return mask_crc_; }

 private:
  Container() = default;
  std::string path_;
  std::unique_ptr<MappedFile> file_;
  ContainerInfo info_;
  std::string_view metadata_json_;
  const uint8_t* mask_runs_ = nullptr;
  size_t mask_runs_size_ = 0;
  uint16_t major_version_ = 0;
  uint16_t minor_version_ = 0;
  bool edited_ = false, from_tail_superblock_ = false;
  uint64_t generation_ = 0, committed_size_ = 0, file_bytes_ = 0;
  uint64_t metadata_offset_ = 0, mask_offset_ = 0, index_offset_ = 0, index_size_ = 0;
  uint32_t metadata_crc_ = 0, mask_crc_ = 0;
};

// ---------------------------------------------------------------------------------------------
// Copy-on-write update (2.2 editing; docs/format.md "Editing (2.2)")

// Where commit() stops, as if the process died there (crash-safety tests).
enum class CommitStop { None, AfterBlobs, AfterIndex, TornSuperblock };

// Appends a new version to a committed container in place: new bytes go after the committed end
// (an interrupted edit's uncommitted tail is cut off first), unchanged regions stay where they are.
// commit() writes the new index and a tail copy of the new superblock, fsyncs, then rewrites the
// superblock at offset 0 and fsyncs again, so a crash at any point leaves either the old or the new
// version readable. The first bytes past the end are a pending-edit record, synced before the rest:
// readers accept bytes past file_size only behind it (or a torn copy of it).
// Not thread-safe; the Container must stay open (its mapping serves the old bytes) until commit.
class ContainerUpdater {
 public:
  // Takes an exclusive flock on the file (held until destruction). Throws Error(WriteFailed) naming
  // the file when it cannot be opened for writing, another process holds the lock, or its superblock
  // no longer describes the version `current` read (another writer committed since).
  explicit ContainerUpdater(const Container& current);
  ~ContainerUpdater();
  ContainerUpdater(const ContainerUpdater&) = delete;
  ContainerUpdater& operator=(const ContainerUpdater&) = delete;

  // Writes `size` bytes at the next 8-aligned offset past the end and returns that offset.
  // Throws Error(WriteFailed).
  uint64_t append(const uint8_t* data, size_t size);
  // Points level `level`'s record at an appended blob with CRC-32C `crc`. Throws std::out_of_range.
  void set_level(uint32_t level, uint64_t offset, uint64_t size, uint32_t crc);
  // Replaces level `level`'s recorded error figures (LevelInfo::error). Throws std::out_of_range.
  void set_level_error(uint32_t level, const LevelError& error) { info_.levels.at(level).error = error; }
  uint64_t bytes_appended() const { return end_ - start_; }
  // Where the next append() will place its bytes.
  uint64_t next_offset() const { return (end_ + 7) & ~uint64_t(7); }
  // Commits (see above) and returns the new committed file size; the new generation is the old + 1.
  // Throws Error(WriteFailed); a failure before the superblock write leaves the old version.
  uint64_t commit(CommitStop stop = CommitStop::None);

 private:
  void write_at(uint64_t offset, const uint8_t* data, size_t size);
  void sync();
  std::string path_;
  int fd_ = -1;
  ContainerInfo info_;
  std::vector<uint64_t> offsets_, sizes_;
  std::vector<uint32_t> crcs_;
  std::vector<bool> has_crc_;
  uint64_t start_ = 0, end_ = 0, generation_ = 0;
  uint64_t metadata_offset_ = 0, metadata_size_ = 0, mask_offset_ = 0, mask_size_ = 0;
  uint32_t metadata_crc_ = 0, mask_crc_ = 0;
  bool committed_ = false;
};

}  // namespace terrain::container
