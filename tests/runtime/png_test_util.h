// Reading the tools' PNG pictures back in tests (through the project's image plugin, OpenImageIO),
// and their PSNR.
#pragma once

#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "readers/internal/image_plugin.h"

namespace pngtest {

// RGBA8 pixels of a PNG (alpha 255 where it has none), row 0 at the top.
inline std::vector<uint8_t> read_rgba(const std::string& path, int& width, int& height) {
  const terrain::io::ImagePlugin& plugin = terrain::io::image_plugin(terrain::ErrorCode::NotFound, path);
  terrain_image_reader* raw = nullptr;
  terrain_image_header header{};
  char message[terrain::io::kImageMessageSize] = {};
  REQUIRE(plugin.open(path.c_str(), &raw, &header, message, sizeof message) == 0);
  terrain::io::ImageReaderHandle reader(raw, terrain::io::ImageReaderCloser{plugin.close});
  width = header.width, height = header.height;
  const int channels = header.channels;
  std::vector<uint8_t> stored(size_t(width) * size_t(height) * size_t(channels));
  REQUIRE(plugin.read_rows(reader.get(), 0, height, channels, TERRAIN_PIXEL_UINT8, stored.data(), message,
                           sizeof message) == 0);
  std::vector<uint8_t> pixels(size_t(width) * size_t(height) * 4, 255);
  for (size_t p = 0; p < size_t(width) * size_t(height); ++p)
    for (int c = 0; c < std::min(channels, 4); ++c)
      pixels[p * 4 + size_t(c)] = stored[p * size_t(channels) + size_t(c)];
  return pixels;
}

// PSNR of two equal-sized RGBA8 images over the colour channels; 99 dB when identical.
inline double psnr_rgb(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b) {
  double sq = 0;
  size_t count = 0;
  for (size_t i = 0; i + 3 < a.size() && i + 3 < b.size(); i += 4)
    for (size_t c = 0; c < 3; ++c, ++count)
      sq += (double(a[i + c]) - b[i + c]) * (double(a[i + c]) - b[i + c]);
  if (sq == 0) return 99;
  return 10 * std::log10(255.0 * 255.0 / (sq / double(count)));
}

}  // namespace pngtest
