// Byte layout of the container (see docs/format.md, which this file must match) and the
// little-endian field helpers shared by the writer and the reader.
#pragma once

#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "container/container.h"
#include "core/bytes.h"

namespace terrain::container::layout {

inline constexpr uint8_t kMagic[8] = {0x89, 'T', 'P', 'Y', 'R', '\r', '\n', 0x1A};
inline constexpr uint64_t kAlignment = 8;

// Superblock at offset 0. Magic, version and superblock size keep their places in every version;
// the superblock CRC is always its last 4 bytes and covers every byte before them.
namespace sb {
inline constexpr size_t kMajor = 8, kMinor = 10, kSize = 12, kFileSize = 16, kIndexOffset = 24,
                        kIndexSize = 32, kIndexCrc = 40, kFlags = 44, kReserved = 48, kCrc = 60;
inline constexpr uint32_t kSizeV1 = 64;
// 2.2: flag bit 0 = edited (copy-on-write generations: dead bytes allowed between regions, a tail copy
// of the superblock ends the file); the u64 edit generation sits at kGeneration (0 in unedited files).
inline constexpr uint32_t kFlagEdited = 1;
inline constexpr size_t kGeneration = 48;
}  // namespace sb

// Index "info" block at the start of the index.
namespace info {
inline constexpr size_t kInfoSize = 0, kLevelCount = 4, kLevelRecordSize = 8, kFilterSize = 12, kWidth = 16,
                        kHeight = 24, kSpacingX = 32, kSpacingY = 40, kHorizontalUnits = 48,
                        kVerticalUnits = 80, kVerticalScale = 112, kVerticalOffset = 120,
                        kHasGeoreference = 128, kFilterProvenance = 132, kOriginX = 136, kOriginY = 144,
                        kGeoreferenceUnits = 152, kStepUnits = 184, kStepMetres = 192, kErrorMode = 200,
                        kMaskEncoding = 204, kTarget = 208, kMaskOffset = 216, kMaskSize = 224,
                        kVoidCount = 232, kMaskCrc = 240, kMetadataCrc = 244, kMetadataOffset = 248,
                        kMetadataSize = 256;
inline constexpr uint32_t kSizeV1 = 264;  // versions 1.x and 2.0
// Version 2.1: the georeference's geotransform (6 f64, GDAL order), its CRS's EPSG code and the size
// of its CRS text, which follows the filter coefficients at the end of the index (zero-padded to 8).
inline constexpr size_t kGeotransform = 264, kCrsEpsg = 312, kCrsTextSize = 316;
inline constexpr uint32_t kSizeV2_1 = 320;
inline constexpr size_t kUnitsField = 32;
}  // namespace info

// One record per level, following the info block; then filter_size^2 f64 coefficients.
namespace level {
inline constexpr size_t kWidth = 0, kHeight = 8, kBlobOffset = 16, kBlobSize = 24, kBlobCrc = 32, kFlags = 36,
                        kMean = 40, kVariance = 48, kRms = 56, kMin = 64, kMax = 72, kErrorRms = 80,
                        kErrorMax = 88;    // version 1.1
inline constexpr uint32_t kSizeV1_1 = 96;  // versions 1.1 and 2.0 (1.0 records ended at kErrorRms)
inline constexpr uint32_t kFlagHasCrc = 1;
inline constexpr uint32_t kFlagHasError = 2;  // version 1.1: error_rms and error_max are recorded
}  // namespace level

inline constexpr uint32_t kMaskNone = 0;  // no voids: mask size 0
inline constexpr uint32_t kMaskRunsLeb128 = 1;

using bytes::put_f64;
using bytes::put_u16;
using bytes::put_u32;
using bytes::put_u64;
// Writes s NUL-padded into a field of `field` bytes; the caller has checked s.size() < field.
inline void put_string(uint8_t* p, const std::string& s, size_t field) {
  std::memset(p, 0, field);
  std::memcpy(p, s.data(), s.size());
}

using bytes::get_f64;
using bytes::get_u16;
using bytes::get_u32;
using bytes::get_u64;

inline uint64_t align_up(uint64_t v) { return (v + kAlignment - 1) & ~(kAlignment - 1); }

// Where the index says each region is (the writer's and the editor's placement of the blobs).
struct BlobPlacement {
  uint64_t offset = 0, size = 0;
  uint32_t crc = 0;
  bool has_crc = false;
};
struct IndexPlacement {
  std::vector<BlobPlacement> levels;  // one per info.levels entry
  bool has_mask = false;
  uint64_t mask_offset = 0, mask_size = 0, void_count = 0;
  uint32_t mask_crc = 0;
  uint64_t metadata_offset = 0, metadata_size = 0;
  uint32_t metadata_crc = 0;
};
// The index bytes (info block, level records, filter, CRS text; 8-aligned size) of the current version.
std::vector<uint8_t> encode_index(const ContainerInfo& info, const IndexPlacement& placement);

struct SuperblockFields {
  uint64_t file_size = 0, index_offset = 0, index_size = 0;
  uint32_t index_crc = 0;
  uint32_t flags = 0;       // sb::kFlagEdited
  uint64_t generation = 0;  // with kFlagEdited only
};
std::array<uint8_t, sb::kSizeV1> encode_superblock(const SuperblockFields& fields);

// 2.2: the record an edit writes (and syncs) at align_up(file_size) before any other byte past the
// committed end, so that what a crash leaves there is recognisable: 8-byte magic, u64 the committed
// file_size it follows, u64 the generation being written, zeros, u32 CRC-32C of bytes 0..59. It is
// a function of those two numbers alone, so a reader can tell a torn copy of it from garbage.
inline constexpr uint8_t kPendingMagic[8] = {0x89, 'T', 'P', 'E', 'D', 'I', 'T', 0x1A};
std::array<uint8_t, sb::kSizeV1> encode_pending(uint64_t committed_size, uint64_t generation);

}  // namespace terrain::container::layout
