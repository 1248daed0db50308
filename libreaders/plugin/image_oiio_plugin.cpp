// The image plugin (CMake MODULE terrain_image_oiio): image_plugin_abi.h implemented with
// OpenImageIO. Built apart from libpyramid so that only processes that touch an image file load
// OpenImageIO and its dependencies.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <geotiffio.h>
#include <tiffio.h>
#include <xtiffio.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <exception>
#include <memory>
#include <string>
#include <vector>

#include "readers/internal/image_plugin_abi.h"

#define TERRAIN_IMAGE_EXPORT extern "C" __attribute__((visibility("default")))

struct terrain_image_reader {
  std::unique_ptr<OIIO::ImageInput> input;
  std::string path;
};

namespace {

// The file an OpenImageIO writer writes through, remembering the first short write: its PNG writer
// ignores what its writes return, so a full disk (or a file-size limit) left a truncated PNG that
// was reported as written.
class CheckedFile final : public OIIO::Filesystem::IOFile {
 public:
  explicit CheckedFile(std::FILE* file) : IOFile(file, Write) {}
  size_t write(const void* buf, size_t size) override { return note(IOFile::write(buf, size), size); }
  size_t pwrite(const void* buf, size_t size, int64_t offset) override {
    return note(IOFile::pwrite(buf, size, offset), size);
  }
  const std::string& failure() const { return failure_; }

 private:
  size_t note(size_t done, size_t size) {
    if (done != size && failure_.empty())
      failure_ = std::string("short write: ") + (errno ? std::strerror(errno) : "no space");
    return done;
  }
  std::string failure_;
};

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};

}  // namespace

// Members in this order so that the output, which may still write while it is destroyed, goes
// before its proxy and the file under it.
struct terrain_image_writer {
  std::unique_ptr<std::FILE, FileCloser> file;  // under proxy, for formats that take one
  std::unique_ptr<CheckedFile> proxy;
  std::unique_ptr<OIIO::ImageOutput> output;
  OIIO::TypeDesc type;
};

