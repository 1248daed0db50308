// terrain-report's pictures: --plot (rms, p99.9 and max per level on a log axis, labelled) and the
// --heatmap's colour scale bar below the map.
#include <catch2/catch.hpp>

#include "io/io_test_util.h"
#include "png_test_util.h"
#include "readers/terrain_generator.h"

using namespace terrain;

namespace {

int64_t count_colour(const std::vector<uint8_t>& px, int x0, int y0, int x1, int y1, int width, uint8_t r,
                     uint8_t g, uint8_t b) {
  int64_t n = 0;
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) {
      const uint8_t* p = &px[(size_t(y) * size_t(width) + size_t(x)) * 4];
      if (p[0] == r && p[1] == g && p[2] == b) ++n;
    }
  return n;
}

}  // namespace

TEST_CASE("terrain-report --plot and --heatmap draw labelled pictures", "[report]") {
  iotest::TempDir dir;
  const Heightmap map = synthesize_terrain(SynthOptions{.seed = 5, .width = 1201, .height = 1201});
  const std::string in = dir.file("N30E030.hgt"), pyr = dir.file("t.pyr");
  const std::string plot = dir.file("plot.png"), heat = dir.file("heat.png");
  iotest::write_file(in, iotest::hgt_bytes(map));
  // Also with coarse levels coded more finely (the calibration's coarse step ratio), where max and
  // p99.9 can coincide: max is drawn wider, so both stay visible.
  REQUIRE(iotest::run_tool(dir, {"pyramid-build", {in, "-o", pyr, "--rms", "1", "-q"}}).status == 0);
  const auto r =
      iotest::run_tool(dir, {"terrain-report", {in, pyr, "--plot", plot, "--heatmap", heat, "-q"}});
  INFO(r.err);
  REQUIRE(r.status == 0);
  int w = 0, h = 0;
  const std::vector<uint8_t> p = pngtest::read_rgba(plot, w, h);
  CHECK(w == 760);
  CHECK(h == 480);
  // The three series (max red, p99.9 orange, rms blue) inside the plot area and in the legend.
  CHECK(count_colour(p, 78, 36, 650, 422, w, 200, 40, 40) > 50);
  CHECK(count_colour(p, 78, 36, 650, 422, w, 230, 140, 20) > 50);
  CHECK(count_colour(p, 78, 36, 650, 422, w, 30, 80, 200) > 50);
  CHECK(count_colour(p, 650, 36, 760, 100, w, 30, 80, 200) > 20);
  // Labels: black text left of the axis (tick labels) and below it (the axis title).
  CHECK(count_colour(p, 0, 36, 70, 430, w, 0, 0, 0) > 100);
  CHECK(count_colour(p, 100, 450, 650, 480, w, 0, 0, 0) > 100);

  const std::vector<uint8_t> m = pngtest::read_rgba(heat, w, h);
  CHECK(w == 1201);
  REQUIRE(h == 1201 + 90);  // the map, then the scale panel (3x text for maps wider than 1200 px)
  // The bar (x 24..1176, from row 1213) runs from the ramp's black to its pale yellow; tick labels
  // and units in black below it.
  const int bar_y = 1201 + 12;
  CHECK(count_colour(m, 24, bar_y, 25, bar_y + 4, w, 0, 0, 0) == 4);
  CHECK(count_colour(m, 1176, bar_y, 1177, bar_y + 4, w, 255, 250, 150) == 4);
  CHECK(count_colour(m, 0, bar_y + 30, 1201, h, w, 0, 0, 0) > 300);
}
