// The level error schedule (--level-error): absolute (the paper's one step at every level) and
// screen (level l's step and max error 2^(m-l) times the finest level's). The target always refers
// to the finest level; screen files are smaller; max error holds per level at its own bound; zero
// error stays zero at every level.
#include <catch2/catch.hpp>
#include <cmath>

#include "build/pyramid_build.h"
#include "container/pyramid_file.h"
#include "io/io_test_util.h"
#include "readers/terrain_generator.h"
#include "runtime/region_decoder.h"

using namespace terrain;
using namespace terrain::container;
using namespace terrain::runtime;
using namespace terrain::build;

namespace {

BuildFileResult build_with(const std::string& src, const std::string& pyr, ErrorMode mode, double metres,
                           bool screen) {
  BuildFileOptions o;
  o.mode = mode;
  o.target_metres = metres;
  o.threads = 2;
  o.screen_level_error = screen;
  return build_pyramid_file(src, {}, pyr, o);
}

}  // namespace

TEST_CASE("level error schedule: screen grows each level's step with its spacing", "[e2e]") {
  iotest::TempDir dir;
  const Heightmap map = synthesize_terrain(SynthOptions{.seed = 5, .width = 700, .height = 600});
  const std::string src = dir.file("synth.raw");
  write_raw(src, map);

  SECTION("rms: the finest level meets the target, coarser levels get 2^(m-l) steps and fewer bytes") {
    const BuildFileResult a = build_with(src, dir.file("a.pyr"), ErrorMode::Rms, 1.0, false);
    const BuildFileResult s = build_with(src, dir.file("s.pyr"), ErrorMode::Rms, 1.0, true);
    const size_t m = s.build.levels.size() - 1;
    REQUIRE(m >= 2);
    for (size_t l = 0; l <= m; ++l) {
      CHECK(a.level_step_units[l] == a.step_units);
      CHECK(s.level_step_units[l] == Approx(s.step_units * std::ldexp(1.0, int(m - l))));
    }
    const double mpu = s.metres_per_unit;
    CHECK(s.build.levels[m].error_rms * mpu == Approx(1.0).epsilon(0.1));
    CHECK(a.build.levels[m].error_rms * mpu == Approx(1.0).epsilon(0.1));
    CHECK(s.build.levels[0].error_rms > 2 * a.build.levels[0].error_rms);  // coarse levels coarser
    // The coarse levels shrink; the whole file need not: with the residual transform (libcodec
    // format 5) a coarser level's larger error is re-coded in the finer residual's low band, and on
    // this smooth synthetic tile that costs more than the coarse levels save (docs/pyramid.md).
    for (size_t l = 0; l < m; ++l) CHECK(s.build.levels[l].bytes < a.build.levels[l].bytes);
    auto file = PyramidFile::open(dir.file("s.pyr"));
    CHECK(file->container().metadata_json().find("\"level_error\":\"screen\"") != std::string::npos);
  }
  SECTION("max error: every level within its own bound E 2^(m-l), the finest within E") {
    const BuildFileResult s = build_with(src, dir.file("m.pyr"), ErrorMode::MaxError, 2.0, true);
    const size_t m = s.build.levels.size() - 1;
    for (size_t l = 0; l <= m; ++l) {
      INFO("level " << l);
      CHECK(double(s.build.levels[l].error_max_abs) * s.metres_per_unit <= 2.0 * std::ldexp(1.0, int(m - l)));
    }
    CHECK(double(s.build.levels[m].error_max_abs) * s.metres_per_unit <= 2.0);
  }
  SECTION("lossless: zero error is zero at every level") {
    const BuildFileResult s = build_with(src, dir.file("l.pyr"), ErrorMode::Lossless, 0, true);
    for (const LevelBuildStats& l : s.build.levels) CHECK(l.error_max_abs == 0);
    for (double step : s.level_step_units) CHECK(step == 1);
  }
}