namespace {

using OIIO::TypeDesc;

int32_t report(int32_t status, const std::string& reason, char* message, size_t message_size) {
  if (message && message_size > 0) {
    const size_t n = std::min(reason.size(), message_size - 1);
    std::memcpy(message, reason.data(), n);
    message[n] = '\0';
  }
  return status;
}

// OIIO reports some failures only through its global error; an empty reason would hide them.
std::string or_unknown(std::string reason) { return reason.empty() ? std::string("unknown error") : reason; }

bool type_for_pixel(int32_t pixel, TypeDesc& type) {
  switch (pixel) {
    case TERRAIN_PIXEL_UINT8:
      type = TypeDesc::UINT8;
      return true;
    case TERRAIN_PIXEL_INT8:
      type = TypeDesc::INT8;
      return true;
    case TERRAIN_PIXEL_UINT16:
      type = TypeDesc::UINT16;
      return true;
    case TERRAIN_PIXEL_INT16:
      type = TypeDesc::INT16;
      return true;
    case TERRAIN_PIXEL_UINT32:
      type = TypeDesc::UINT32;
      return true;
    case TERRAIN_PIXEL_INT32:
      type = TypeDesc::INT32;
      return true;
    case TERRAIN_PIXEL_HALF:
      type = TypeDesc::HALF;
      return true;
    case TERRAIN_PIXEL_FLOAT:
      type = TypeDesc::FLOAT;
      return true;
    case TERRAIN_PIXEL_DOUBLE:
      type = TypeDesc::DOUBLE;
      return true;
    default:
      return false;
  }
}

int32_t pixel_for_type(TypeDesc type) {
  // TypeDesc == BASETYPE also requires a scalar, non-array type.
  if (type == TypeDesc::UINT8) return TERRAIN_PIXEL_UINT8;
  if (type == TypeDesc::INT8) return TERRAIN_PIXEL_INT8;
  if (type == TypeDesc::UINT16) return TERRAIN_PIXEL_UINT16;
  if (type == TypeDesc::INT16) return TERRAIN_PIXEL_INT16;
  if (type == TypeDesc::UINT32) return TERRAIN_PIXEL_UINT32;
  if (type == TypeDesc::INT32) return TERRAIN_PIXEL_INT32;
  if (type == TypeDesc::HALF) return TERRAIN_PIXEL_HALF;
  if (type == TypeDesc::FLOAT) return TERRAIN_PIXEL_FLOAT;
  if (type == TypeDesc::DOUBLE) return TERRAIN_PIXEL_DOUBLE;
  return TERRAIN_PIXEL_OTHER;
}

// No C++ exception may leave the plugin: the caller is on the other side of a C interface.
template <typename Body>
int32_t guarded(char* message, size_t message_size, int32_t failure_status, Body body) {
  try {
    return body();
  } catch (const std::exception& e) {
    return report(failure_status, e.what(), message, message_size);
  } catch (...) {
    return report(failure_status, "unknown exception in the image plugin", message, message_size);
  }
}

// The PNG header's interlace method (IHDR byte 12, at file offset 28): OpenImageIO decodes an
// interlaced (Adam7) PNG whole on its first row read, and its spec does not say so.
bool png_is_interlaced(const char* path) {
  std::FILE* f = std::fopen(path, "rb");
  if (!f) return false;
  unsigned char head[29] = {};
  const bool whole = std::fread(head, 1, sizeof head, f) == sizeof head;
  std::fclose(f);
  return whole && std::memcmp(head + 12, "IHDR", 4) == 0 && head[28] != 0;
}

// An OpenEXR header is a list of attributes (name, type, int32 size, value) that OpenEXR reads by
// allocating each declared size first: a 64-byte file declaring a 1.7 GB string took 2 GB before
// failing. Every size must fit in the bytes that follow it, checked before OpenEXR sees the file.
// Empty when the file is not EXR or its headers are consistent; else what is wrong.
std::string exr_header_problem(const char* path) {
  std::FILE* f = std::fopen(path, "rb");
  if (!f) return {};
  // Every image open comes through here: other formats cost one 8-byte read.
  static const uint8_t kMagic[4] = {0x76, 0x2f, 0x31, 0x01};
  std::vector<uint8_t> data(8);
  if (std::fread(data.data(), 1, 8, f) != 8 || std::memcmp(data.data(), kMagic, 4) != 0) {
    std::fclose(f);
    return {};
  }
  uint8_t buffer[65536];
  size_t got = 0;
  // Headers are small; 16 MiB of them is beyond any real file (the checks below use the file size).
  while (data.size() < (size_t(16) << 20) && (got = std::fread(buffer, 1, sizeof buffer, f)) > 0)
    data.insert(data.end(), buffer, buffer + got);
  std::fseek(f, 0, SEEK_END);
  const long file_size = std::ftell(f);
  std::fclose(f);
  const bool multipart = (data[5] & 0x10) != 0;  // version field bit 12
  size_t p = 8;
  const auto c_string = [&](std::string& out) {
    const size_t start = p;
    while (p < data.size() && data[p] != 0 && p - start < 256) ++p;
    if (p >= data.size() || data[p] != 0) return false;
    out.assign(reinterpret_cast<const char*>(data.data() + start), p - start);
    ++p;
    return true;
  };
  for (int header = 0; header < 1024; ++header) {
    for (;;) {
      std::string name, type;
      if (!c_string(name)) return "EXR header ends inside an attribute name";
      if (name.empty()) break;  // end of this header
      if (!c_string(type)) return "EXR attribute " + name + ": no type";
      if (p + 4 > data.size()) return "EXR attribute " + name + ": no size";
      const int32_t size = int32_t(uint32_t(data[p]) | uint32_t(data[p + 1]) << 8 |
                                   uint32_t(data[p + 2]) << 16 | uint32_t(data[p + 3]) << 24);
      p += 4;
      if (size < 0 || int64_t(size) > int64_t(file_size) - int64_t(p))
        return "EXR attribute " + name + " declares " + std::to_string(size) +
               " bytes, more than the file holds";
      if (p + size_t(size) > data.size()) return {};  // beyond what was read: OpenEXR checks the rest
      p += size_t(size);
    }
    // A multi-part file ends its list of headers with an empty one.
    if (!multipart || p >= data.size() || data[p] == 0) return {};
  }
  return {};
}

// Rows OpenEXR decodes together in a scanline file, by compression (OpenEXR's own table).
int64_t exr_chunk_rows(const std::string& compression) {
  if (compression == "zip" || compression == "pxr24") return 16;
  if (compression == "piz" || compression == "b44" || compression == "b44a" || compression == "dwaa")
    return 32;
  if (compression == "dwab") return 256;
  return 1;  // none, rle, zips
}

// What decoding one row costs OpenImageIO at least, from the header alone (no pixel is read): the
// native bytes of the rows it decodes together. Saturates at INT64_MAX (a forged header may claim
// 2^31 x 2^31 pixels of 65535 channels).
int64_t decode_unit_bytes(const char* path, OIIO::ImageInput& input) {
  const OIIO::ImageSpec& spec = input.spec();
  const std::string format = input.format_name();
  const int64_t width = std::max(1, spec.width), height = std::max(1, spec.height);
  int64_t rows = 1, row_width = width;
  if (spec.tile_width > 0) {
    rows = int64_t(std::max(1, spec.tile_height)) * std::max(1, spec.tile_depth);
    row_width = (width + spec.tile_width - 1) / spec.tile_width * int64_t(spec.tile_width);
  } else if (format == "tiff") {
    // Absent, the tag means one strip for the whole image (libtiff's default of 2^32-1, which
    // reads back as -1 through an int).
    rows = spec.get_int_attribute("tiff:RowsPerStrip", 0);
    if (rows <= 0 || rows > height) rows = height;
  } else if (format == "png") {
    if (png_is_interlaced(path)) rows = height;
  } else if (format == "openexr") {
    rows = std::min(height, exr_chunk_rows(spec.get_string_attribute("compression")));
  }
  const unsigned __int128 bytes =
      (unsigned __int128)rows * (unsigned __int128)row_width * (unsigned __int128)spec.pixel_bytes(true);
  return bytes > (unsigned __int128)INT64_MAX ? INT64_MAX : int64_t(bytes);
}

}  // namespace

