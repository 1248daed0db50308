// GeoTiffWriter (export/geotiff.h): libtiff strips written as rows arrive, GeoKeys through
// libgeotiff, the nodata value in GDAL's private tag so that GDAL and QGIS see the voids.
#include <geotiffio.h>
#include <tiffio.h>
#include <unistd.h>
#include <xtiffio.h>

#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/file.h"
#include "core/text.h"
#include "export/geotiff.h"

namespace terrain {
namespace {

constexpr ttag_t kGdalNodataTag = 42113;  // GDAL_NODATA: the nodata value as ASCII text
const TIFFFieldInfo kGdalNodataField[] = {
    {kGdalNodataTag, -1, -1, TIFF_ASCII, FIELD_CUSTOM, 1, 0, const_cast<char*>("GDALNoDataValue")}};

[[noreturn]] void fail(ErrorCode code, const std::string& path, const std::string& problem) {
  throw Error(code, path + ": " + problem);
}

}  // namespace

struct GeoTiffWriter::Impl {
  std::string path, temp;  // the file is written to `temp` and renamed onto `path` when complete
  TIFF* tif = nullptr;
  int64_t width = 0, height = 0, row = 0;
  GeoTiffOptions options;
  std::vector<int16_t> row16;
  bool committed = false;
  explicit Impl(const std::string& p) : path(p), temp(p + ".tmp." + std::to_string(::getpid())) {}
  [[noreturn]] void fail(const std::string& problem) const {
    terrain::fail(ErrorCode::WriteFailed, path, problem);
  }
};

GeoTiffWriter::GeoTiffWriter(const std::string& path, int64_t width, int64_t height, const GeoTiffOptions& o)
    : impl_(std::make_unique<Impl>(path)) {
  check_output_path(path);
  Impl& m = *impl_;
  if (o.type != SampleType::Float32 && o.type != SampleType::Int16)
    fail(ErrorCode::InvalidOption, path, "GeoTIFF output is float32 or int16");
  if (width < 1 || height < 1 || width > (int64_t(1) << 31) || height > (int64_t(1) << 31))
    fail(ErrorCode::InvalidOption, path,
         "GeoTIFF size " + std::to_string(width) + "x" + std::to_string(height));
  m.width = width, m.height = height, m.options = o;
  m.tif = XTIFFOpen(m.temp.c_str(), height * width > (int64_t(1) << 29) ? "w8" : "w");
  if (!m.tif) m.fail("cannot create");
  TIFFMergeFieldInfo(m.tif, kGdalNodataField, 1);
  const bool f32 = o.type == SampleType::Float32;
  TIFFSetField(m.tif, TIFFTAG_IMAGEWIDTH, uint32_t(width));
  TIFFSetField(m.tif, TIFFTAG_IMAGELENGTH, uint32_t(height));
  TIFFSetField(m.tif, TIFFTAG_SAMPLESPERPIXEL, 1);
  TIFFSetField(m.tif, TIFFTAG_BITSPERSAMPLE, f32 ? 32 : 16);
  TIFFSetField(m.tif, TIFFTAG_SAMPLEFORMAT, f32 ? SAMPLEFORMAT_IEEEFP : SAMPLEFORMAT_INT);
  TIFFSetField(m.tif, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_MINISBLACK);
  TIFFSetField(m.tif, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
  TIFFSetField(m.tif, TIFFTAG_COMPRESSION, COMPRESSION_ADOBE_DEFLATE);
  TIFFSetField(m.tif, TIFFTAG_PREDICTOR, f32 ? PREDICTOR_FLOATINGPOINT : PREDICTOR_HORIZONTAL);
  TIFFSetField(m.tif, TIFFTAG_ROWSPERSTRIP, uint32_t(std::max(1, o.rows_per_strip)));
  const std::string nodata = f32 ? "nan" : std::to_string(o.int16_nodata);
  TIFFSetField(m.tif, kGdalNodataTag, nodata.c_str());
  if (o.geotransform) {
    const GeoTransform& g = *o.geotransform;
    double scale[3] = {g.dx, g.dy, 0.0};
    double tie[6] = {0.0, 0.0, 0.0, g.x0, g.y0, 0.0};
    TIFFSetField(m.tif, TIFFTAG_GEOPIXELSCALE, 3, scale);
    TIFFSetField(m.tif, TIFFTAG_GEOTIEPOINTS, 6, tie);
  }
  GTIF* gtif = GTIFNew(m.tif);
  if (!gtif) m.fail("cannot start the GeoTIFF keys");
  GTIFKeySet(gtif, GTRasterTypeGeoKey, TYPE_SHORT, 1, RasterPixelIsArea);
  if (o.epsg || !o.crs_text.empty()) {
    const int code = o.epsg ? *o.epsg : KvUserDefined;
    GTIFKeySet(gtif, GTModelTypeGeoKey, TYPE_SHORT, 1,
               o.geographic ? ModelTypeGeographic : ModelTypeProjected);
    GTIFKeySet(gtif, o.geographic ? GeographicTypeGeoKey : ProjectedCSTypeGeoKey, TYPE_SHORT, 1, code);
    if (!o.epsg) {
      const std::string citation = "ESRI PE String = " + o.crs_text;
      GTIFKeySet(gtif, GTCitationGeoKey, TYPE_ASCII, 0, citation.c_str());
    }
  }
  const bool keys_written = GTIFWriteKeys(gtif) != 0;
  GTIFFree(gtif);
  if (!keys_written) m.fail("cannot write the GeoTIFF keys");
  if (!f32) m.row16.resize(size_t(width));
}

GeoTiffWriter::~GeoTiffWriter() {
  if (!impl_) return;
  if (impl_->tif) XTIFFClose(impl_->tif);
  if (!impl_->committed) std::remove(impl_->temp.c_str());
}

void GeoTiffWriter::write_rows(const float* values, int64_t rows) {
  Impl& m = *impl_;
  if (rows < 0 || m.row + rows > m.height)
    throw std::logic_error("GeoTiffWriter: more rows than the image has");
  for (int64_t r = 0; r < rows; ++r, ++m.row) {
    const float* v = values + r * m.width;
    void* line = const_cast<float*>(v);
    if (m.options.type == SampleType::Int16) {
      for (int64_t x = 0; x < m.width; ++x) {
        if (std::isnan(v[x])) {
          m.row16[size_t(x)] = m.options.int16_nodata;
          continue;
        }
        if (v[x] != std::nearbyint(v[x]) || v[x] < -32768.0f || v[x] > 32767.0f ||
            int16_t(v[x]) == m.options.int16_nodata)
          fail(ErrorCode::InvalidOption, m.path,
               "height " + shortest(double(v[x])) + " at row " + std::to_string(m.row) + ", column " +
                   std::to_string(x) + " is not an int16 value other than the nodata value (use float32)");
        m.row16[size_t(x)] = int16_t(v[x]);
      }
      line = m.row16.data();
    }
    if (TIFFWriteScanline(m.tif, line, uint32_t(m.row), 0) < 0) m.fail("write error (disk full?)");
  }
}

void GeoTiffWriter::finish() {
  Impl& m = *impl_;
  if (m.row != m.height) throw std::logic_error("GeoTiffWriter::finish before every row was written");
  const bool flushed = TIFFFlush(m.tif) == 1;
  XTIFFClose(m.tif);
  m.tif = nullptr;
  if (!flushed) m.fail("write error (disk full?)");
  check_output_path(m.path);
  if (std::rename(m.temp.c_str(), m.path.c_str()) != 0) m.fail("cannot rename the finished file into place");
  m.committed = true;
}

}  // namespace terrain
