// Images through OpenImageIO: 16-bit grey PNG/TIFF, float TIFF/EXR, Mapbox Terrain-RGB PNG;
// read scanline band by scanline band, and the 16-bit / float32 image writers.
#include <OpenImageIO/imageio.h>

#include <cmath>
#include <cstring>
#include <vector>

#include "io_internal.h"

namespace terrain::io {
namespace {

using OIIO::ImageInput;
using OIIO::ImageOutput;
using OIIO::ImageSpec;
using OIIO::TypeDesc;

// How an opened image maps onto a grid: which channels to read, as what, and what they mean.
struct ImagePlan {
  GridInfo info;
  TypeDesc read_type;  // native type requested from OIIO, so it does no value conversion
  int channels = 1;    // channels read per pixel (1, or 3 for Terrain-RGB)
};

std::unique_ptr<ImageInput> open_image(const std::string& path) {
  existing_file_size(path);  // NotFound with a clear message before OIIO's own
  ImageSpec config;
  // Keep RGB exactly as stored: by default OIIO premultiplies by alpha, which would corrupt Terrain-RGB codes.
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto in = ImageInput::open(path, &config);
  if (!in) {
    std::string err = OIIO::geterror();
    fail(IoErrorCode::CorruptData, path, "cannot decode image: " + (err.empty() ? std::string("unknown error") : err));
  }
  return in;
}

ImagePlan plan_image(const std::string& path, const ImageSpec& spec, const ReadOptions& options) {
  ImagePlan plan;
  GridInfo& g = plan.info;
  g.width = spec.width;
  g.height = spec.height;
  g.format = FileFormat::Image;
  if (spec.width <= 0 || spec.height <= 0 || spec.depth > 1)
    fail(IoErrorCode::DimensionMismatch, path, "image has no usable 2-D size");
  const TypeDesc fmt = spec.format;
  const bool rgb8 = fmt == TypeDesc::UINT8 && (spec.nchannels == 3 || spec.nchannels == 4);
  const bool is_png = ends_with_ci(path, ".png");
  if (options.terrain_rgb || (rgb8 && is_png)) {
    if (!rgb8)
      fail(IoErrorCode::UnknownType, path,
           "Terrain-RGB needs an 8-bit RGB or RGBA image, this one has " + std::to_string(spec.nchannels) + " channels of " +
               fmt.c_str());
    g.format = FileFormat::TerrainRgbImage;
    g.sample_type = SampleType::TerrainRGB;
    // value = R*65536 + G*256 + B stays an exact integer; metres = value * 0.1 - 10000.
    g.vertical_scale = 0.1;
    g.vertical_offset = -10000.0;
    plan.read_type = TypeDesc::UINT8;
    plan.channels = 3;
  } else {
    if (spec.nchannels != 1 && spec.nchannels != 2)
      fail(IoErrorCode::UnknownType, path,
           std::to_string(spec.nchannels) + "-channel " + fmt.c_str() +
               " image: expected one grey channel (or 8-bit RGB with --terrain-rgb)");
    if (fmt == TypeDesc::UINT16 || fmt == TypeDesc::UINT8) {
      g.sample_type = SampleType::UInt16;  // 8-bit grey is widened: there is no 8-bit sample type
      plan.read_type = fmt;
    } else if (fmt == TypeDesc::INT16) {
      g.sample_type = SampleType::Int16;
      plan.read_type = TypeDesc::INT16;
    } else if (fmt == TypeDesc::INT32) {
      g.sample_type = SampleType::Int32;
      plan.read_type = TypeDesc::INT32;
    } else if (fmt == TypeDesc::FLOAT || fmt == TypeDesc::HALF) {
      g.sample_type = SampleType::Float32;  // half widens to float exactly
      plan.read_type = TypeDesc::FLOAT;
    } else {
      fail(IoErrorCode::UnknownType, path, std::string("unsupported pixel type ") + fmt.c_str());
    }
    plan.channels = 1;
  }
  apply_common_overrides(g, options);
  return plan;
}

class ImageBandReader final : public BandReader {
 public:
  ImageBandReader(std::string path, std::unique_ptr<ImageInput> in, const ImagePlan& plan)
      : path_(std::move(path)), in_(std::move(in)), plan_(plan) {
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
    const size_t pixel_bytes = plan_.read_type.size() * size_t(plan_.channels);
    const size_t want = size_t(n) * size_t(g.width) * pixel_bytes;
    if (buffer_.size() < want) buffer_.resize(want);
    const int y0 = in_->spec().y + int(rows_read_);
    if (!in_->read_scanlines(0, 0, y0, y0 + int(n), 0, 0, plan_.channels, plan_.read_type, buffer_.data())) {
      std::string err = in_->geterror();
      fail(IoErrorCode::CorruptData, path_,
           "cannot decode rows " + std::to_string(rows_read_) + ".." + std::to_string(rows_read_ + n - 1) + ": " + err);
    }
    const int64_t count = n * g.width;
    const bool has_nodata = g.nodata.has_value();
    const double nodata = has_nodata ? *g.nodata : 0.0;
    auto store = [&](int64_t i, double v) {
      bool is_void = has_nodata && v == nodata;
      values[i] = is_void ? 0.0 : v;
      valid[i] = is_void ? 0 : 1;
    };
    const uint8_t* b = buffer_.data();
    if (plan_.info.sample_type == SampleType::TerrainRGB) {
      for (int64_t i = 0; i < count; ++i)
        store(i, double(uint32_t(b[3 * i]) << 16 | uint32_t(b[3 * i + 1]) << 8 | uint32_t(b[3 * i + 2])));
    } else if (plan_.read_type == TypeDesc::UINT8) {
      for (int64_t i = 0; i < count; ++i) store(i, double(b[i]));
    } else if (plan_.read_type == TypeDesc::UINT16) {
      for (int64_t i = 0; i < count; ++i) {
        uint16_t v;
        std::memcpy(&v, b + 2 * i, 2);
        store(i, double(v));
      }
    } else if (plan_.read_type == TypeDesc::INT16) {
      for (int64_t i = 0; i < count; ++i) {
        int16_t v;
        std::memcpy(&v, b + 2 * i, 2);
        store(i, double(v));
      }
    } else if (plan_.read_type == TypeDesc::INT32) {
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
          fail(IoErrorCode::NonFinite, path_,
               std::string(std::isnan(f) ? "NaN" : "Inf") + " at row " + std::to_string(rows_read_ + i / g.width) +
                   ", column " + std::to_string(i % g.width));
        values[i] = is_void ? 0.0 : double(f);
        valid[i] = is_void ? 0 : 1;
      }
    }
    rows_read_ += n;
    return n;
  }

