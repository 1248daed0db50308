// Images through the image plugin (OpenImageIO, loaded on first use): 16-bit grey PNG/TIFF, float
// TIFF/EXR, Mapbox Terrain-RGB PNG; read scanline band by scanline band, and the 16-bit / float32
// image writers, and the 8-bit writer for pictures.
#include <array>
#include <charconv>
#include <cmath>
#include <cstring>
#include <vector>

#include "core/text.h"
#include "readers/image8.h"
#include "readers/internal/image_plugin.h"
#include "readers/internal/io_internal.h"

namespace terrain::io {
namespace {

using Message = std::array<char, kImageMessageSize>;

// How an opened image maps onto a grid: which channels to read, as what, and what they mean.
struct ImagePlan {
  GridInfo info;
  int32_t read_pixel =
      TERRAIN_PIXEL_OTHER;  // native type requested from the plugin, so it does no value conversion
  size_t read_bytes = 0;    // bytes per sample of read_pixel
  int channels = 1;         // channels read per pixel (1, or 3 for Terrain-RGB)
};

struct OpenedImage {
  const ImagePlugin* plugin = nullptr;
  ImageReaderHandle reader;
  terrain_image_header header{};
};

OpenedImage open_image(const std::string& path) {
  existing_file_size(path);  // NotFound with a clear message before the decoder's own
  OpenedImage image;
  image.plugin = &image_plugin(ErrorCode::UnknownType, path);
  Message message{};
  terrain_image_reader* reader = nullptr;
  const int32_t status =
      image.plugin->open(path.c_str(), &reader, &image.header, message.data(), message.size());
  image.reader = ImageReaderHandle(reader, {image.plugin->close});
  if (status != TERRAIN_IMAGE_OK)
    fail(ErrorCode::CorruptData, path, "cannot decode image: " + std::string(message.data()));
  return image;
}

// GeoTIFF georeference (tags read by the plugin) into g: origin, spacing and units, CRS, nodata.
// Throws MissingField naming the file and the tag for values no stage could use.
void apply_geotiff(const std::string& path, const terrain_image_georef& t, GridInfo& g) {
  const auto bad = [&](const std::string& field, const std::string& rule) {
    fail(ErrorCode::MissingField, path, "GeoTIFF " + field + " " + rule);
  };
  if (t.has_nodata) {
    const std::string text = t.nodata;
    double v = 0;
    size_t begin = text.find_first_not_of(" \t");
    if (begin == std::string::npos) bad("GDAL_NODATA", "is empty");
    const std::string value = text.substr(begin, text.find_last_not_of(" \t") + 1 - begin);
    const auto res = std::from_chars(value.data(), value.data() + value.size(), v);
    if (to_lower(value) == "nan")
      g.nodata = std::nan("");
    else if (res.ec != std::errc() || res.ptr != value.data() + value.size() || !std::isfinite(v))
      bad("GDAL_NODATA", "is not a number: \"" + text + "\"");
    else
      g.nodata = v;
  }
  std::array<double, 6> gt{};  // GDAL order, pixel corners once PixelIsPoint is accounted for
  std::string field;           // the tag gt came from, for messages
  const auto all_finite = [](const double* v, int n) {
    for (int i = 0; i < n; ++i)
      if (!std::isfinite(v[i])) return false;
    return true;
  };
  if (t.transformation_count > 0) {
    field = "ModelTransformation";
    if (t.transformation_count != 16)
      bad(field, "has " + std::to_string(t.transformation_count) + " values, not 16");
    const double* m = t.transformation;
    if (!all_finite(m, 16)) bad(field, "must be finite");
    gt = {m[3], m[0], m[1], m[7], m[4], m[5]};
  } else if (t.tiepoint_count > 0 || t.pixel_scale_count > 0) {
    field = "ModelTiepoint";
    if (t.tiepoint_count > 6)
      bad(field,
          "has " + std::to_string(t.tiepoint_count / 6) +
              " tiepoints: ground control points are not supported (one tiepoint and ModelPixelScale)");
    if (t.tiepoint_count != 6) bad(field, "has " + std::to_string(t.tiepoint_count) + " values, not 6");
    if (!all_finite(t.tiepoint, 6)) bad(field, "must be finite");
    if (t.pixel_scale_count < 2) bad("ModelPixelScale", "is missing or has fewer than 2 values");
    if (!all_finite(t.pixel_scale, 2) || t.pixel_scale[0] == 0 || t.pixel_scale[1] == 0)
      bad("ModelPixelScale", "must be finite and non-zero (" + format_double(t.pixel_scale[0]) + ", " +
                                 format_double(t.pixel_scale[1]) + ")");
    const double* tp = t.tiepoint;
    const double sx = t.pixel_scale[0], sy = t.pixel_scale[1];
    gt = {tp[3] - tp[0] * sx, sx, 0.0, tp[4] + tp[1] * sy, 0.0, -sy};
  } else {
    return;  // no georeference
  }
  if (gt[2] != 0 || gt[4] != 0)
    bad(field, "has rotation terms (" + format_double(gt[2]) + ", " + format_double(gt[4]) +
                   "): rotated grids are not supported");
  if (!(gt[1] > 0 && gt[5] < 0))
    bad(field, "pixel size " + format_double(gt[1]) + " x " + format_double(gt[5]) +
                   " is not north-up with columns east (x > 0, y < 0): flipped grids are not supported");
  // PixelIsPoint: the tags place pixel centres, so the corners lie half a pixel up and left.
  if (t.raster_type == 2) {
    gt[0] -= 0.5 * gt[1];
    gt[3] -= 0.5 * gt[5];
  }
  const bool geographic = t.model_type == 2;
  const int code = geographic ? t.geographic_type : t.model_type == 1 ? t.projected_type : 0;
  if (code >= 1 && code < 32767) g.crs_epsg = code;
  if (t.citation_truncated) bad("citation", "is longer than " + std::to_string(kMaxCrsTextBytes) + " bytes");
  const std::string citation = t.citation;
  const std::string esri = "ESRI PE String = ";
  if (!g.crs_epsg) {
    if (citation.rfind(esri, 0) == 0)
      g.crs_text = citation.substr(esri.size());
    else if (citation.rfind("PROJCS[", 0) == 0 || citation.rfind("GEOGCS[", 0) == 0)
      g.crs_text = citation;
    if (!g.crs_text.empty()) g.crs_epsg = epsg_from_wkt(g.crs_text);
  }
  const double per_unit = geographic ? 3600.0 : 1.0;  // spacing in arc-seconds for degrees
  g.horizontal_units = geographic ? "arc-second" : "m";
  g.spacing_x = gt[1] * per_unit;
  g.spacing_y = -gt[5] * per_unit;
  g.origin_x = gt[0] + 0.5 * gt[1];
  g.origin_y = gt[3] + 0.5 * gt[5];
  if (!std::isfinite(*g.origin_x) || !std::isfinite(*g.origin_y) || !std::isfinite(g.spacing_x) ||
      !std::isfinite(g.spacing_y))
    bad(field, "gives a non-finite origin or pixel size");
}

ImagePlan plan_image(const std::string& path, const OpenedImage& image, const ReadOptions& options) {
  const terrain_image_header& header = image.header;
  ImagePlan plan;
  GridInfo& g = plan.info;
  g.width = header.width;
  g.height = header.height;
  g.format = FileFormat::Image;
  if (header.width <= 0 || header.height <= 0 || header.depth > 1)
    fail(ErrorCode::DimensionMismatch, path, "image has no usable 2-D size");
  check_row_width(path, header.width);
  if (header.decode_unit_bytes > kMaxImageDecodeBytes)
    fail(ErrorCode::DimensionMismatch, path,
         "decoding it needs " + std::to_string(header.decode_unit_bytes) +
             " bytes at once (one strip or row of tiles, or the whole of an interlaced PNG); the limit "
             "is " +
             std::to_string(kMaxImageDecodeBytes) +
             " (docs/io.md, \"Limits\"): store it in smaller strips or tiles, or not interlaced");
  const int32_t fmt = header.pixel;
  const std::string fmt_name = header.pixel_name;
  const bool rgb8 = fmt == TERRAIN_PIXEL_UINT8 && (header.channels == 3 || header.channels == 4);
  const bool is_png = ends_with_ci(path, ".png");
  if (options.terrain_rgb || (rgb8 && is_png)) {
    if (!rgb8)
      fail(ErrorCode::UnknownType, path,
           "Terrain-RGB needs an 8-bit RGB or RGBA image, this one has " + std::to_string(header.channels) +
               " channels of " + fmt_name);
    g.format = FileFormat::TerrainRgbImage;
    g.sample_type = SampleType::TerrainRGB;
    // value = R*65536 + G*256 + B stays an exact integer; metres = value * 0.1 - 10000.
    g.vertical_scale = 0.1;
    g.vertical_offset = -10000.0;
    plan.read_pixel = TERRAIN_PIXEL_UINT8;
    plan.read_bytes = 1;
    plan.channels = 3;
  } else {
    if (header.channels != 1 && header.channels != 2)
      fail(ErrorCode::UnknownType, path,
           std::to_string(header.channels) + "-channel " + fmt_name +
               " image: expected one grey channel (or 8-bit RGB with --terrain-rgb)");
    if (fmt == TERRAIN_PIXEL_UINT16 || fmt == TERRAIN_PIXEL_UINT8) {
      g.sample_type = SampleType::UInt16;  // 8-bit grey is widened: there is no 8-bit sample type
      plan.read_pixel = fmt;
      plan.read_bytes = fmt == TERRAIN_PIXEL_UINT8 ? 1 : 2;
    } else if (fmt == TERRAIN_PIXEL_INT16) {
      g.sample_type = SampleType::Int16;
      plan.read_pixel = TERRAIN_PIXEL_INT16;
      plan.read_bytes = 2;
    } else if (fmt == TERRAIN_PIXEL_INT32) {
      g.sample_type = SampleType::Int32;
      plan.read_pixel = TERRAIN_PIXEL_INT32;
      plan.read_bytes = 4;
    } else if (fmt == TERRAIN_PIXEL_FLOAT || fmt == TERRAIN_PIXEL_HALF) {
      g.sample_type = SampleType::Float32;  // half widens to float exactly
      plan.read_pixel = TERRAIN_PIXEL_FLOAT;
      plan.read_bytes = 4;
    } else {
      fail(ErrorCode::UnknownType, path, "unsupported pixel type " + fmt_name);
    }
    plan.channels = 1;
  }
  terrain_image_georef georef{};
  Message message{};
  if (image.plugin->read_georef(image.reader.get(), &georef, message.data(), message.size()) !=
      TERRAIN_IMAGE_OK)
    fail(ErrorCode::CorruptData, path, "cannot read the GeoTIFF tags: " + std::string(message.data()));
  apply_geotiff(path, georef, g);
  apply_common_overrides(g, options);
  return plan;
}

class ImageBandReader final : public BandReader {
 public:
  ImageBandReader(std::string path, OpenedImage image, const ImagePlan& plan)
      : path_(std::move(path)), image_(std::move(image)), plan_(plan) {
    if (plan_.info.nodata) {
      nodata_as_float_ = float(*plan_.info.nodata);
      std::memcpy(&nodata_float_bits_, &nodata_as_float_, sizeof nodata_float_bits_);
    }
  }
  const GridInfo& info() const override { return plan_.info; }

