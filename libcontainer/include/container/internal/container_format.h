// Byte layout of the container (see docs/format.md, which this file must match) and the
// little-endian field helpers shared by the writer and the reader.
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>

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

}  // namespace terrain::container::layout
