// PNG output of rendered frames (OpenImageIO).
#include <OpenImageIO/imageio.h>

#include <stdexcept>

#include "runtime/renderer.h"

namespace terrain::runtime {

void write_png_rgba(const std::string& path, int width, int height, const std::vector<uint8_t>& rgba) {
  if (width < 1 || height < 1 || rgba.size() != size_t(width) * size_t(height) * 4)
    throw std::invalid_argument("write_png_rgba: " + path + ": pixel buffer does not match " + std::to_string(width) +
                                "x" + std::to_string(height));
  auto out = OIIO::ImageOutput::create(path);
  if (!out) throw std::runtime_error("cannot write " + path + ": " + OIIO::geterror());
  const OIIO::ImageSpec spec(width, height, 4, OIIO::TypeDesc::UINT8);
  if (!out->open(path, spec) || !out->write_image(OIIO::TypeDesc::UINT8, rgba.data()) || !out->close())
    throw std::runtime_error("cannot write " + path + ": " + out->geterror());
}

}  // namespace terrain::runtime
