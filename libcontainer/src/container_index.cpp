// The index and superblock bytes, shared by the streaming writer and the copy-on-write editor
// (docs/format.md: "Index", "Superblock").
#include <cstring>

#include "container/internal/container_format.h"

namespace terrain::container::layout {

std::vector<uint8_t> encode_index(const ContainerInfo& info, const IndexPlacement& pl) {
  const size_t level_count = info.levels.size();
  const size_t filter_count = info.filter.size();
  const size_t filter_end = info::kSizeV2_1 + level_count * level::kSizeV1_1 + filter_count * 8;
  const std::string crs_text = info.georeference ? info.georeference->crs_text : std::string();
  const size_t index_size = size_t(align_up(filter_end + crs_text.size()));
  std::vector<uint8_t> index(index_size, 0);
  uint8_t* p = index.data();
  put_u32(p + info::kInfoSize, info::kSizeV2_1);
  put_u32(p + info::kLevelCount, uint32_t(level_count));
  put_u32(p + info::kLevelRecordSize, level::kSizeV1_1);
  put_u32(p + info::kFilterSize, info.filter_size);
  put_u64(p + info::kWidth, info.width);
  put_u64(p + info::kHeight, info.height);
  put_f64(p + info::kSpacingX, info.spacing_x);
  put_f64(p + info::kSpacingY, info.spacing_y);
  put_string(p + info::kHorizontalUnits, info.horizontal_units, info::kUnitsField);
  put_string(p + info::kVerticalUnits, info.vertical_units, info::kUnitsField);
  put_f64(p + info::kVerticalScale, info.vertical_scale);
  put_f64(p + info::kVerticalOffset, info.vertical_offset);
  put_u32(p + info::kHasGeoreference, info.georeference ? 1 : 0);
  put_u32(p + info::kFilterProvenance, uint32_t(info.filter_provenance));
  if (info.georeference) {
    const Georeference& g = *info.georeference;
    put_f64(p + info::kOriginX, g.origin_x());
    put_f64(p + info::kOriginY, g.origin_y());
    put_string(p + info::kGeoreferenceUnits, g.units, info::kUnitsField);
    for (size_t i = 0; i < 6; ++i) put_f64(p + info::kGeotransform + 8 * i, g.geotransform[i]);
    put_u32(p + info::kCrsEpsg, g.crs_epsg);
    put_u32(p + info::kCrsTextSize, uint32_t(crs_text.size()));
    std::memcpy(p + filter_end, crs_text.data(), crs_text.size());
  }
  put_f64(p + info::kStepUnits, info.quantisation.step_units);
  put_f64(p + info::kStepMetres, info.quantisation.step_metres);
  put_u32(p + info::kErrorMode, uint32_t(info.quantisation.mode));
  put_u32(p + info::kMaskEncoding, pl.has_mask ? kMaskRunsLeb128 : kMaskNone);
  put_f64(p + info::kTarget, info.quantisation.target);
  put_u64(p + info::kMaskOffset, pl.has_mask ? pl.mask_offset : 0);
  put_u64(p + info::kMaskSize, pl.mask_size);
  put_u64(p + info::kVoidCount, pl.void_count);
  put_u32(p + info::kMaskCrc, pl.mask_crc);
  put_u32(p + info::kMetadataCrc, pl.metadata_crc);
  put_u64(p + info::kMetadataOffset, pl.metadata_offset);
  put_u64(p + info::kMetadataSize, pl.metadata_size);
  for (size_t l = 0; l < level_count; ++l) {
    uint8_t* r = p + info::kSizeV2_1 + l * level::kSizeV1_1;
    const LevelInfo& li = info.levels[l];
    put_u64(r + level::kWidth, li.width);
    put_u64(r + level::kHeight, li.height);
    put_u64(r + level::kBlobOffset, pl.levels[l].offset);
    put_u64(r + level::kBlobSize, pl.levels[l].size);
    put_u32(r + level::kBlobCrc, pl.levels[l].crc);
    put_u32(r + level::kFlags,
            (pl.levels[l].has_crc ? level::kFlagHasCrc : 0) | (li.error ? level::kFlagHasError : 0));
    put_f64(r + level::kMean, li.stats.mean);
    put_f64(r + level::kVariance, li.stats.variance);
    put_f64(r + level::kRms, li.stats.rms);
    put_f64(r + level::kMin, li.stats.min);
    put_f64(r + level::kMax, li.stats.max);
    if (li.error) {
      put_f64(r + level::kErrorRms, li.error->rms);
      put_f64(r + level::kErrorMax, li.error->max_abs);
    }
  }
  uint8_t* f = p + info::kSizeV2_1 + level_count * level::kSizeV1_1;
  for (size_t i = 0; i < filter_count; ++i) put_f64(f + 8 * i, info.filter[i]);
  return index;
}

std::array<uint8_t, sb::kSizeV1> encode_superblock(const SuperblockFields& fields) {
  std::array<uint8_t, sb::kSizeV1> out{};
  uint8_t* super = out.data();
  std::memcpy(super, kMagic, sizeof kMagic);
  put_u16(super + sb::kMajor, kFormatMajor);
  put_u16(super + sb::kMinor, kFormatMinor);
  put_u32(super + sb::kSize, sb::kSizeV1);
  put_u64(super + sb::kFileSize, fields.file_size);
  put_u64(super + sb::kIndexOffset, fields.index_offset);
  put_u64(super + sb::kIndexSize, fields.index_size);
  put_u32(super + sb::kIndexCrc, fields.index_crc);
  put_u32(super + sb::kFlags, fields.flags);
  if (fields.flags & sb::kFlagEdited) put_u64(super + sb::kGeneration, fields.generation);
  put_u32(super + sb::kCrc, crc32c(super, sb::kCrc));
  return out;
}

std::array<uint8_t, sb::kSizeV1> encode_pending(uint64_t committed_size, uint64_t generation) {
  std::array<uint8_t, sb::kSizeV1> out{};
  std::memcpy(out.data(), kPendingMagic, sizeof kPendingMagic);
  put_u64(out.data() + 8, committed_size);
  put_u64(out.data() + 16, generation);
  put_u32(out.data() + sb::kCrc, crc32c(out.data(), sb::kCrc));
  return out;
}

}  // namespace terrain::container::layout
