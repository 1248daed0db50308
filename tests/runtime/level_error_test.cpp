// The level error schedule (--level-error): absolute (the paper's one step at every level) and
// screen (level l's step and max error 2^(m-l) times the finest level's), and the coarse step ratio
// (--coarse-step-ratio: level l's step R^min(m-l, 2) times the finest's, R <= 1, chosen by the rms
// calibration unless given). The target always refers to the finest level; max error holds per level
// at its own bound; zero error stays zero at every level.
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>

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

// ratio: BuildFileOptions::coarse_step_ratio (0: automatic); 1 keeps the paper's one absolute step.
BuildFileResult build_with(const std::string& src, const std::string& pyr, ErrorMode mode, double metres,
                           bool screen, double ratio = 1) {
  BuildFileOptions o;
  o.mode = mode;
  o.target_metres = metres;
  o.threads = 2;
  o.screen_level_error = screen;
  o.coarse_step_ratio = mode == ErrorMode::Rms || mode == ErrorMode::Step ? ratio : 0;
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

TEST_CASE(
    "coarse step ratio: coarse levels R^min(m-l, 2) times the finest step, chosen by the rms calibration",
    "[e2e]") {
  iotest::TempDir dir;
  // Smooth terrain (the generator's heights flattened to a fifth), where finer coarse levels pay, and
  // the generator's own relief, where they need not.
  Heightmap smooth = synthesize_terrain(SynthOptions{.seed = 9, .width = 640, .height = 576});
  for (double& v : smooth.values) v = std::round(v / 5);
  const std::string src = dir.file("smooth.raw");
  write_raw(src, smooth);

  SECTION("a given ratio: each level's step, at least 1, combined with the screen schedule") {
    const BuildFileResult r = build_with(src, dir.file("r.pyr"), ErrorMode::Step, 8.0, false, 0.5);
    const size_t m = r.build.levels.size() - 1;
    REQUIRE(m >= 2);
    CHECK(r.coarse_step_ratio == 0.5);
    for (size_t l = 0; l <= m; ++l)
      CHECK(r.level_step_units[l] == Approx(std::max(1.0, 8.0 * std::pow(0.5, std::min(int(m - l), 2)))));
    // Coarse levels at a smaller step are more accurate than at the finest level's.
    const BuildFileResult a = build_with(src, dir.file("a.pyr"), ErrorMode::Step, 8.0, false, 1);
    for (size_t l = 0; l < m; ++l) CHECK(r.build.levels[l].error_rms < a.build.levels[l].error_rms);
    const BuildFileResult s = build_with(src, dir.file("s.pyr"), ErrorMode::Step, 8.0, true, 0.5);
    for (size_t l = 0; l <= m; ++l)
      CHECK(s.level_step_units[l] ==
            Approx(8.0 * std::ldexp(1.0, int(m - l)) * std::pow(0.5, std::min(int(m - l), 2))));
    auto file = PyramidFile::open(dir.file("r.pyr"));
    CHECK(file->container().metadata_json().find("\"coarse_step_ratio\":0.5") != std::string::npos);
  }
  SECTION("rms: the calibration's ratio is never worse than the paper's, the target still met") {
    for (double metres : {1.0, 2.0, 4.0}) {
      INFO("rms " << metres);
      const BuildFileResult one = build_with(src, dir.file("one.pyr"), ErrorMode::Rms, metres, false, 1);
      const BuildFileResult chosen = build_with(src, dir.file("auto.pyr"), ErrorMode::Rms, metres, false, 0);
      const size_t m = chosen.build.levels.size() - 1;
      CHECK(one.coarse_step_ratio == 1);
      CHECK(chosen.coarse_step_ratio <= 1);
      CHECK(chosen.build.levels[m].error_rms * chosen.metres_per_unit == Approx(metres).epsilon(0.1));
      // The calibration compares the ratios on its sample (here the whole input), 1 % apart at least.
      CHECK(chosen.file_bytes <= one.file_bytes + 64);
      std::printf("coarse step ratio, smooth synthetic, rms %.0f m: ratio %.2f, %ju bytes (ratio 1: %ju)\n",
                  metres, chosen.coarse_step_ratio, uintmax_t(chosen.file_bytes), uintmax_t(one.file_bytes));
    }
  }
  SECTION("out-of-range ratios and ratios with bounded targets are option errors") {
    for (double bad : {-0.5, 1.5, std::nan("")}) {
      BuildFileOptions o;
      o.mode = ErrorMode::Step;
      o.target_metres = 4;
      o.coarse_step_ratio = bad;
      try {
        build_pyramid_file(src, {}, dir.file("bad.pyr"), o);
        FAIL("ratio " << bad << " accepted");
      } catch (const Error& e) {
        CHECK(e.code() == ErrorCode::InvalidOption);
      }
    }
    for (ErrorMode mode : {ErrorMode::MaxError, ErrorMode::Lossless}) {
      BuildFileOptions o;
      o.mode = mode;
      o.target_metres = mode == ErrorMode::MaxError ? 2 : 0;
      o.coarse_step_ratio = 0.5;
      CHECK_THROWS_AS(build_pyramid_file(src, {}, dir.file("bad.pyr"), o), Error);
    }
    CHECK_FALSE(std::filesystem::exists(dir.file("bad.pyr")));
  }
}

TEST_CASE(
    "rms calibration: the target is a bound, and a target only step 1 meets builds the lossless pyramid",
    "[e2e]") {
  iotest::TempDir dir;
  Heightmap terrain = synthesize_terrain(SynthOptions{.seed = 4, .width = 520, .height = 448});
  for (double& v : terrain.values) v = std::round(v);
  const std::string src = dir.file("t.raw");
  write_raw(src, terrain);
  // The sample is the whole input here (448 rows), so the file's rms is the calibrated one.
  for (double metres : {0.5, 1.0, 3.0}) {
    INFO("rms " << metres);
    const BuildFileResult r = build_with(src, dir.file("r.pyr"), ErrorMode::Rms, metres, false, 0);
    const double rms = r.build.levels.back().error_rms * r.metres_per_unit;
    CHECK(rms <= metres);
    CHECK(rms >= 0.9 * metres);
  }
  // Integer heights: 0.05 m is below what any step above 1 gives; the transforms at step 1 would be
  // exact too, but the lossless build (point sampling, phase tiles) codes them in fewer bytes.
  const BuildFileResult tiny = build_with(src, dir.file("tiny.pyr"), ErrorMode::Rms, 0.05, false, 0);
  const BuildFileResult lossless = build_with(src, dir.file("lossless.pyr"), ErrorMode::Lossless, 0, false);
  CHECK(tiny.step_units == 1);
  CHECK(tiny.build.levels.back().error_rms == 0);
  CHECK(tiny.build.levels.back().error_max_abs == 0);
  // The same levels; only the metadata (the target and options) differs.
  CHECK(tiny.file_bytes <= lossless.file_bytes + 64);
  BuildFileOptions wavelet;
  wavelet.mode = ErrorMode::Rms;
  wavelet.target_metres = 0.05;
  wavelet.downsample = DownsampleChoice::Wavelet;  // a D the user names is kept
  const BuildFileResult named = build_pyramid_file(src, {}, dir.file("named.pyr"), wavelet);
  CHECK(named.build.levels.back().error_rms == 0);
  CHECK(named.file_bytes > tiny.file_bytes);
}
