// A tiny software rasteriser for the tools' pictures: RGBA canvas, rectangles, lines and a 5 x 7
// bitmap font (ASCII 32..126), used for terrain-report's error plot and heat-map scale bar and for
// clipmap-view's on-screen overlay (drawn here, then shown as a GL texture). Written out through the
// project's PNG writer (readers/image8.h).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace cli {

struct Rgba {
  uint8_t r = 0, g = 0, b = 0, a = 255;
};

class Canvas {
 public:
  // width x height pixels (1..16384 a side), all `fill`. Throws std::invalid_argument otherwise.
  Canvas(int width, int height, Rgba fill = {255, 255, 255, 255});
  int width() const { return width_; }
  int height() const { return height_; }
  const std::vector<uint8_t>& rgba() const { return pixels_; }  // row 0 at the top
  // Pixels outside the canvas are clipped everywhere.
  void set(int x, int y, Rgba c);
  void fill_rect(int x, int y, int w, int h, Rgba c);
  // A line of `thickness` pixels between two points (pixel centres at integer + 0.5).
  void line(double x0, double y0, double x1, double y1, Rgba c, int thickness = 1);
  // Text with its top-left corner at (x, y), each font pixel `scale` x `scale`; characters outside
  // 32..126 show as '?'. vertical: rotated 90 degrees counter-clockwise (reads bottom to top),
  // starting at (x, y) as its bottom-left corner.
  void text(int x, int y, const std::string& s, Rgba c, int scale = 1, bool vertical = false);
  static int text_width(const std::string& s, int scale = 1) { return int(s.size()) * 6 * scale - scale; }
  static int text_height(int scale = 1) { return 7 * scale; }
  // Writes the canvas as RGB (`with_alpha` false) or RGBA through write_image8; throws terrain::Error.
  void write_png(const std::string& path, bool with_alpha = false) const;

 private:
  int width_, height_;
  std::vector<uint8_t> pixels_;
};

// Short tick text: 3 significant digits, no trailing zeros ("0.25", "12.5", "1e+03").
std::string tick_label(double v);

}  // namespace cli
