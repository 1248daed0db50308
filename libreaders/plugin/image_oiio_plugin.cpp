// The image plugin (CMake MODULE terrain_image_oiio): image_plugin_abi.h implemented with
// OpenImageIO. Built apart from libpyramid so that only processes that touch an image file load
// OpenImageIO and its dependencies.
#include <OpenImageIO/imageio.h>
#include <geotiffio.h>
#include <tiffio.h>
#include <xtiffio.h>

#include <algorithm>
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

struct terrain_image_writer {
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
    auto input = OIIO::ImageInput::open(path, &config);
    if (!input) return report(TERRAIN_IMAGE_OPEN_FAILED, or_unknown(OIIO::geterror()), message, message_size);
    const OIIO::ImageSpec& spec = input->spec();
    *header = terrain_image_header{};
    header->width = spec.width;
    header->height = spec.height;
    header->depth = spec.depth;
    header->channels = spec.nchannels;
    header->pixel = pixel_for_type(spec.format);
    std::strncpy(header->pixel_name, spec.format.c_str(), sizeof header->pixel_name - 1);
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
    if (!output->open(path, spec))
      return report(TERRAIN_IMAGE_CREATE_FAILED, output->geterror(), message, message_size);
    *writer = new terrain_image_writer{std::move(output), type};
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
      return report(TERRAIN_IMAGE_WRITE_FAILED, writer->output->geterror(), message, message_size);
    return TERRAIN_IMAGE_OK;
  });
}

TERRAIN_IMAGE_EXPORT void terrain_image_destroy(terrain_image_writer* writer) { delete writer; }
