// The clipmap over a real compressed pyramid file: RegionDecoderSource fills each clipmap level with
// exactly the decoder's T^_level (inside the terrain) and with the nearest edge sample outside it.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <random>

#include "build/pyramid_build.h"
#include "io/io_test_util.h"
#include "readers/terrain_generator.h"
#include "runtime/clipmap.h"
#include "runtime/height_source.h"
#include "runtime/region_decoder.h"
#include "runtime/screen_error.h"

using namespace terrain;
using namespace terrain::runtime;
using namespace terrain::container;
using namespace terrain::build;

namespace {

// A synthetic terrain written as <dir>/t.raw (with its sidecar); returns it.
Heightmap write_terrain(const iotest::TempDir& dir, int64_t width, int64_t height, uint64_t seed) {
  SynthOptions so;
  so.width = width;
  so.height = height;
  so.seed = seed;
  Heightmap map = synthesize_terrain(so);
  write_raw(dir.file("t.raw"), map);
  return map;
}

BuildFileOptions build_options(int levels) {
  BuildFileOptions bo;
  bo.levels = levels;
  bo.threads = 1;
  return bo;
}

}  // namespace

TEST_CASE("clipmap: a decoded pyramid fills the levels with the decoder's samples", "[clipmap]") {
  iotest::TempDir dir;
  write_terrain(dir, 300, 260, 5);
  BuildFileOptions bo = build_options(4);
  bo.mode = ErrorMode::Step;
  bo.target_metres = 4.0;
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
      decoder->decode_metres(cm.source_level(l), Rect{0, 0, size.width, size.height}, level.data(),
                             size.width);
      const Rect c = cm.clip_region(l);
      int64_t outside = 0;
      for (int64_t y = c.y0; y < c.y0 + c.height; ++y)
        for (int64_t x = c.x0; x < c.x0 + c.width; ++x) {
          const int64_t sx = std::clamp<int64_t>(x, 0, size.width - 1),
                        sy = std::clamp<int64_t>(y, 0, size.height - 1);
          outside += (sx != x || sy != y) ? 1 : 0;
          REQUIRE(cm.heights(l)[cm.index(x, y)] == level[size_t(sy * size.width + sx)]);
        }
      INFO("level " << l);
      CHECK(outside > 0);
    }
  }
}

TEST_CASE("clipmap: the original input's in-memory reference equals a lossless pyramid file, level by level",
          "[clipmap]") {
  // original_source rebuilds the original's pyramid with the file's D: for a lossless file every
  // decoded level must equal it exactly, and the finest level's screen-space error must be 0. For a
  // lossy file the finest level's error is the compression error, and coarser levels err more.
  iotest::TempDir dir;
  const Heightmap map = write_terrain(dir, 200, 170, 11);
  BuildFileOptions bo = build_options(3);
  build_pyramid_file(dir.file("t.raw"), ReadOptions{}, dir.file("lossless.pyr"), bo);
  bo.mode = ErrorMode::Step;
  bo.target_metres = 8.0;
  build_pyramid_file(dir.file("t.raw"), ReadOptions{}, dir.file("lossy.pyr"), bo);

  auto file = PyramidFile::open(dir.file("lossless.pyr"));
  const int finest = file->level_count() - 1;
  const GridHeightSource original =
      original_source(dir.file("t.raw"), ReadOptions{}, file->level_size(finest), file->level_count(),
                      file->downsample_filter(), 30.0);
  REQUIRE(original.level_count() == 3);
  RegionDecoderSource lossless(std::make_shared<const RegionDecoder>(file), 30.0);
  for (int l = 0; l < 3; ++l) {
    const GridSize s = original.level_size(l);
    std::vector<float> decoded(size_t(s.width * s.height));
    lossless.fill(l, Rect{0, 0, s.width, s.height}, decoded.data(), s.width);
    INFO("level " << l);
    CHECK(decoded == original.level(l));
  }
  for (int64_t i = 0; i < map.width() * map.height(); i += 997)
    CHECK(original.level(finest)[size_t(i)] == float(map.metres(i % map.width(), i / map.width())));

  const double s_px = triangle_size_px(640, 480, 60, 255);
  CHECK(s_px == Approx(1.25 * 640 / (255 * std::tan(M_PI / 6) * 640 / 480)));
  const auto exact = screen_space_error(lossless, original, 0, s_px);
  REQUIRE(exact.size() == 3);
  CHECK(exact[2].max_px == 0.0);
  CHECK(exact[0].rms_px > 0.0);  // a coarse level misses the finest detail

  auto lossy_file = PyramidFile::open(dir.file("lossy.pyr"));
  RegionDecoderSource lossy(std::make_shared<const RegionDecoder>(lossy_file), 30.0);
  const auto e = screen_space_error(lossy, original, 0, s_px);
  REQUIRE(e.size() == 3);
  CHECK(e[2].rms_m > 0.0);
  {  // the file records the finest level's error as the builder measured it: the same figures
    const std::optional<LevelError> finest_error = level_error_metres(lossy_file->info(), 2);
    REQUIRE(finest_error.has_value());
    CHECK(finest_error->max_abs == Approx(e[2].max_m));
    CHECK(finest_error->rms == Approx(e[2].rms_m).epsilon(1e-4));
  }
  {  // at the finest level PL(T^_m) is T^_m itself: the error is the plain sample difference
    const GridSize s = original.level_size(finest);
    std::vector<float> decoded(size_t(s.width * s.height));
    lossy.fill(finest, Rect{0, 0, s.width, s.height}, decoded.data(), s.width);
    double max_diff = 0;
    for (size_t i = 0; i < decoded.size(); ++i)
      max_diff = std::max(max_diff, std::abs(double(decoded[i]) - double(original.level(finest)[i])));
    CHECK(e[2].max_m == Approx(max_diff));
  }
  CHECK(e[2].rms_px == Approx(e[2].rms_m * s_px / 30.0));
  CHECK(e[2].p999_px <= e[2].max_px);
  CHECK(e[0].spacing_m == 120.0);
}