 private:
  std::string path_;
  std::unique_ptr<ImageInput> in_;
  ImagePlan plan_;
  std::vector<uint8_t> buffer_;
  float nodata_as_float_ = 0;
  uint32_t nodata_float_bits_ = 0;
};

// Writes `map` band by band through OIIO as `type` (one channel), converting each value with `convert`.
template <typename T, typename Convert>
void write_image_bands(const std::string& path, const Heightmap& map, TypeDesc type, const char* compression,
                       Convert convert) {
  const GridInfo& g = map.info;
  if (g.width <= 0 || g.height <= 0 || map.values.size() != size_t(g.width * g.height))
    fail(IoErrorCode::WriteFailed, path, "heightmap dimensions do not match its sample count");
  if (g.width > (int64_t(1) << 30) || g.height > (int64_t(1) << 30))
    fail(IoErrorCode::WriteFailed, path, "image too large");
  // Convert (and so validate) every value before creating anything, so a refused grid leaves no file.
  for (int64_t y = 0; y < g.height; ++y)
    for (int64_t x = 0; x < g.width; ++x) convert(value_for_writing(map, x, y, path), x, y);
  AtomicOutput target(path);
  auto out = ImageOutput::create(target.temp_path());
  if (!out) fail(IoErrorCode::WriteFailed, path, "no image writer for this extension: " + OIIO::geterror());
  ImageSpec spec(int(g.width), int(g.height), 1, type);
  if (compression) spec.attribute("compression", compression);
  // OIIO stamps the current time when DateTime is absent; a fixed value keeps output byte-reproducible.
  spec.attribute("DateTime", "");
  if (!out->open(target.temp_path(), spec)) fail(IoErrorCode::WriteFailed, path, "cannot create: " + out->geterror());
  constexpr int64_t kBandRows = 64;
  std::vector<T> band(size_t(std::min<int64_t>(kBandRows, g.height) * g.width));
  for (int64_t y0 = 0; y0 < g.height; y0 += kBandRows) {
    int64_t n = std::min(kBandRows, g.height - y0);
    for (int64_t y = y0; y < y0 + n; ++y)
      for (int64_t x = 0; x < g.width; ++x) band[size_t((y - y0) * g.width + x)] = convert(value_for_writing(map, x, y, path), x, y);
    if (!out->write_scanlines(int(y0), int(y0 + n), 0, type, band.data()))
      fail(IoErrorCode::WriteFailed, path, "write error: " + out->geterror());
  }
  if (!out->close()) fail(IoErrorCode::WriteFailed, path, "write error on close: " + out->geterror());
  out.reset();
  target.commit();
}

}  // namespace

