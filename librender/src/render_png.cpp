// PNG output of rendered frames, through libpyramid's image plugin (loaded on first use).
#include <stdexcept>

#include "readers/heightmap.h"
#include "readers/image8.h"
#include "render/renderer.h"

namespace terrain::render {

using namespace terrain::runtime;  // the stage below

void write_png_rgba(const std::string& path, int width, int height, const std::vector<uint8_t>& rgba) {
  if (width < 1 || height < 1 || rgba.size() != size_t(width) * size_t(height) * 4)
    throw std::invalid_argument("write_png_rgba: " + path + ": pixel buffer does not match " +
                                std::to_string(width) + "x" + std::to_string(height));
  try {
    write_image8(path, width, height, 4, rgba.data());
  } catch (const Error& e) {
    // Exit status 9 in the tools, as every other write failure: "cannot write <path>: <reason>".
    throw Error(ErrorCode::WriteFailed, std::string("cannot write ") + e.what());
  }
}

}  // namespace terrain::render
