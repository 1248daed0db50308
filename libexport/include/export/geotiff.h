// A GeoTIFF writer that takes rows as they come (bounded memory for any height), for heightmaps read
// back out of a pyramid. libtiff + libgeotiff from Debian; no GDAL.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "readers/heightmap.h"

namespace terrain {

// Where the raster lies: GDAL's affine geotransform of pixel corners without rotation, x = x0 + col *
// dx and y = y0 - row * dy, in the CRS's units.
struct GeoTransform {
  double x0 = 0, dx = 1;  // west edge of column 0; column width (> 0)
  double y0 = 0, dy = 1;  // north edge of row 0; row height (> 0)
};

struct GeoTiffOptions {
  SampleType type = SampleType::Float32;  // Float32 (voids NaN) or Int16 (voids = nodata)
  std::optional<GeoTransform> geotransform;
  // The CRS: an EPSG code (geographic when `geographic`, else projected), or else CRS text (WKT),
  // written as a user-defined CRS with the citation "ESRI PE String = <text>" that GDAL reads back.
  std::optional<int> epsg;
  bool geographic = true;
  std::string crs_text;
  int16_t int16_nodata = -32768;
  int rows_per_strip = 16;
};

// Writes width x height samples to `path` (deflate-compressed strips, GDAL_NODATA tag, GeoKeys) under
// a temporary name that finish() renames onto `path`; destroying an unfinished writer removes it.
// Throws Error(WriteFailed) naming the file when it cannot be created or written, InvalidOption for
// a type other than Float32 / Int16 or non-positive sizes. One thread at a time.
class GeoTiffWriter {
 public:
  GeoTiffWriter(const std::string& path, int64_t width, int64_t height, const GeoTiffOptions& options);
  ~GeoTiffWriter();
  GeoTiffWriter(const GeoTiffWriter&) = delete;
  GeoTiffWriter& operator=(const GeoTiffWriter&) = delete;
  // Appends `rows` rows of heights (width per row; NaN = void). Int16 files take integers within
  // int16 only: any other value throws Error(InvalidOption) naming the row and column.
  void write_rows(const float* values, int64_t rows);
  // Requires all rows written (else std::logic_error); closes, syncs and renames.
  void finish();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace terrain
