// The one rectangle type of the project: a window of samples on a grid (a codec image, a pyramid
// level, a clipmap region). Half-open: columns x0 .. x0 + width - 1, rows y0 .. y0 + height - 1.
#pragma once

#include <cstdint>

namespace terrain {

struct Rect {
  int64_t x0 = 0, y0 = 0;         // first column and row
  int64_t width = 0, height = 0;  // in samples; a rectangle with either <= 0 is empty
  bool operator==(const Rect&) const = default;
};

}  // namespace terrain