TERRAIN_IMAGE_EXPORT int32_t terrain_image_abi_version(void) { return TERRAIN_IMAGE_PLUGIN_ABI_VERSION; }

TERRAIN_IMAGE_EXPORT int32_t terrain_image_open(const char* path, terrain_image_reader** reader,
                                                terrain_image_header* header, char* message,
                                                size_t message_size) {
  return guarded(message, message_size, TERRAIN_IMAGE_OPEN_FAILED, [&]() -> int32_t {
    if (!path || !reader || !header)
      return report(TERRAIN_IMAGE_BAD_ARGUMENT, "null argument", message, message_size);
    *reader = nullptr;
    OIIO::ImageSpec config;
    // Keep RGB exactly as stored: by default OIIO premultiplies by alpha, which would corrupt Terrain-RGB
    // codes.
    config.attribute("oiio:UnassociatedAlpha", 1);
    const std::string exr_problem = exr_header_problem(path);
    if (!exr_problem.empty()) return report(TERRAIN_IMAGE_OPEN_FAILED, exr_problem, message, message_size);
    auto input = OIIO::ImageInput::open(path, &config);
    if (!input) return report(TERRAIN_IMAGE_OPEN_FAILED, or_unknown(OIIO::geterror()), message, message_size);
    if (input->has_error())
      return report(TERRAIN_IMAGE_OPEN_FAILED, or_unknown(input->geterror()), message, message_size);
    const OIIO::ImageSpec& spec = input->spec();
    *header = terrain_image_header{};
    header->width = spec.width;
    header->height = spec.height;
    header->depth = spec.depth;
    header->channels = spec.nchannels;
    header->pixel = pixel_for_type(spec.format);
    std::strncpy(header->pixel_name, spec.format.c_str(), sizeof header->pixel_name - 1);
    header->decode_unit_bytes = decode_unit_bytes(path, *input);
    *reader = new terrain_image_reader{std::move(input), path};
    return TERRAIN_IMAGE_OK;
  });
}

