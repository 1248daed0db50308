// Numerical stress suite (issue 7): pathological terrains through the real public API
// (build_pyramid_file + RegionDecoder). Every case states its bound and checks it:
//   * no NaN/Inf at valid samples, voids decode as NaN, coarse levels within [zmin - 4R - s,
//     zmax + 4R + s] (R = the input's range, s = the step: D's negative taps and the quantiser may
//     overshoot, but never blow up);
//   * --lossless: the finest level is exact;
//   * --max-error E: every valid finest sample within E (the builder guarantees it);
//   * --rms T: within 1.5 T (the step is calibrated on a window; the goal is 10 %, see e2e tests,
//     but these inputs are built to defeat calibration, so only "no blow-up" is asserted here).
// Two cases reproduce defects this suite found in the builder (flat-terrain rms calibration, level
// units beyond libcodec's range); both are fixed and the cases now guard them.
#include <catch2/catch.hpp>
#include <cstdint>
#include <fstream>
#include <iterator>
#include <random>

#include "stress_util.h"

using namespace stress;

namespace {

// A w x h grid of `type` whose sample (x, y) is f(x, y).
template <typename F> Heightmap grid_from(int64_t w, int64_t h, SampleType type, F f) {
  Heightmap m = make_grid(w, h, type);
  for (int64_t y = 0; y < h; ++y)
    for (int64_t x = 0; x < w; ++x) m.values[size_t(y * w + x)] = f(x, y);
  return m;
}

// Writes m as dir/name (raw + sidecar); returns the path.
std::string write_input(iotest::TempDir& dir, const std::string& name, const Heightmap& m) {
  const std::string src = dir.file(name);
  write_raw(src, m);
  return src;
}

// Builds src with `options` (a max-error target) and checks the case's bound: sane, and every
// valid finest sample within the target + tolerance. The outcome is returned for further checks.
Outcome check_max_error(const std::string& src, iotest::TempDir& dir, const BuildFileOptions& options,
                        double tolerance = 1e-9, const ReadOptions& ro = {}) {
  const Outcome m = build_and_measure(src, dir.file("m.pyr"), options, ro);
  STRESS_CHECK_SANE(m);
  CHECK(m.max_err <= options.target_metres + tolerance);
  return m;
}

// Builds src at --rms rms and checks that it stays sane and within `bound` metres rms.
void check_rms(const std::string& src, iotest::TempDir& dir, double rms, double bound) {
  const Outcome r = build_and_measure(src, dir.file("r.pyr"), target(ErrorMode::Rms, rms));
  STRESS_CHECK_SANE(r);
  CHECK(r.rms <= bound);
}

void lossless_and_max_error(const std::string& src, iotest::TempDir& dir, double max_error,
                            const ReadOptions& ro = {}) {
  const Outcome l = build_and_measure(src, dir.file("l.pyr"), target(ErrorMode::Lossless), ro);
  STRESS_CHECK_SANE(l);
  // Lossless is exact in level units; metres are units * scale + offset in double, which rounds by
  // ~1e-10 m at 1e6 m.
  CHECK(l.max_err <= 1e-6);
  check_max_error(src, dir, target(ErrorMode::MaxError, max_error), 1e-9, ro);
}

}  // namespace

TEST_CASE("stress: flat terrain codes to almost nothing, exactly", "[stress]") {
  iotest::TempDir dir;
  const std::string src = write_input(dir, "flat.raw", make_grid(300, 200, SampleType::Int16, 1234));
  const Outcome l = build_and_measure(src, dir.file("l.pyr"), target(ErrorMode::Lossless));
  STRESS_CHECK_SANE(l);
  CHECK(l.max_err == 0);
  CHECK(l.bits_per_sample < 1.0);  // bound: a constant costs only headers (60000 samples)
  lossless_and_max_error(src, dir, 0.5);
}

TEST_CASE("stress: rms target on flat terrain is not overshot (calibration keeps a step that meets it)",
          "[stress]") {
  iotest::TempDir dir;
  const std::string src = write_input(dir, "flat.raw", make_grid(300, 200, SampleType::Int16, 1234));
  for (double rms : {0.5, 4.0}) {
    INFO("rms target " << rms);
    check_rms(src, dir, rms, 1.5 * rms);
  }
}

TEST_CASE("stress: one 8000 m needle on a plain", "[stress]") {
  iotest::TempDir dir;
  Heightmap m = make_grid(257, 257, SampleType::Int16, 100);
  m.values[size_t(128 * 257 + 128)] = 8100;
  const std::string src = write_input(dir, "needle.raw", m);
  lossless_and_max_error(src, dir, 2);
  check_rms(src, dir, 1, 1.5);
}