TEST_CASE("clipmap: the screen-space error estimate from the pyramid alone, and the clipmap size it picks",
          "[clipmap]") {
  // With a lossless pyramid the file's own finest level is the original, so the estimate over the
  // whole level equals the analysis against the original; over windows (a subset of the samples)
  // no level's maximum can exceed the whole level's.
  iotest::TempDir dir;
  const Heightmap map = write_terrain(dir, 300, 260, 5);
  build_pyramid_file(dir.file("t.raw"), ReadOptions{}, dir.file("lossless.pyr"), build_options(3));
  auto file = PyramidFile::open(dir.file("lossless.pyr"));
  const GridHeightSource original = original_source(dir.file("t.raw"), ReadOptions{}, file->level_size(2), 3,
                                                    file->downsample_filter(), 30.0);
  RegionDecoderSource source(std::make_shared<const RegionDecoder>(file), 30.0);
  const double s_px = triangle_size_px(640, 480, 60, 255);
  const auto truth = screen_space_error(source, original, 0, s_px);
  const auto whole = estimate_screen_space_error(source, 0, s_px);
  REQUIRE(whole.size() == 3);
  for (size_t l = 0; l < 3; ++l) {
    INFO("level " << l);
    CHECK(whole[l].rms_m == truth[l].rms_m);
    CHECK(whole[l].p999_px == truth[l].p999_px);
    CHECK(whole[l].max_m == truth[l].max_m);
  }
  CHECK(whole[0].p999_px > 0.0);
  CHECK(whole[2].max_m == 0.0);
  const auto sampled = estimate_screen_space_error(source, 1, s_px, 256 * 256);  // one 256x256 window
  REQUIRE(sampled.size() == 2);
  CHECK(sampled[0].level == 1);
  CHECK(sampled[0].rms_m > 0.0);
  CHECK(sampled[0].max_m <= whole[1].max_m);

  // The size: errors scale as s ~ 1/n; the smallest 2^k - 1 within the tolerance.
  double worst = 0;
  for (const auto& e : whole) worst = std::max(worst, e.p999_px / s_px);
  for (double tolerance : {0.05, 0.2, 1.0}) {
    const ClipmapSizeChoice c = clipmap_size_for_screen_error(whole, s_px, 640, 480, 60, tolerance);
    INFO("tolerance " << tolerance << " n " << c.n);
    CHECK(((c.n + 1) & c.n) == 0);
    CHECK(c.p999_px == Approx(worst * triangle_size_px(640, 480, 60, c.n)));
    if (c.met) {
      CHECK(c.p999_px <= tolerance);
      if (c.n > 15) CHECK(worst * triangle_size_px(640, 480, 60, c.n / 2) > tolerance);
    } else {
      CHECK(c.n == 1023);
    }
  }
  CHECK(clipmap_size_for_screen_error(whole, s_px, 640, 480, 60, 1000.0).n == 15);

  // A lossy pyramid: its finest level is not the original any more, and the estimate plus the
  // finest level's recorded error must bound the true figures on every level.
  BuildFileOptions bo = build_options(3);
  bo.mode = ErrorMode::Step;
  bo.target_metres = 16.0;
  build_pyramid_file(dir.file("t.raw"), ReadOptions{}, dir.file("lossy.pyr"), bo);
  auto lossy_file = PyramidFile::open(dir.file("lossy.pyr"));
  RegionDecoderSource lossy(std::make_shared<const RegionDecoder>(lossy_file), 30.0);
  const auto lossy_truth = screen_space_error(lossy, original, 0, s_px);
  auto bound = estimate_screen_space_error(lossy, 0, s_px);
  const LevelError finest_error = level_error_metres(lossy_file->info(), 2).value();
  REQUIRE(finest_error.max_abs > 0.0);
  CHECK(bound[2].max_px == 0.0);  // alone, the estimate sees no error at the finest level
  CHECK(lossy_truth[2].p999_px > 0.0);
  add_finest_error_bound(bound, finest_error.rms, finest_error.max_abs, s_px);
  for (size_t l = 0; l < 3; ++l) {
    INFO("level " << l << ": bound " << bound[l].p999_px << " px, true " << lossy_truth[l].p999_px << " px");
    CHECK(bound[l].rms_px >= lossy_truth[l].rms_px);
    CHECK(bound[l].p999_px >= lossy_truth[l].p999_px);
    CHECK(bound[l].max_px >= lossy_truth[l].max_px);
    CHECK(bound[l].max_m >= lossy_truth[l].max_m);
  }
  CHECK(bound[2].max_m == Approx(lossy_truth[2].max_m));  // at the finest level the bound is exact
  const ClipmapSizeChoice unreachable = clipmap_size_for_screen_error(whole, s_px, 640, 480, 60, 1e-9);
  CHECK(!unreachable.met);
  CHECK(unreachable.n == 1023);
}