TERRAIN_IMAGE_EXPORT int32_t terrain_image_read_rows(terrain_image_reader* reader, int32_t row_begin,
                                                     int32_t row_end, int32_t channels, int32_t pixel,
                                                     void* pixels, char* message, size_t message_size) {
  return guarded(message, message_size, TERRAIN_IMAGE_READ_FAILED, [&]() -> int32_t {
    TypeDesc type;
    if (!reader || !type_for_pixel(pixel, type))
      return report(TERRAIN_IMAGE_BAD_ARGUMENT, "bad reader or pixel type", message, message_size);
    OIIO::ImageInput& in = *reader->input;
    const int y0 = in.spec().y + row_begin;
    // OpenImageIO can return success for strips libtiff failed to decode (a truncated file, a strip
    // past its end, an unknown compression) and keep only an error message: those rows would read
    // as zeros. Any error it recorded is a failed read.
    const OIIO::ImageSpec& spec = in.spec();
    bool read = false;
    if (spec.tile_width > 0) {
      // Tiled files: OpenImageIO 2.4's read_scanlines divides by a RowsPerStrip they lack (SIGFPE).
      // Whole tile rows are read instead, full width, and the rows asked for copied out.
      const int th = std::max(1, spec.tile_height);
      const int tb = row_begin - row_begin % th;
      const int te = std::min(spec.height, (row_end + th - 1) / th * th);
      const size_t row_bytes = size_t(spec.width) * size_t(channels) * type.size();
      std::vector<unsigned char> tiles(size_t(te - tb) * row_bytes);
      read = in.read_tiles(0, 0, spec.x, spec.x + spec.width, spec.y + tb, spec.y + te, spec.z,
                           spec.z + std::max(1, spec.depth), 0, channels, type, tiles.data());
      if (read)
        std::memcpy(pixels, tiles.data() + size_t(row_begin - tb) * row_bytes,
                    size_t(row_end - row_begin) * row_bytes);
    } else {
      read = in.read_scanlines(0, 0, y0, y0 + (row_end - row_begin), 0, 0, channels, type, pixels);
    }
    if (!read || in.has_error())
      return report(TERRAIN_IMAGE_READ_FAILED, or_unknown(in.geterror()), message, message_size);
    return TERRAIN_IMAGE_OK;
  });
}

TERRAIN_IMAGE_EXPORT void terrain_image_close(terrain_image_reader* reader) { delete reader; }

namespace {

constexpr ttag_t kGdalNodataTag = 42113;  // GDAL_NODATA: ASCII

// Copies `count` doubles of a variable-count tag (libgeotiff registers them with a uint16 count).
int32_t get_doubles(TIFF* tif, ttag_t tag, double* out, int32_t room) {
  uint16_t count = 0;
  double* values = nullptr;
  if (TIFFGetField(tif, tag, &count, &values) != 1 || !values) return 0;
  for (int32_t i = 0; i < std::min<int32_t>(count, room); ++i) out[i] = values[i];
  return count;
}

int32_t short_key(GTIF* gtif, geokey_t key) {
  unsigned short v = 0;
  return GTIFKeyGetSHORT(gtif, key, &v, 0, 1) == 1 ? int32_t(v) : 0;
}

// An ASCII GeoKey into `out` (room bytes); true when present.
bool ascii_key(GTIF* gtif, geokey_t key, char* out, size_t room, int32_t& truncated) {
  int size = 0;
  tagtype_t type = TYPE_UNKNOWN;
  if (GTIFKeyInfo(gtif, key, &size, &type) <= 0 || type != TYPE_ASCII) return false;
  std::string text(size_t(std::max(size, 0)) + 1, '\0');
  if (GTIFKeyGetASCII(gtif, key, text.data(), int(text.size())) <= 0) return false;
  text.resize(std::strlen(text.c_str()));
  truncated = text.size() >= room ? 1 : 0;
  const size_t n = std::min(text.size(), room - 1);
  std::memcpy(out, text.data(), n);
  out[n] = '\0';
  return true;
}

}  // namespace