TEST_CASE("stress: 8000 m cliffs, straight and diagonal", "[stress]") {
  iotest::TempDir dir;
  const Heightmap m = grid_from(200, 190, SampleType::Int16, [](int64_t x, int64_t y) {
    if (x + y > 250) return -500;  // a diagonal cliff cutting back down
    return x < 100 ? 0 : 8000;
  });
  const std::string src = write_input(dir, "cliff.raw", m);
  lossless_and_max_error(src, dir, 1);
  check_rms(src, dir, 2, 3.0);
}

TEST_CASE("stress: the full int16 range, alternating extremes and noise", "[stress]") {
  iotest::TempDir dir;
  Heightmap m = make_grid(131, 97, SampleType::Int16);
  std::mt19937 rng(11);
  for (int64_t y = 0; y < 97; ++y)
    for (int64_t x = 0; x < 131; ++x) {
      const size_t i = size_t(y * 131 + x);
      if (x < 40)
        m.values[i] = ((x + y) & 1) ? 32767 : -32768;  // worst-case swing, every sample
      else
        m.values[i] = double(int32_t(rng() % 65536u) - 32768);
    }
  lossless_and_max_error(write_input(dir, "range.raw", m), dir, 4);
}

TEST_CASE("stress: maximum-frequency checkerboard", "[stress]") {
  iotest::TempDir dir;
  const Heightmap m = grid_from(160, 144, SampleType::Int16,
                                [](int64_t x, int64_t y) { return ((x + y) & 1) ? 1000 : -1000; });
  const std::string src = write_input(dir, "checker.raw", m);
  lossless_and_max_error(src, dir, 2);
  check_rms(src, dir, 4, 6.0);
}

TEST_CASE("stress: 1e6 m offset plus centimetre detail, within libcodec's range", "[stress]") {
  iotest::TempDir dir;
  SECTION("float32 with a 1e6 m vertical_offset and centimetre values: max error 0.01 m") {
    Heightmap m = grid_from(150, 120, SampleType::Float32, [](int64_t x, int64_t y) {
      return double(float(0.01 * double((x * 7 + y * 13) % 23)));
    });
    m.info.vertical_offset = 1e6;
    // + 1e-6: float32 representation of the centimetre values.
    check_max_error(write_input(dir, "offset_f32b.raw", m), dir, target(ErrorMode::MaxError, 0.01), 1e-6);
  }
  SECTION("float32 at 1e6 m (input ulp 0.0625 m), quantum 1 m: max error 2 m holds") {
    const Heightmap m = grid_from(150, 120, SampleType::Float32, [](int64_t x, int64_t y) {
      return double(float(1e6 + 0.01 * double((x * 7 + y * 13) % 23) + 5 * std::sin(0.1 * double(x))));
    });
    BuildFileOptions o = target(ErrorMode::MaxError, 2);
    o.quantum_metres = 1;
    check_max_error(write_input(dir, "offset_f32.raw", m), dir, o);
  }
}

TEST_CASE("stress: level units beyond +-2^20 (libcodec's range) are centred by the builder", "[stress]") {
  // The coarsest level is coded as absolute values; inputs whose level units exceed
  // codec::kMaxAbsSample = 2^20 (1e6 m at the default 0.01 m float quantum, float bathymetry of
  // -11000 m = 1.1e6 centimetre units, int32 millimetre heights above 1048 m) used to fail with
  // "sample value out of range". The builder now subtracts an integer centring offset.
  iotest::TempDir dir;
  SECTION("int32 centimetre units at 1e6 m: lossless and max error 0.05 m") {
    Heightmap m = grid_from(150, 120, SampleType::Int32, [](int64_t x, int64_t y) {
      return std::round(1e8 + double((x * 7 + y * 13) % 23) + 50 * std::sin(0.1 * double(x)));
    });
    m.info.vertical_scale = 0.01;
    lossless_and_max_error(write_input(dir, "offset_i32.raw", m), dir, 0.05);
  }
  SECTION("float32 at 1e6 m, default 0.01 m quantum: max error 0.1 m") {
    const Heightmap m = grid_from(150, 120, SampleType::Float32, [](int64_t x, int64_t y) {
      return double(float(1e6 + 0.01 * double((x * 7 + y * 13) % 23) + 0.5 * std::sin(0.1 * double(x))));
    });
    check_max_error(write_input(dir, "offset_f32.raw", m), dir, target(ErrorMode::MaxError, 0.1));
  }
  SECTION("float32 bathymetry near -11000 m, default 0.01 m quantum: max error 0.5 m") {
    Heightmap m = make_grid(200, 150, SampleType::Float32);
    for (int64_t i = 0; i < 200 * 150; ++i)
      m.values[size_t(i)] = double(float(-11000 + 50 * std::sin(double(i) / 300.0)));
    check_max_error(write_input(dir, "trench.raw", m), dir, target(ErrorMode::MaxError, 0.5));
  }
}