TEST_CASE("clipmap: levels refined from the coarser clipmap level equal the decoder's, voids too",
          "[clipmap]") {
  // The clipmap keeps each level's integer units and decodes only the residual of a finer level
  // (U of its own coarser level + R^, paper §5). Whatever the path, every level must hold exactly
  // the decoder's T^ (edges repeated outside the terrain, voids as 0 m), during a walk in and out.
  iotest::TempDir dir;
  Heightmap map = write_terrain(dir, 520, 500, 7);
  map.info.nodata = -32768;
  for (int64_t y = 200; y < 260; ++y)
    for (int64_t x = 300; x < 330; ++x) map.values[size_t(y * map.width() + x)] = -32768;
  write_raw(dir.file("t.raw"), map);
  BuildFileOptions bo = build_options(4);
  bo.mode = ErrorMode::Step;
  bo.target_metres = 4.0;
  build_pyramid_file(dir.file("t.raw"), ReadOptions{}, dir.file("t.pyr"), bo);
  auto file = PyramidFile::open(dir.file("t.pyr"));
  REQUIRE(file->info().void_count == 60 * 30);
  auto decoder = std::make_shared<RegionDecoder>(file, size_t(1) << 20);
  RegionDecoderSource source(decoder, 30.0);
  REQUIRE(source.refines_units());
  std::vector<std::vector<float>> levels;
  for (int l = 0; l < source.level_count(); ++l) {
    const GridSize s = source.level_size(l);
    levels.emplace_back(size_t(s.width * s.height));
    decoder->decode_metres(l, Rect{0, 0, s.width, s.height}, levels.back().data(), s.width);
    for (float& v : levels.back())
      if (std::isnan(v)) v = 0.0f;
  }
  ClipmapOptions o;
  o.n = 31;
  o.budget = 1 << 30;
  o.deactivate_by_height = false;
  Clipmap cm(source, o);
  // All clip regions inside the terrain: each level is decoded once, without recursion.
  decoder->reset_stats();
  const ClipmapUpdateStats first = cm.update(260 * 30.0, 250 * 30.0, 5000.0);
  CHECK(first.samples_filled == 4 * 31 * 31);
  CHECK(decoder->stats().samples_reconstructed == uint64_t(first.samples_filled));
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> step(-150.0, 150.0), jump(-6000.0, 6000.0);
  double x = 260 * 30.0, y = 250 * 30.0;
  for (int frame = 0; frame < 120; ++frame) {
    if (frame % 40 == 39) x += jump(rng), y += jump(rng);
    x = std::clamp(x + step(rng), -3000.0, 18000.0);
    y = std::clamp(y + step(rng), -3000.0, 18000.0);
    cm.update(x, y, 5000.0);
    for (int l = 0; l < cm.level_count(); ++l) {
      const GridSize size = source.level_size(l);
      const Rect c = cm.clip_region(l);
      bool same = true;
      for (int64_t v = c.y0; v < c.y0 + c.height; ++v)
        for (int64_t u = c.x0; u < c.x0 + c.width; ++u) {
          const int64_t su = std::clamp<int64_t>(u, 0, size.width - 1),
                        sv = std::clamp<int64_t>(v, 0, size.height - 1);
          same = same && cm.heights(l)[cm.index(u, v)] == levels[size_t(l)][size_t(sv * size.width + su)];
        }
      INFO("frame " << frame << " level " << l);
      REQUIRE(same);
    }
  }
}