TERRAIN_IMAGE_EXPORT int32_t terrain_image_read_georef(terrain_image_reader* reader,
                                                       terrain_image_georef* georef, char* message,
                                                       size_t message_size) {
  return guarded(message, message_size, TERRAIN_IMAGE_OPEN_FAILED, [&]() -> int32_t {
    if (!reader || !georef) return report(TERRAIN_IMAGE_BAD_ARGUMENT, "null argument", message, message_size);
    std::memset(georef, 0, sizeof *georef);
    if (std::strcmp(reader->input->format_name(), "tiff") != 0) return TERRAIN_IMAGE_OK;
    // XTIFFOpen registers the GeoTIFF tags (libgeotiff's tag extender) before the directory is read.
    TIFF* tif = XTIFFOpen(reader->path.c_str(), "r");
    if (!tif)
      return report(TERRAIN_IMAGE_OPEN_FAILED, "libtiff cannot reopen the file", message, message_size);
    georef->pixel_scale_count = get_doubles(tif, TIFFTAG_GEOPIXELSCALE, georef->pixel_scale, 3);
    georef->tiepoint_count = get_doubles(tif, TIFFTAG_GEOTIEPOINTS, georef->tiepoint, 6);
    georef->transformation_count = get_doubles(tif, TIFFTAG_GEOTRANSMATRIX, georef->transformation, 16);
    // libgeotiff does not register GDAL_NODATA: libtiff reads it as an anonymous field, whose value
    // comes with a count (uint32 for TIFF_VARIABLE2, else uint16) when the field says so.
    if (const TIFFField* field = TIFFFieldWithTag(tif, kGdalNodataTag);
        field && TIFFFieldDataType(field) == TIFF_ASCII) {
      char* nodata = nullptr;
      uint32_t count32 = 0;
      uint16_t count16 = 0;
      int got = 0;
      if (!TIFFFieldPassCount(field))
        got = TIFFGetField(tif, kGdalNodataTag, &nodata);
      else if (TIFFFieldReadCount(field) == TIFF_VARIABLE2)
        got = TIFFGetField(tif, kGdalNodataTag, &count32, &nodata);
      else
        got = TIFFGetField(tif, kGdalNodataTag, &count16, &nodata);
      if (got == 1 && nodata) {
        const size_t limit = TIFFFieldPassCount(field) ? size_t(std::max<uint32_t>(count32, count16))
                                                       : sizeof georef->nodata - 1;
        const size_t n = std::min({limit, sizeof georef->nodata - 1, strnlen(nodata, limit)});
        georef->has_nodata = 1;
        std::memcpy(georef->nodata, nodata, n);
        georef->nodata[n] = '\0';
      }
    }
    uint16_t key_count = 0;
    uint16_t* keys = nullptr;
    if (TIFFGetField(tif, TIFFTAG_GEOKEYDIRECTORY, &key_count, &keys) == 1 && key_count >= 4) {
      georef->has_geokeys = 1;
      if (GTIF* gtif = GTIFNew(tif)) {
        georef->model_type = short_key(gtif, GTModelTypeGeoKey);
        georef->raster_type = short_key(gtif, GTRasterTypeGeoKey);
        georef->geographic_type = short_key(gtif, GeographicTypeGeoKey);
        georef->projected_type = short_key(gtif, ProjectedCSTypeGeoKey);
        const size_t room = sizeof georef->citation;
        if (!ascii_key(gtif, PCSCitationGeoKey, georef->citation, room, georef->citation_truncated) &&
            !ascii_key(gtif, GeogCitationGeoKey, georef->citation, room, georef->citation_truncated))
          ascii_key(gtif, GTCitationGeoKey, georef->citation, room, georef->citation_truncated);
        GTIFFree(gtif);
      }
    }
    XTIFFClose(tif);
    return TERRAIN_IMAGE_OK;
  });
}