  int64_t read_rows(int64_t rows, double* values, uint8_t* valid) override {
    const GridInfo& g = plan_.info;
    int64_t n = std::min(rows, g.height - rows_read_);
    if (n <= 0) return 0;
    const size_t row_bytes = plan_.read_bytes * size_t(plan_.channels) * size_t(g.width);
    if (rows_read_ < buffer_y0_ || rows_read_ >= buffer_y1_) {
      // Read ahead: a plugin call per row costs the image library a buffer allocation (and under
      // ASan a page-faulted mmap) each time; callers that read one row at a time were 35 s per DEM.
      // At most kReadAheadRows rows, whatever the caller asks for (fewer rows come back then): the
      // buffer stays small, and so does OpenImageIO's log of an error per row it fails to decode,
      // which aborts the process past 16 MB within one call.
      const int64_t ahead =
          std::min(kReadAheadRows, int64_t(std::max<size_t>(1, kReadAheadBytes / row_bytes)));
      const int64_t m = std::min(ahead, g.height - rows_read_);
      if (buffer_.size() < size_t(m) * row_bytes) buffer_.resize(size_t(m) * row_bytes);
      if (image_.plugin->read_rows(image_.reader.get(), int32_t(rows_read_), int32_t(rows_read_ + m),
                                   plan_.channels, plan_.read_pixel, buffer_.data(), message_.data(),
                                   message_.size()) != TERRAIN_IMAGE_OK)
        fail(ErrorCode::CorruptData, path_,
             "cannot decode rows " + std::to_string(rows_read_) + ".." + std::to_string(rows_read_ + m - 1) +
                 ": " + message_.data());
      buffer_y0_ = rows_read_;
      buffer_y1_ = rows_read_ + m;
    }
    n = std::min(n, buffer_y1_ - rows_read_);
    const int64_t count = n * g.width;
    const bool has_nodata = g.nodata.has_value();
    const double nodata = has_nodata ? *g.nodata : 0.0;
    auto store = [&](int64_t i, double v) {
      bool is_void = has_nodata && v == nodata;
      values[i] = is_void ? 0.0 : v;
      valid[i] = is_void ? 0 : 1;
    };
    const uint8_t* b = buffer_.data() + size_t(rows_read_ - buffer_y0_) * row_bytes;
    if (plan_.info.sample_type == SampleType::TerrainRGB) {
      for (int64_t i = 0; i < count; ++i)
        store(i, double(uint32_t(b[3 * i]) << 16 | uint32_t(b[3 * i + 1]) << 8 | uint32_t(b[3 * i + 2])));
    } else if (plan_.read_pixel == TERRAIN_PIXEL_UINT8) {
      for (int64_t i = 0; i < count; ++i) store(i, double(b[i]));
    } else if (plan_.read_pixel == TERRAIN_PIXEL_UINT16) {
      for (int64_t i = 0; i < count; ++i) {
        uint16_t v;
        std::memcpy(&v, b + 2 * i, 2);
        store(i, double(v));
      }
    } else if (plan_.read_pixel == TERRAIN_PIXEL_INT16) {
      for (int64_t i = 0; i < count; ++i) {
        int16_t v;
        std::memcpy(&v, b + 2 * i, 2);
        store(i, double(v));
      }
    } else if (plan_.read_pixel == TERRAIN_PIXEL_INT32) {
      for (int64_t i = 0; i < count; ++i) {
        int32_t v;
        std::memcpy(&v, b + 4 * i, 4);
        store(i, double(v));
      }
    } else {
      for (int64_t i = 0; i < count; ++i) {
        float f;
        std::memcpy(&f, b + 4 * i, 4);
        uint32_t bits;
        std::memcpy(&bits, &f, 4);
        // A NaN nodata value is matched by bit pattern, since NaN never compares equal.
        bool is_void = has_nodata && (bits == nodata_float_bits_ || f == nodata_as_float_);
        if (!is_void && !std::isfinite(f))
          fail(ErrorCode::NonFinite, path_,
               std::string(std::isnan(f) ? "NaN" : "Inf") + " at row " +
                   std::to_string(rows_read_ + i / g.width) + ", column " + std::to_string(i % g.width));
        values[i] = is_void ? 0.0 : double(f);
        valid[i] = is_void ? 0 : 1;
      }
    }
    rows_read_ += n;
    return n;
  }

