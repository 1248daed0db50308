// The image plugin as libpyramid sees it: loaded with dlopen on the first image read or write, so
// that programs which never touch an image never map OpenImageIO. Not a public header.
#pragma once

#include <cstddef>
#include <memory>
#include <string>

#include "readers/heightmap.h"
#include "readers/internal/image_plugin_abi.h"

namespace terrain::io {

struct ImagePlugin {
  decltype(&terrain_image_open) open = nullptr;
  decltype(&terrain_image_read_rows) read_rows = nullptr;
  decltype(&terrain_image_close) close = nullptr;
  decltype(&terrain_image_read_georef) read_georef = nullptr;
  decltype(&terrain_image_create) create = nullptr;
  decltype(&terrain_image_write_rows) write_rows = nullptr;
  decltype(&terrain_image_finish) finish = nullptr;
  decltype(&terrain_image_destroy) destroy = nullptr;
};

// Loads the plugin once per process (thread-safe): $TERRAIN_IMAGE_PLUGIN when set, else the module
// of this build (its absolute path is compiled in). When it cannot be loaded, throws
// Error(code, "<image_path>: cannot load the image plugin <plugin path>: <dlerror()>") on every call.
const ImagePlugin& image_plugin(ErrorCode code, const std::string& image_path);

// Room for the plugin's reason text; longer reasons are truncated.
constexpr size_t kImageMessageSize = 1024;

struct ImageReaderCloser {
  decltype(&terrain_image_close) close;
  void operator()(terrain_image_reader* reader) const { close(reader); }
};
using ImageReaderHandle = std::unique_ptr<terrain_image_reader, ImageReaderCloser>;

struct ImageWriterDestroyer {
  decltype(&terrain_image_destroy) destroy;
  void operator()(terrain_image_writer* writer) const { destroy(writer); }
};
using ImageWriterHandle = std::unique_ptr<terrain_image_writer, ImageWriterDestroyer>;

}  // namespace terrain::io