TERRAIN_IMAGE_EXPORT int32_t terrain_image_create(const char* path, int32_t width, int32_t height,
                                                  int32_t channels, int32_t pixel, const char* compression,
                                                  int32_t flags, terrain_image_writer** writer, char* message,
                                                  size_t message_size) {
  return guarded(message, message_size, TERRAIN_IMAGE_CREATE_FAILED, [&]() -> int32_t {
    TypeDesc type;
    if (!path || !writer || !type_for_pixel(pixel, type))
      return report(TERRAIN_IMAGE_BAD_ARGUMENT, "null argument or bad pixel type", message, message_size);
    *writer = nullptr;
    auto output = OIIO::ImageOutput::create(path);
    if (!output) return report(TERRAIN_IMAGE_NO_WRITER, OIIO::geterror(), message, message_size);
    OIIO::ImageSpec spec(width, height, channels, type);
    if (compression) spec.attribute("compression", compression);
    // OIIO stamps the current time when DateTime is absent; a fixed value keeps output byte-reproducible.
    if (flags & TERRAIN_IMAGE_NO_TIMESTAMP) spec.attribute("DateTime", "");
    auto w = std::make_unique<terrain_image_writer>();
    w->output = std::move(output);
    w->type = type;
    OIIO::ImageOutput* out = w->output.get();
    if (out->supports("ioproxy")) {
      w->file.reset(std::fopen(path, "wb"));
      if (!w->file)
        return report(TERRAIN_IMAGE_CREATE_FAILED, std::string("cannot open: ") + std::strerror(errno),
                      message, message_size);
      w->proxy = std::make_unique<CheckedFile>(w->file.get());
      if (!out->set_ioproxy(w->proxy.get()))
        return report(TERRAIN_IMAGE_CREATE_FAILED, or_unknown(out->geterror()), message, message_size);
    }
    if (!out->open(path, spec))
      return report(TERRAIN_IMAGE_CREATE_FAILED, or_unknown(out->geterror()), message, message_size);
    *writer = w.release();
    return TERRAIN_IMAGE_OK;
  });
}

TERRAIN_IMAGE_EXPORT int32_t terrain_image_write_rows(terrain_image_writer* writer, int32_t row_begin,
                                                      int32_t row_end, const void* pixels, char* message,
                                                      size_t message_size) {
  return guarded(message, message_size, TERRAIN_IMAGE_WRITE_FAILED, [&]() -> int32_t {
    if (!writer) return report(TERRAIN_IMAGE_BAD_ARGUMENT, "null writer", message, message_size);
    if (!writer->output->write_scanlines(row_begin, row_end, 0, writer->type, pixels))
      return report(TERRAIN_IMAGE_WRITE_FAILED, writer->output->geterror(), message, message_size);
    return TERRAIN_IMAGE_OK;
  });
}

TERRAIN_IMAGE_EXPORT int32_t terrain_image_finish(terrain_image_writer* writer, char* message,
                                                  size_t message_size) {
  return guarded(message, message_size, TERRAIN_IMAGE_WRITE_FAILED, [&]() -> int32_t {
    if (!writer) return report(TERRAIN_IMAGE_BAD_ARGUMENT, "null writer", message, message_size);
    if (!writer->output->close())
      return report(TERRAIN_IMAGE_WRITE_FAILED, or_unknown(writer->output->geterror()), message,
                    message_size);
    if (writer->proxy && !writer->proxy->failure().empty())
      return report(TERRAIN_IMAGE_WRITE_FAILED, writer->proxy->failure(), message, message_size);
    // stdio may still hold the last bytes: only a checked fflush and fclose show they reached the file.
    if (writer->file) {
      std::FILE* f = writer->file.release();
      const bool flushed = std::fflush(f) == 0 && !std::ferror(f);
      const int err = errno;
      if (std::fclose(f) != 0 || !flushed)
        return report(TERRAIN_IMAGE_WRITE_FAILED, std::string("cannot write: ") + std::strerror(err), message,
                      message_size);
    }
    return TERRAIN_IMAGE_OK;
  });
}

TERRAIN_IMAGE_EXPORT void terrain_image_destroy(terrain_image_writer* writer) { delete writer; }