 private:
  std::string path_;
  OpenedImage image_;
  ImagePlan plan_;
  static constexpr size_t kReadAheadBytes = size_t(1) << 20;
  static constexpr int64_t kReadAheadRows = 1024;
  std::vector<uint8_t> buffer_;  // rows [buffer_y0_, buffer_y1_) as the plugin delivered them
  int64_t buffer_y0_ = 0, buffer_y1_ = 0;
  Message message_{};
  float nodata_as_float_ = 0;
  uint32_t nodata_float_bits_ = 0;
};

// An image file being written through the plugin; each step returns the plugin's status, with its
// reason in message(). Destroying it before finish() abandons the file.
class PluginImageWriter {
 public:
  explicit PluginImageWriter(const ImagePlugin& plugin)
      : plugin_(plugin), writer_(nullptr, {plugin.destroy}) {}
  int32_t create(const std::string& file, int64_t width, int64_t height, int channels, int32_t pixel,
                 const char* compression, int32_t flags) {
    terrain_image_writer* writer = nullptr;
    const int32_t status = plugin_.create(file.c_str(), int32_t(width), int32_t(height), channels, pixel,
                                          compression, flags, &writer, message_.data(), message_.size());
    writer_.reset(writer);
    return status;
  }
  int32_t write_rows(int64_t row_begin, int64_t row_end, const void* pixels) {
    return plugin_.write_rows(writer_.get(), int32_t(row_begin), int32_t(row_end), pixels, message_.data(),
                              message_.size());
  }
  int32_t finish() { return plugin_.finish(writer_.get(), message_.data(), message_.size()); }
  std::string message() const { return message_.data(); }

