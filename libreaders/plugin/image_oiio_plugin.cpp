// The image plugin (CMake MODULE terrain_image_oiio): image_plugin_abi.h implemented with
// OpenImageIO. Built apart from libpyramid so that only processes that touch an image file load
// OpenImageIO and its dependencies.
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cstring>
#include <exception>
#include <memory>
#include <string>

#include "readers/internal/image_plugin_abi.h"

#define TERRAIN_IMAGE_EXPORT extern "C" __attribute__((visibility("default")))

struct terrain_image_reader {
  std::unique_ptr<OIIO::ImageInput> input;
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
    *reader = new terrain_image_reader{std::move(input)};
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
    const bool read = in.read_scanlines(0, 0, y0, y0 + (row_end - row_begin), 0, 0, channels, type, pixels);
    if (!read || in.has_error())
      return report(TERRAIN_IMAGE_READ_FAILED, or_unknown(in.geterror()), message, message_size);
    return TERRAIN_IMAGE_OK;
  });
}

TERRAIN_IMAGE_EXPORT void terrain_image_close(terrain_image_reader* reader) { delete reader; }

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
