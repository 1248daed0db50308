// Images through the image plugin (OpenImageIO, loaded on first use): 16-bit grey PNG/TIFF, float
// TIFF/EXR, Mapbox Terrain-RGB PNG; read scanline band by scanline band, and the 16-bit / float32
// image writers, and the 8-bit writer for pictures.
#include <array>
#include <cmath>
#include <cstring>
#include <vector>

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

ImagePlan plan_image(const std::string& path, const terrain_image_header& header,
                     const ReadOptions& options) {
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
  return plan_image(path, image.header, options).info;
}

std::unique_ptr<BandReader> open_image_reader(const std::string& path, const ReadOptions& options) {
  OpenedImage image = open_image(path);
  ImagePlan plan = plan_image(path, image.header, options);
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