TEST_CASE("stress: NaN and nodata regions stay voids, the rest within bounds", "[stress]") {
  iotest::TempDir dir;
  SECTION("int16 with -32768 voids: a block, a full row, a full column, scattered samples") {
    Heightmap m = grid_from(180, 150, SampleType::Int16, [](int64_t x, int64_t y) {
      if ((x >= 20 && x < 90 && y >= 30 && y < 100) || y == 120 || x == 150 || (x * 31 + y * 17) % 97 == 0)
        return -32768.0;
      return std::round(500 + 300 * std::sin(0.05 * double(x)) * std::cos(0.07 * double(y)));
    });
    m.info.nodata = -32768;
    lossless_and_max_error(write_input(dir, "voids.raw", m), dir, 1);
  }
  SECTION("float32 with NaN voids (nodata NaN)") {
    Heightmap m = grid_from(170, 130, SampleType::Float32, [](int64_t x, int64_t y) {
      if ((x / 16 + y / 16) % 3 == 0) return std::numeric_limits<double>::quiet_NaN();
      return 100.25 * std::sin(0.03 * double(x + y));
    });
    m.info.nodata = std::numeric_limits<double>::quiet_NaN();
    check_max_error(write_input(dir, "nan.raw", m), dir, target(ErrorMode::MaxError, 0.5));
  }
  SECTION("everything void but one sample") {
    Heightmap m = make_grid(40, 30, SampleType::Int16, -32768);
    m.info.nodata = -32768;
    m.values[size_t(15 * 40 + 20)] = 77;
    lossless_and_max_error(write_input(dir, "one.raw", m), dir, 1);
  }
}

TEST_CASE("stress: every grid from 1x1 to 7x7", "[stress]") {
  iotest::TempDir dir;
  for (int64_t h = 1; h <= 7; ++h)
    for (int64_t w = 1; w <= 7; ++w) {
      INFO(w << "x" << h);
      Heightmap m = make_grid(w, h, SampleType::Int16);
      for (int64_t i = 0; i < w * h; ++i) m.values[size_t(i)] = double((i * 2654435761u) % 2001) - 1000;
      lossless_and_max_error(write_input(dir, "tiny.raw", m), dir, 3);
    }
}

TEST_CASE("stress: 1e5 x 3 and 3 x 1e5 strips", "[stress]") {
  iotest::TempDir dir;
  for (const bool wide : {true, false}) {
    const int64_t w = wide ? 100000 : 3, h = wide ? 3 : 100000;
    INFO(w << "x" << h);
    Heightmap m = make_grid(w, h, SampleType::Int16);
    for (int64_t i = 0; i < w * h; ++i)
      m.values[size_t(i)] = std::round(1000 * std::sin(1e-3 * double(i)) + double(i % 7));
    lossless_and_max_error(write_input(dir, "strip.raw", m), dir, 2);
  }
}

TEST_CASE("stress: a 20-level pyramid", "[stress]") {
  iotest::TempDir dir;
  // 2^19 + 1 columns halve (rounding up) to 2 after 19 steps, so 20 levels exist above 1x1.
  const int64_t w = (int64_t(1) << 19) + 1;
  Heightmap m = make_grid(w, 1, SampleType::Int16);
  for (int64_t x = 0; x < w; ++x)
    m.values[size_t(x)] = std::round(2000 * std::sin(double(x) * 1e-4) + double(x % 13));
  const std::string src = write_input(dir, "deep.raw", m);
  BuildFileOptions o = target(ErrorMode::Lossless);
  o.levels = 20;
  const Outcome l = build_and_measure(src, dir.file("l.pyr"), o);
  STRESS_CHECK_SANE(l);
  CHECK(l.levels == 20);
  CHECK(l.max_err == 0);
  o = target(ErrorMode::MaxError, 3);
  o.levels = 20;
  CHECK(check_max_error(src, dir, o).levels == 20);
}

