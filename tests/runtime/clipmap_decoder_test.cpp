// The clipmap over a real compressed pyramid file: RegionDecoderSource fills each clipmap level with
// exactly the decoder's T^_level (inside the terrain) and with the nearest edge sample outside it.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>

#include "io/io_test_util.h"
#include "pyramid/synth.h"
#include "runtime/clipmap.h"
#include "runtime/pyramid_build.h"
#include "runtime/region_decoder.h"

using namespace terrain;
using namespace terrain::runtime;

TEST_CASE("clipmap: a decoded pyramid fills the levels with the decoder's samples", "[clipmap]") {
  iotest::TempDir dir;
  SynthOptions so;
  so.width = 300;
  so.height = 260;
  so.seed = 5;
  const Heightmap map = synthesize_terrain(so);
  write_raw(dir.file("t.raw"), map);
  BuildFileOptions bo;
  bo.target = ErrorTarget::Step;
  bo.target_metres = 4.0;
  bo.levels = 4;
  bo.threads = 1;
  build_pyramid_file(dir.file("t.raw"), ReadOptions{}, dir.file("t.pyr"), bo);
  auto file = PyramidFile::open(dir.file("t.pyr"));
  auto decoder = std::make_shared<const RegionDecoder>(file);
  RegionDecoderSource source(decoder, 30.0);
  REQUIRE(source.level_count() == 4);

  ClipmapOptions o;
  o.n = 63;
  o.budget = 1 << 30;
  o.deactivate_by_height = false;
  Clipmap cm(source, o);
  // Near a corner, so that the clip regions reach outside the terrain on two sides.
  for (const auto& at : {std::array<double, 2>{600.0, 450.0}, std::array<double, 2>{8000.0, 7000.0}}) {
    cm.update(at[0], at[1], 5000.0);
    for (int l = 0; l < cm.level_count(); ++l) {
      const GridSize size = source.level_size(cm.source_level(l));
      std::vector<float> level(size_t(size.width * size.height));
      decoder->decode_metres(cm.source_level(l), Rect{0, 0, size.width, size.height}, level.data(), size.width);
      const Rect c = cm.clip_region(l);
      int64_t outside = 0;
      for (int64_t y = c.y0; y < c.y0 + c.height; ++y)
        for (int64_t x = c.x0; x < c.x0 + c.width; ++x) {
          const int64_t sx = std::clamp<int64_t>(x, 0, size.width - 1), sy = std::clamp<int64_t>(y, 0, size.height - 1);
          outside += (sx != x || sy != y) ? 1 : 0;
          REQUIRE(cm.heights(l)[cm.index(x, y)] == level[size_t(sy * size.width + sx)]);
        }
      INFO("level " << l);
      CHECK(outside > 0);
    }
  }
}
