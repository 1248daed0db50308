// Container reader: maps the file and validates everything the accessors will rely on (magic,
// version, checksums of superblock, index, mask and metadata, every region against the file
// size, non-overlap, the level dimension chain), so that after open() no accessor can read out
// of bounds whatever the file contained.
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <utility>

#include "container/container.h"
#include "container/internal/container_format.h"
#include "container/internal/container_mask.h"
#include "container/internal/mmap_file.h"
#include "core/file.h"
#include "core/text.h"

namespace terrain::container {

using namespace layout;

namespace {

struct Region {
  uint64_t offset, size;
  std::string what;
};

class Parser {
 public:
  Parser(const std::string& path, uint64_t file_size) : path_(path), file_size_(file_size) {}

  [[noreturn]] void fail(ErrorCode code, const std::string& what) const {
    throw Error(code, path_ + ": " + what);
  }
  void require(bool ok, const std::string& what) const {
    if (!ok) fail(ErrorCode::CorruptData, what);
  }
  // Regions are checked with subtraction only, so no 64-bit sum can wrap.
  void require_region(uint64_t offset, uint64_t size, uint64_t min_offset, const std::string& what) const {
    require(offset >= min_offset && offset <= file_size_ && size <= file_size_ - offset,
            what + " (offset " + std::to_string(offset) + ", size " + std::to_string(size) +
                ") lies outside the file (" + std::to_string(file_size_) + " bytes)");
    require(offset % kAlignment == 0, what + " offset " + std::to_string(offset) + " is not 8-byte aligned");
  }
  void require_crc(const uint8_t* data, uint64_t size, uint32_t stored, const std::string& what) const {
    const uint32_t actual = crc32c(data, size_t(size));
    if (actual != stored) {
      fail(ErrorCode::ChecksumMismatch,
           what + " checksum mismatch (stored " + hex(stored) + ", computed " + hex(actual) + ")");
    }
  }
  // A NUL-terminated string in a zero-padded fixed field.
  std::string string_field(const uint8_t* p, size_t field, const std::string& what) const {
    const void* nul = std::memchr(p, 0, field);
    require(nul != nullptr, what + " is not NUL-terminated");
    const size_t len = size_t(static_cast<const uint8_t*>(nul) - p);
    require(all_zero(p + len, field - len), what + " has bytes after its terminator");
    return std::string(reinterpret_cast<const char*>(p), len);
  }
  static bool all_zero(const uint8_t* p, size_t n) {
    return std::all_of(p, p + n, [](uint8_t b) { return b == 0; });
  }
  static std::string hex(uint32_t v) {
    char buf[16];
    std::snprintf(buf, sizeof buf, "0x%08X", v);
    return buf;
  }