TEST_CASE("stress: repeated build/decode cycles do not drift", "[stress]") {
  // Each generation is the previous one's decode, rebuilt at the same max error E; every generation
  // stays within E of its own input. Bounds, against the original: the second generation adds an
  // error about as large as the first (two independent quantisations: rms up to sqrt(2) x), after
  // which the sequence must not random-walk: from generation 3 on, each generation moves the rms by
  // less than 2 % of the first generation's and changes fewer than 5 % of the samples (1 % from
  // generation 7 on), and the rms stays below 1.5 x the first generation's. Lossless generations are
  // then exact.
  // Measured (libcodec format 3, E = 3 m; `test_stress "<this name>" -s`): rms 1.87, 2.15, 2.16, 2.16,
  // 2.17, 2.17, 2.18, 2.19, 2.20, 2.21 m; changed samples 26432, 3853, 502, 295, 217, 243, 204, 152,
  // 181, 135 of 32300 (format 2: rms 2.07 .. 2.77 m). It is not
  // an exact fixed point (format 1 reached one after 4 generations at rms 2.35 m): D is re-fitted on
  // every generation and the lapped transform is not idempotent, so ~0.5 % of samples keep toggling.
  iotest::TempDir dir;
  Heightmap m = make_grid(190, 170, SampleType::Int16);
  std::mt19937 rng(5);
  for (int64_t y = 0; y < 170; ++y)
    for (int64_t x = 0; x < 190; ++x)
      m.values[size_t(y * 190 + x)] =
          std::round(800 * std::sin(0.04 * double(x)) * std::cos(0.05 * double(y)) + double(rng() % 9));
  const std::vector<double> original = m.values;
  const double E = 3;
  const int generations = 10;
  double first_rms = 0, previous_rms = 0;
  for (int gen = 0; gen < generations; ++gen) {
    INFO("generation " << gen);
    const Outcome o = check_max_error(write_input(dir, "gen.raw", m), dir, target(ErrorMode::MaxError, E));
    double sq = 0, worst = 0;
    int64_t changed = 0;
    for (size_t i = 0; i < original.size(); ++i) {
      const double e = o.finest[i] - original[i];
      sq += e * e;
      worst = std::max(worst, std::abs(e));
      changed += o.finest[i] != m.values[i];
    }
    const double rms = std::sqrt(sq / double(original.size()));
    if (gen == 0) first_rms = rms;
    CHECK(rms <= 1.5 * first_rms + 1e-9);
    if (gen >= 3) {
      CHECK(std::abs(rms - previous_rms) <= 0.02 * first_rms);
      CHECK(double(changed) <= (gen >= 7 ? 0.01 : 0.05) * double(original.size()));
    }
    std::printf("stress drift: generation %d: rms vs original %.4f m, max %.1f m, %lld samples changed\n",
                gen, rms, worst, (long long)changed);
    previous_rms = rms;
    m.values = o.finest;  // decoded metres are whole numbers here (integer input, integer step)
  }
  for (int gen = 0; gen < 3; ++gen) {
    const Outcome o =
        build_and_measure(write_input(dir, "lgen.raw", m), dir.file("lg.pyr"), target(ErrorMode::Lossless));
    CHECK(o.max_err == 0);
    m.values = o.finest;
  }
}

TEST_CASE("stress: output is identical for 1 and 2 build threads on a pathological grid", "[stress]") {
  iotest::TempDir dir;
  Heightmap m = make_grid(300, 280, SampleType::Int16);
  for (int64_t i = 0; i < 300 * 280; ++i) m.values[size_t(i)] = (i % 3 == 0) ? 8000 : double(i % 101);
  const std::string src = write_input(dir, "t.raw", m);
  BuildFileOptions a = target(ErrorMode::MaxError, 2), b = a;
  a.threads = 1;
  b.threads = 2;
  const Outcome oa = build_and_measure(src, dir.file("a.pyr"), a);
  const Outcome ob = build_and_measure(src, dir.file("b.pyr"), b);
  CHECK(oa.finest == ob.finest);
  CHECK(oa.bits_per_sample == ob.bits_per_sample);
  // The whole file, metadata included: nothing run-dependent (timings, thread count) may be stored.
  const auto bytes = [](const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  };
  const std::string fa = bytes(dir.file("a.pyr")), fb = bytes(dir.file("b.pyr"));
  REQUIRE(!fa.empty());
  CHECK(fa == fb);
}