GridInfo probe_image(const std::string& path, const ReadOptions& options) {
  auto in = open_image(path);
  return plan_image(path, in->spec(), options).info;
}

std::unique_ptr<BandReader> open_image_reader(const std::string& path, const ReadOptions& options) {
  auto in = open_image(path);
  ImagePlan plan = plan_image(path, in->spec(), options);
  return std::make_unique<ImageBandReader>(path, std::move(in), plan);
}

}  // namespace terrain::io

namespace terrain {

void write_image16(const std::string& path, const Heightmap& map) {
  const bool is_tiff = io::ends_with_ci(path, ".tif") || io::ends_with_ci(path, ".tiff");
  if (!is_tiff && !io::ends_with_ci(path, ".png"))
    io::fail(IoErrorCode::WriteFailed, path, "16-bit images are written as .png, .tif or .tiff");
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
      io::fail(IoErrorCode::WriteFailed, path,
               "value " + io::format_double(v) + " at row " + std::to_string(y) + ", column " + std::to_string(x) +
                   " does not fit a " + (write_signed ? "signed" : "unsigned") + " 16-bit " + (is_tiff ? "TIFF" : "PNG"));
    return v;
  };
  const char* compression = is_tiff ? "zip" : nullptr;
  if (write_signed)
    io::write_image_bands<int16_t>(path, map, OIIO::TypeDesc::INT16, compression,
                                   [&](double v, int64_t x, int64_t y) { return int16_t(check(v, x, y)); });
  else
    io::write_image_bands<uint16_t>(path, map, OIIO::TypeDesc::UINT16, compression,
                                    [&](double v, int64_t x, int64_t y) { return uint16_t(check(v, x, y)); });
}

void write_exr(const std::string& path, const Heightmap& map) {
  if (!io::ends_with_ci(path, ".exr")) io::fail(IoErrorCode::WriteFailed, path, "float images are written as .exr");
  io::write_image_bands<float>(path, map, OIIO::TypeDesc::FLOAT, "zip", [&](double v, int64_t x, int64_t y) {
    float f = float(v);
    if (double(f) != v && !std::isnan(v))
      io::fail(IoErrorCode::WriteFailed, path,
               "value " + io::format_double(v) + " at row " + std::to_string(y) + ", column " + std::to_string(x) +
                   " is not exactly representable as float32");
    return f;
  });
}

}  // namespace terrain