 private:
  const std::string& path_;
  uint64_t file_size_;
};

}  // namespace

Container::Container(Container&&) noexcept = default;
Container& Container::operator=(Container&&) noexcept = default;
Container::~Container() = default;

bool is_container_file(const std::string& path) {
  uint8_t head[sizeof kMagic] = {};
  int fd = -1;
  try {
    fd = open_regular_file(path);  // a FIFO or device is no container (and must not block us)
  } catch (const Error&) {
    return false;
  }
  const ssize_t got = ::read(fd, head, sizeof head);
  ::close(fd);
  return got == ssize_t(sizeof head) && std::memcmp(head, kMagic, sizeof kMagic) == 0;
}

Container Container::open(const std::string& path) {
  Container c;
  c.path_ = path;
  c.file_ = std::make_unique<MappedFile>(path);
  const uint8_t* base = c.file_->data();
  const uint64_t size = c.file_->size();
  const Parser parse(path, size);
  using Code = ErrorCode;

  // --- superblock
  if (size == 0) parse.fail(Code::Truncated, "empty file");
  if (std::memcmp(base, kMagic, size_t(std::min<uint64_t>(size, sizeof kMagic))) != 0) {
    parse.fail(Code::UnknownType, "not a pyramid container (bad magic bytes)");
  }
  if (size < 16)
    parse.fail(Code::Truncated, "file is " + std::to_string(size) + " bytes, too short for a header");
  // 2.2: a superblock that fails its CRC may be a torn commit of an edit, which wrote (and synced) a
  // copy of the new superblock as the last 64 bytes of the file before it touched offset 0.
  const uint8_t* sbp = base;
  if (size >= 2 * uint64_t(sb::kSizeV1)) {
    const auto intact = [](const uint8_t* p) {
      return get_u32(p + sb::kSize) == sb::kSizeV1 && crc32c(p, sb::kCrc) == get_u32(p + sb::kCrc);
    };
    const uint8_t* tail = base + size - sb::kSizeV1;
    if (!intact(base) && std::memcmp(tail, kMagic, sizeof kMagic) == 0 && intact(tail) &&
        (get_u16(tail + sb::kMajor) == kFormatMajor ||
         (get_u16(tail + sb::kMajor) == 2 && get_u16(tail + sb::kMinor) >= 2)) &&
        (get_u32(tail + sb::kFlags) & sb::kFlagEdited) && get_u64(tail + sb::kFileSize) == size) {
      sbp = tail;
      c.from_tail_superblock_ = true;
    }
  }
  const uint16_t major = get_u16(sbp + sb::kMajor), minor = get_u16(sbp + sb::kMinor);
  // 3.0 keeps 2.2's layout; its band streams may be libcodec format 5, which 2.x readers cannot decode.
  if (major != kFormatMajor && major != 2) {
    parse.fail(Code::UnsupportedVersion,
               "format version " + std::to_string(major) + "." + std::to_string(minor) +
                   " is not supported (this reader reads versions 2.x and " + std::to_string(kFormatMajor) +
                   ".x): rebuild it with pyramid-build");
  }
  c.major_version_ = major;
  c.minor_version_ = minor;
  // Newer minor versions may grow fixed-size structures; this reader reads the fields it knows.
  const bool newer = major == kFormatMajor ? minor > kFormatMinor : minor > 2;
  const bool since_2_1 = major > 2 || minor >= 1, since_2_2 = major > 2 || minor >= 2;
  const uint32_t sb_size = get_u32(sbp + sb::kSize);
  parse.require(
      newer ? (sb_size >= sb::kSizeV1 && sb_size % 8 == 0 && sb_size <= 65536) : sb_size == sb::kSizeV1,
      "superblock size " + std::to_string(sb_size) + " is invalid");
  if (size < sb_size)
    parse.fail(Code::Truncated, "file is " + std::to_string(size) + " bytes, shorter than its header");
  parse.require_crc(sbp, sb_size - 4, get_u32(sbp + sb_size - 4), "superblock");
  const uint64_t recorded_size = get_u64(sbp + sb::kFileSize);
  if (size < recorded_size) {
    parse.fail(Code::Truncated, "file is " + std::to_string(size) + " bytes, its header says " +
                                    std::to_string(recorded_size) + ": truncated");
  }
  // 2.2: bytes past file_size are what an interrupted edit appended and never committed, when they
  // start with its pending record (or are the start of a torn copy of it).
  if (size > recorded_size) {
    const uint64_t at = align_up(recorded_size);
    const uint64_t gen =
        since_2_2 && (get_u32(sbp + sb::kFlags) & sb::kFlagEdited) ? get_u64(sbp + sb::kGeneration) : 0;
    const std::array<uint8_t, sb::kSizeV1> pending = encode_pending(recorded_size, gen + 1);
    bool ok =
        at <= size && Parser::all_zero(base + recorded_size, size_t(std::min(at, size) - recorded_size));
    if (ok) {
      const size_t have = size_t(std::min<uint64_t>(size - at, sb::kSizeV1));
      ok = std::memcmp(base + at, pending.data(), have) == 0;
    }
    parse.require(ok, "file is " + std::to_string(size) + " bytes, its header says " +
                          std::to_string(recorded_size) + ": trailing bytes");
  }
  c.committed_size_ = recorded_size;
  const Parser committed(path, recorded_size);  // every region lies in the committed bytes
  c.file_bytes_ = size;
  const uint32_t sb_flags = get_u32(sbp + sb::kFlags);
  const bool edited = since_2_2 && (sb_flags & sb::kFlagEdited) != 0;
  c.edited_ = edited;
  if (edited) c.generation_ = get_u64(sbp + sb::kGeneration);
  if (!newer) {
    const uint32_t known_flags = since_2_2 ? sb::kFlagEdited : 0;
    const size_t reserved_from = edited ? sb::kGeneration + 8 : sb::kReserved;
    parse.require(
        (sb_flags & ~known_flags) == 0 && Parser::all_zero(sbp + reserved_from, sb::kCrc - reserved_from),
        "reserved superblock fields are not zero");
  }
  parse.require(!edited || recorded_size >= 2 * uint64_t(sb::kSizeV1),
                "edited file of " + std::to_string(recorded_size) + " bytes has no tail superblock");
  const uint64_t index_offset = get_u64(sbp + sb::kIndexOffset), index_size = get_u64(sbp + sb::kIndexSize);
  committed.require_region(index_offset, index_size, sb_size, "index");
  parse.require(index_size >= info::kSizeV1, "index is " + std::to_string(index_size) + " bytes, too small");
  const uint8_t* idx = base + index_offset;
  c.index_offset_ = index_offset;
  c.index_size_ = index_size;
  parse.require_crc(idx, index_size, get_u32(sbp + sb::kIndexCrc), "index");

  // --- index: sizes first, so every later read is known to be inside it
  const uint32_t info_size = get_u32(idx + info::kInfoSize);
  const uint32_t level_count = get_u32(idx + info::kLevelCount);
  const uint32_t record_size = get_u32(idx + info::kLevelRecordSize);
  const uint32_t filter_size = get_u32(idx + info::kFilterSize);
  // 2.0 info blocks end at kSizeV1; 2.1 appends the geotransform and the CRS (kSizeV2_1).
  const bool has_crs_fields = since_2_1;
  const uint32_t known_info_size = has_crs_fields ? info::kSizeV2_1 : info::kSizeV1;
  parse.require(newer ? (info_size >= known_info_size && info_size % 8 == 0) : info_size == known_info_size,
                "index info size " + std::to_string(info_size) + " is invalid");
  // Version 2.0 records are those of 1.1: the residual statistics, then the reconstruction error.
  const uint32_t known_record_size = level::kSizeV1_1;
  const uint32_t known_level_flags = level::kFlagHasCrc | level::kFlagHasError;
  parse.require(
      newer ? (record_size >= known_record_size && record_size % 8 == 0) : record_size == known_record_size,
      "level record size " + std::to_string(record_size) + " is invalid");
  parse.require(
      level_count >= 1 && level_count <= kMaxLevels,
      "level count " + std::to_string(level_count) + " is outside 1.." + std::to_string(kMaxLevels));
  parse.require(filter_size <= kMaxFilterSize,
                "filter size " + std::to_string(filter_size) + " is too large");
  // Each term is below 2^38, so the sum cannot wrap.
  const uint64_t filter_end =
      uint64_t(info_size) + uint64_t(level_count) * record_size + uint64_t(filter_size) * filter_size * 8;
  // 2.1: the CRS text follows the filter, zero-padded to 8 bytes.
  const uint32_t crs_text_size = has_crs_fields ? get_u32(idx + info::kCrsTextSize) : 0;
  parse.require(crs_text_size <= kMaxCrsTextBytes, "georeference crs_text_size " +
                                                       std::to_string(crs_text_size) + " exceeds " +
                                                       std::to_string(kMaxCrsTextBytes) + " bytes");
  const uint64_t needed = align_up(filter_end + crs_text_size);
  parse.require(
      newer ? index_size >= needed : index_size == needed,
      "index is " + std::to_string(index_size) + " bytes, its contents need " + std::to_string(needed));
  parse.require(
      Parser::all_zero(idx + filter_end + crs_text_size, size_t(needed - filter_end - crs_text_size)),
      "padding after the CRS text is not zero");

  ContainerInfo& info = c.info_;
  info.width = get_u64(idx + info::kWidth);
  info.height = get_u64(idx + info::kHeight);
  info.spacing_x = get_f64(idx + info::kSpacingX);
  info.spacing_y = get_f64(idx + info::kSpacingY);
  info.horizontal_units =
      parse.string_field(idx + info::kHorizontalUnits, info::kUnitsField, "horizontal units");
  info.vertical_units = parse.string_field(idx + info::kVerticalUnits, info::kUnitsField, "vertical units");
  info.vertical_scale = get_f64(idx + info::kVerticalScale);
  info.vertical_offset = get_f64(idx + info::kVerticalOffset);
  const uint32_t has_georeference = get_u32(idx + info::kHasGeoreference);
  std::optional<std::pair<double, double>> stored_origin;  // 2.1: the 2.0 origin fields
  parse.require(has_georeference <= 1, "georeference flag is " + std::to_string(has_georeference));
  if (has_georeference) {
    Georeference g;
    const double origin_x = get_f64(idx + info::kOriginX), origin_y = get_f64(idx + info::kOriginY);
    g.units = parse.string_field(idx + info::kGeoreferenceUnits, info::kUnitsField, "georeference units");
    if (has_crs_fields) {
      for (size_t i = 0; i < 6; ++i) g.geotransform[i] = get_f64(idx + info::kGeotransform + 8 * i);
      g.crs_epsg = get_u32(idx + info::kCrsEpsg);
      g.crs_text.assign(reinterpret_cast<const char*>(idx + filter_end), crs_text_size);
      stored_origin = {origin_x, origin_y};  // checked against the geotransform after validate_info
    } else {
      // 2.0: north-up, the pixel size from the spacing (arc-seconds -> degrees).
      const double per_unit =
          info.horizontal_units == "arc-second" && g.units == "degree" ? 1.0 / 3600.0 : 1.0;
      const double dx = info.spacing_x * per_unit, dy = info.spacing_y * per_unit;
      g.geotransform = {origin_x - 0.5 * dx, dx, 0.0, origin_y + 0.5 * dy, 0.0, -dy};
    }
    info.georeference = std::move(g);
  } else {
    parse.require(Parser::all_zero(idx + info::kOriginX, info::kStepUnits - info::kOriginX),
                  "georeference fields are set but its flag is not");
    if (has_crs_fields)
      parse.require(Parser::all_zero(idx + info::kGeotransform, info::kSizeV2_1 - info::kGeotransform),
                    "georeference geotransform or CRS fields are set but its flag is not");
  }
  const uint32_t provenance = get_u32(idx + info::kFilterProvenance);
  // Provenance 2 (the wavelet D, not stored) came with 3.1, 3 (point sampling) with 3.2.
  const bool since_3_1 = major > 3 || (major == 3 && minor >= 1);
  const bool since_3_2 = major > 3 || (major == 3 && minor >= 2);
  parse.require(provenance <= uint32_t(since_3_2   ? FilterProvenance::Point
                                       : since_3_1 ? FilterProvenance::Wavelet
                                                   : FilterProvenance::Fallback),
                "unknown filter provenance " + std::to_string(provenance));
  // 3.2's point-sampled pyramids hold libcodec format-6 phase tiles, replaced by format 7 in 3.3.
  if (major == 3 && minor == 2 && provenance == uint32_t(FilterProvenance::Point))
    parse.fail(Code::UnsupportedVersion,
               "format version 3.2 with point sampling holds libcodec format-6 streams, which this reader "
               "no longer decodes: rebuild it with pyramid-build");
  info.filter_provenance = FilterProvenance(provenance);
  info.quantisation.step_units = get_f64(idx + info::kStepUnits);
  info.quantisation.step_metres = get_f64(idx + info::kStepMetres);
  const uint32_t mode = get_u32(idx + info::kErrorMode);
  parse.require(mode <= uint32_t(ErrorMode::Lossless), "unknown error mode " + std::to_string(mode));
  info.quantisation.mode = ErrorMode(mode);
  info.quantisation.target = get_f64(idx + info::kTarget);

  info.levels.resize(level_count);
  std::vector<Region> regions = {{0, sb_size, "superblock"}, {index_offset, index_size, "index"}};
  for (uint32_t l = 0; l < level_count; ++l) {
    const uint8_t* r = idx + info_size + uint64_t(l) * record_size;
    LevelInfo& li = info.levels[l];
    const std::string name = "level " + std::to_string(l);
    li.width = get_u64(r + level::kWidth);
    li.height = get_u64(r + level::kHeight);
    li.blob_offset = get_u64(r + level::kBlobOffset);
    li.blob_size = get_u64(r + level::kBlobSize);
    li.blob_crc = get_u32(r + level::kBlobCrc);
    const uint32_t flags = get_u32(r + level::kFlags);
    parse.require(newer || (flags & ~known_level_flags) == 0, name + " has unknown flags");
    li.has_blob_crc = (flags & level::kFlagHasCrc) != 0;
    parse.require(li.has_blob_crc || li.blob_crc == 0, name + " has a checksum but its flag is not set");
    li.stats.mean = get_f64(r + level::kMean);
    li.stats.variance = get_f64(r + level::kVariance);
    li.stats.rms = get_f64(r + level::kRms);
    li.stats.min = get_f64(r + level::kMin);
    li.stats.max = get_f64(r + level::kMax);
    const double error_rms = get_f64(r + level::kErrorRms), error_max = get_f64(r + level::kErrorMax);
    if (flags & level::kFlagHasError) {
      li.error = LevelError{error_rms, error_max};  // validate_info below checks the figures
    } else {
      parse.require(error_rms == 0 && error_max == 0, name + " has error figures but its flag is not set");
    }
    committed.require_region(li.blob_offset, li.blob_size, sb_size, name + " blob");
    regions.push_back({li.blob_offset, li.blob_size, name + " blob"});
  }
  info.filter_size = filter_size;
  info.filter.resize(size_t(filter_size) * filter_size);
  const uint8_t* f = idx + info_size + uint64_t(level_count) * record_size;
  for (size_t i = 0; i < info.filter.size(); ++i) info.filter[i] = get_f64(f + 8 * i);

  // Dimension chain, spacing, units: the same rules the writer enforced.
  try {
    validate_info(info);
  } catch (const std::invalid_argument& e) {
    parse.fail(Code::CorruptData, e.what());
  }
  // 2.1 keeps 2.0's origin fields for 2.0 readers: they must say what the geotransform says.
  if (stored_origin)
    parse.require(stored_origin->first == info.georeference->origin_x() &&
                      stored_origin->second == info.georeference->origin_y(),
                  "georeference origin_x/origin_y disagree with its geotransform");

  // --- metadata and mask, each with its own checksum
  const uint64_t metadata_offset = get_u64(idx + info::kMetadataOffset);
  const uint64_t metadata_size = get_u64(idx + info::kMetadataSize);
  committed.require_region(metadata_offset, metadata_size, sb_size, "metadata");
  parse.require_crc(base + metadata_offset, metadata_size, get_u32(idx + info::kMetadataCrc), "metadata");
  regions.push_back({metadata_offset, metadata_size, "metadata"});
  c.metadata_offset_ = metadata_offset;
  c.metadata_crc_ = get_u32(idx + info::kMetadataCrc);
  c.metadata_json_ =
      std::string_view(reinterpret_cast<const char*>(base + metadata_offset), size_t(metadata_size));

  const uint32_t mask_encoding = get_u32(idx + info::kMaskEncoding);
  const uint64_t mask_offset = get_u64(idx + info::kMaskOffset), mask_size = get_u64(idx + info::kMaskSize);
  const uint64_t void_count = get_u64(idx + info::kVoidCount);
  const uint32_t mask_crc = get_u32(idx + info::kMaskCrc);
  if (mask_encoding == kMaskNone) {
    parse.require(mask_offset == 0 && mask_size == 0 && void_count == 0 && mask_crc == 0,
                  "mask fields are set but the mask encoding says there is no mask");
  } else {
    parse.require(mask_encoding == kMaskRunsLeb128, "unknown mask encoding " + std::to_string(mask_encoding));
    parse.require(void_count >= 1 && mask_size >= 1, "run-coded mask without voids");
    committed.require_region(mask_offset, mask_size, sb_size, "mask");
    parse.require_crc(base + mask_offset, mask_size, mask_crc, "mask");
    const std::string problem =
        mask_runs::check(base + mask_offset, size_t(mask_size), info.width * info.height, void_count);
    parse.require(problem.empty(), problem);
    regions.push_back({mask_offset, mask_size, "mask"});
    c.mask_offset_ = mask_offset;
    c.mask_crc_ = mask_crc;
    c.mask_runs_ = base + mask_offset;
    c.mask_runs_size_ = size_t(mask_size);
  }
  info.void_count = void_count;

  // No two regions may share bytes (a corrupted offset pointing into the index, say).
  if (edited) regions.push_back({recorded_size - sb::kSizeV1, sb::kSizeV1, "tail superblock"});
  std::erase_if(regions, [](const Region& r) { return r.size == 0; });
  std::sort(regions.begin(), regions.end(),
            [](const Region& a, const Region& b) { return a.offset < b.offset; });
  // Regions were checked to lie inside the file, so offset + size cannot wrap. The bytes between
  // regions are alignment padding, covered by no checksum: requiring zeros there means a flipped
  // byte anywhere outside the blobs is caught by open(), and inside a blob by verify(). An edited
  // file (2.2) has dead bytes between its regions (earlier generations' blobs and indices, which the
  // current band maps may still point into), so only the overlap check applies to it.
  uint64_t covered_to = 0;
  for (size_t i = 0; i < regions.size(); ++i) {
    if (covered_to > regions[i].offset) {
      parse.fail(Code::CorruptData, regions[i - 1].what + " overlaps " + regions[i].what);
    }
    if (!edited) {
      // Between regions there is alignment padding only: anything longer is bytes no field accounts for.
      if (regions[i].offset - covered_to >= kAlignment) {
        parse.fail(Code::CorruptData, std::to_string(regions[i].offset - covered_to) +
                                          " unaccounted bytes before " + regions[i].what);
      }
      if (!Parser::all_zero(base + covered_to, size_t(regions[i].offset - covered_to))) {
        parse.fail(Code::CorruptData, "padding before " + regions[i].what + " is not zero");
      }
    }
    covered_to = regions[i].offset + regions[i].size;
  }
  if (!edited) {
    parse.require(
        recorded_size - covered_to < kAlignment,
        std::to_string(recorded_size - covered_to) + " unaccounted bytes after " + regions.back().what);
    parse.require(Parser::all_zero(base + covered_to, size_t(recorded_size - covered_to)),
                  "padding at the end is not zero");
  }
  return c;
}

const uint8_t* Container::file_bytes(uint64_t offset, uint64_t size) const {
  if (offset > committed_size_ || size > committed_size_ - offset) return nullptr;
  return file_->data() + offset;
}

uint64_t Container::offset_of(const uint8_t* p) const { return uint64_t(p - file_->data()); }

LevelView Container::level(uint32_t level) const {
  if (level >= info_.levels.size()) {
    throw std::out_of_range(path_ + ": level " + std::to_string(level) + " requested, file has " +
                            std::to_string(info_.levels.size()));
  }
  const LevelInfo& li = info_.levels[level];
  return LevelView{file_->data() + li.blob_offset, size_t(li.blob_size), li.width, li.height};
}

std::vector<uint8_t> Container::mask() const {
  if (info_.void_count == 0) return {};
  const uint64_t samples = info_.width * info_.height;
  std::vector<uint8_t> out(static_cast<size_t>(samples));
  mask_runs::expand(mask_runs_, mask_runs_size_, 0, samples, out.data());
  return out;
}

void Container::mask_rows(uint64_t first_row, uint64_t row_count, uint8_t* out) const {
  if (first_row > info_.height || row_count > info_.height - first_row) {
    throw std::out_of_range(path_ + ": mask rows " + std::to_string(first_row) + "+" +
                            std::to_string(row_count) + " requested, grid has " +
                            std::to_string(info_.height));
  }
  const uint64_t count = row_count * info_.width;
  if (info_.void_count == 0) {
    std::memset(out, 1, size_t(count));
  } else {
    mask_runs::expand(mask_runs_, mask_runs_size_, first_row * info_.width, count, out);
  }
}

bool Container::level_checksum_ok(uint32_t level) const {
  const LevelView v = this->level(level);
  const LevelInfo& li = info_.levels[level];
  return !li.has_blob_crc || crc32c(v.data, v.size) == li.blob_crc;
}

void Container::verify() const {
  for (uint32_t l = 0; l < level_count(); ++l) {
    if (!level_checksum_ok(l)) {
      const LevelView v = level(l);
      throw Error(ErrorCode::ChecksumMismatch, path_ + ": level " + std::to_string(l) +
                                                   " blob checksum mismatch (stored " +
                                                   Parser::hex(info_.levels[l].blob_crc) + ", computed " +
                                                   Parser::hex(crc32c(v.data, v.size)) + ")");
    }
  }
}

}  // namespace terrain::container