 private:
  const ImagePlugin& plugin_;
  ImageWriterHandle writer_;
  Message message_{};
};

// Writes `map` band by band as `pixel` (one channel), converting each value with `convert`.
template <typename T, typename Convert>
void write_image_bands(const std::string& path, const Heightmap& map, int32_t pixel, const char* compression,
                       Convert convert) {
  const GridInfo& g = map.info;
  if (g.width <= 0 || g.height <= 0 || map.values.size() != size_t(g.width * g.height))
    fail(ErrorCode::WriteFailed, path, "heightmap dimensions do not match its sample count");
  if (g.width > (int64_t(1) << 30) || g.height > (int64_t(1) << 30))
    fail(ErrorCode::WriteFailed, path, "image too large");
  // Convert (and so validate) every value before creating anything, so a refused grid leaves no file.
  for (int64_t y = 0; y < g.height; ++y)
    for (int64_t x = 0; x < g.width; ++x) convert(value_for_writing(map, x, y, path), x, y);
  AtomicOutput target(path);
  PluginImageWriter out(
      image_plugin(ErrorCode::WriteFailed, path));  // closed before the temporary is removed
  const int32_t created =
      out.create(target.temp_path(), g.width, g.height, 1, pixel, compression, TERRAIN_IMAGE_NO_TIMESTAMP);
  if (created == TERRAIN_IMAGE_NO_WRITER)
    fail(ErrorCode::WriteFailed, path, "no image writer for this extension: " + out.message());
  if (created != TERRAIN_IMAGE_OK) fail(ErrorCode::WriteFailed, path, "cannot create: " + out.message());
  constexpr int64_t kBandRows = 64;
  std::vector<T> band(size_t(std::min<int64_t>(kBandRows, g.height) * g.width));
  for (int64_t y0 = 0; y0 < g.height; y0 += kBandRows) {
    int64_t n = std::min(kBandRows, g.height - y0);
    for (int64_t y = y0; y < y0 + n; ++y)
      for (int64_t x = 0; x < g.width; ++x)
        band[size_t((y - y0) * g.width + x)] = convert(value_for_writing(map, x, y, path), x, y);
    if (out.write_rows(y0, y0 + n, band.data()) != TERRAIN_IMAGE_OK)
      fail(ErrorCode::WriteFailed, path, "write error: " + out.message());
  }
  if (out.finish() != TERRAIN_IMAGE_OK)
    fail(ErrorCode::WriteFailed, path, "write error on close: " + out.message());
  target.commit();
}

}  // namespace

GridInfo probe_image(const std::string& path, const ReadOptions& options) {
  OpenedImage image = open_image(path);
  return plan_image(path, image, options).info;
}

std::unique_ptr<BandReader> open_image_reader(const std::string& path, const ReadOptions& options) {
  OpenedImage image = open_image(path);
  ImagePlan plan = plan_image(path, image, options);
  return std::make_unique<ImageBandReader>(path, std::move(image), plan);
}

}  // namespace terrain::io

