// 8-bit picture output (rendered frames, error heat-maps) through libpyramid's image plugin, which
// is loaded on the first image read or write; see docs/io.md.
#pragma once

#include <cstdint>
#include <string>

namespace terrain {

// Writes width x height pixels of `channels` uint8 samples (1 grey, 3 RGB, 4 RGBA; packed, row 0
// first) straight to `path`, in the format its extension names (PNG for .png). Throws
// Error(WriteFailed, "<path>: <reason>"), the reason being the writer's or why the plugin could
// not be loaded, or for no pixels or a channel count outside 1..4. Any thread.
void write_image8(const std::string& path, int width, int height, int channels, const uint8_t* pixels);

}  // namespace terrain