namespace terrain {

void write_image16(const std::string& path, const Heightmap& map) {
  const bool is_tiff = io::ends_with_ci(path, ".tif") || io::ends_with_ci(path, ".tiff");
  if (!is_tiff && !io::ends_with_ci(path, ".png"))
    io::fail(ErrorCode::WriteFailed, path, "16-bit images are written as .png, .tif or .tiff");
  // Signed data goes to an int16 TIFF; PNG only holds unsigned samples.
  bool any_negative = false;
  for (int64_t y = 0; y < map.height() && !any_negative; ++y)
    for (int64_t x = 0; x < map.width(); ++x)
      if (map.is_valid(x, y) ? map.at(x, y) < 0 : (map.info.nodata && *map.info.nodata < 0)) {
        any_negative = true;
        break;
      }
  const bool write_signed = is_tiff && (any_negative || map.info.sample_type == SampleType::Int16);
  const double lo = write_signed ? -32768 : 0, hi = write_signed ? 32767 : 65535;
  auto check = [&](double v, int64_t x, int64_t y) {
    if (!(v >= lo && v <= hi) || v != std::floor(v))
      io::fail(ErrorCode::WriteFailed, path,
               "value " + io::format_double(v) + " at row " + std::to_string(y) + ", column " +
                   std::to_string(x) + " does not fit a " + (write_signed ? "signed" : "unsigned") +
                   " 16-bit " + (is_tiff ? "TIFF" : "PNG"));
    return v;
  };
  const char* compression = is_tiff ? "zip" : nullptr;
  if (write_signed)
    io::write_image_bands<int16_t>(path, map, TERRAIN_PIXEL_INT16, compression,
                                   [&](double v, int64_t x, int64_t y) { return int16_t(check(v, x, y)); });
  else
    io::write_image_bands<uint16_t>(path, map, TERRAIN_PIXEL_UINT16, compression,
                                    [&](double v, int64_t x, int64_t y) { return uint16_t(check(v, x, y)); });
}

void write_exr(const std::string& path, const Heightmap& map) {
  if (!io::ends_with_ci(path, ".exr"))
    io::fail(ErrorCode::WriteFailed, path, "float images are written as .exr");
  io::write_image_bands<float>(path, map, TERRAIN_PIXEL_FLOAT, "zip", [&](double v, int64_t x, int64_t y) {
    float f = float(v);
    if (double(f) != v && !std::isnan(v))
      io::fail(ErrorCode::WriteFailed, path,
               "value " + io::format_double(v) + " at row " + std::to_string(y) + ", column " +
                   std::to_string(x) + " is not exactly representable as float32");
    return f;
  });
}

void write_image8(const std::string& path, int width, int height, int channels, const uint8_t* pixels) {
  if (width < 1 || height < 1 || channels < 1 || channels > 4 || !pixels)
    io::fail(ErrorCode::WriteFailed, path, "no pixels, or not 1 to 4 channels");
  io::AtomicOutput target(path);  // a failed write leaves no partial picture under the final name
  {
    io::PluginImageWriter out(io::image_plugin(ErrorCode::WriteFailed, path));
    if (out.create(target.temp_path(), width, height, channels, TERRAIN_PIXEL_UINT8, nullptr, 0) !=
            TERRAIN_IMAGE_OK ||
        out.write_rows(0, height, pixels) != TERRAIN_IMAGE_OK || out.finish() != TERRAIN_IMAGE_OK)
      io::fail(ErrorCode::WriteFailed, path, out.message());
  }
  target.commit();
}

}  // namespace terrain
