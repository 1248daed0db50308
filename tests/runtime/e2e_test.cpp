// End to end: heightmap file -> pyramid-build -> .pyr -> region decoder, against the source.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <random>
#include <sstream>

#include "build/pyramid_build.h"
#include "container/container.h"
#include "io/io_test_util.h"
#include "readers/terrain_generator.h"
#include "runtime/region_decoder.h"
#include "shared_data.h"

using namespace terrain;
using namespace terrain::runtime;
using namespace terrain::container;
using namespace terrain::build;

namespace {

struct Finest {
  double rms = 0, max = 0;
  int64_t nan_mismatch = 0;
  bool exact = true;
};

// Decodes the finest level in metres and compares it with the source file's valid samples.
Finest compare_finest(const std::string& pyr, const Heightmap& map) {
  auto file = PyramidFile::open(pyr);
  RegionDecoder dec(file);
  const int top = file->level_count() - 1;
  const int64_t w = map.width(), h = map.height();
  std::vector<float> out(size_t(w * h));
  dec.decode_metres(top, terrain::Rect{0, 0, w, h}, out.data(), w);
  std::vector<int32_t> units(size_t(w * h));
  dec.decode_units(top, terrain::Rect{0, 0, w, h}, units.data(), w);
  Finest f;
  double sq = 0;
  int64_t n = 0;
  for (int64_t i = 0; i < w * h; ++i) {
    const bool valid = map.valid.empty() || map.valid[size_t(i)];
    if (!valid) {
      if (!std::isnan(out[size_t(i)])) ++f.nan_mismatch;
      continue;
    }
    const double src = map.values[size_t(i)] * map.info.vertical_scale + map.info.vertical_offset;
    const double got = units[size_t(i)] * dec.metres_per_unit() + dec.metres_offset();
    const double e = got - src;
    if (std::abs(e) > 1e-9 * std::max(1.0, std::abs(src))) f.exact = false;
    sq += e * e;
    f.max = std::max(f.max, std::abs(e));
    ++n;
  }
  f.rms = std::sqrt(sq / double(std::max<int64_t>(1, n)));
  return f;
}

ReadOptions options_for(const std::string& path) {
  ReadOptions o;
  if (path.find("pugetsound") != std::string::npos) o.vertical_scale = 0.1;
  return o;
}

double bits_per_sample(uint64_t file_bytes, const Heightmap& map) {
  return 8.0 * double(file_bytes) / double(map.width() * map.height());
}

BuildFileOptions target(ErrorMode t, double metres) {
  BuildFileOptions o;
  o.mode = t;
  o.target_metres = metres;
  return o;
}

// synthesize_terrain(seed, width x height) written as a raw file in dir and built at quantiser step
// step_m into dir/name; returns the .pyr path.
std::string synthetic_pyramid(iotest::TempDir& dir, uint64_t seed, int64_t width, int64_t height,
                              double step_m, const std::string& name) {
  const std::string src = dir.file("synth.raw");
  write_raw(src, synthesize_terrain(SynthOptions{.seed = seed, .width = width, .height = height}));
  const std::string pyr = dir.file(name);
  build_pyramid_file(src, {}, pyr, target(ErrorMode::Step, step_m));  // default tile size
  return pyr;
}

// Calls body(dem, read options, heightmap, stem, scratch .pyr path) for each DEM of the heavy set.
template <class Body> void for_each_heavy_dem(Body&& body) {
  iotest::TempDir dir;
  for (const std::string& dem : testdata::dems_for_heavy_tests()) {
    const ReadOptions ro = options_for(dem);
    const Heightmap map = read_heightmap(dem, ro);
    const std::string name = std::filesystem::path(dem).stem().string();
    INFO(name);
    body(dem, ro, map, name, dir.file(name + ".pyr"));
  }
}

}  // namespace

// One case per mode, so that ctest runs them side by side (each builds a pyramid of every DEM).
TEST_CASE("e2e: every shared DEM codes losslessly", "[e2e]") {
  for_each_heavy_dem([](const std::string& dem, const ReadOptions& ro, const Heightmap& map,
                        const std::string& name, const std::string& pyr) {
    const auto r = build_pyramid_file(dem, ro, pyr, BuildFileOptions{});
    const Finest f = compare_finest(pyr, map);
    CHECK(f.exact);
    CHECK(f.nan_mismatch == 0);
    std::printf("e2e %-45s lossless %.3f b/s\n", name.c_str(), bits_per_sample(r.file_bytes, map));
  });
}

TEST_CASE("e2e: every shared DEM meets rms 1 m", "[e2e]") {
  for_each_heavy_dem([](const std::string& dem, const ReadOptions& ro, const Heightmap& map,
                        const std::string& name, const std::string& pyr) {
    const auto r = build_pyramid_file(dem, ro, pyr, target(ErrorMode::Rms, 1.0));
    const Finest f = compare_finest(pyr, map);
    // Integer-metre inputs that code losslessly at step 1 cannot reach 1 m rms from below; the
    // target is then met as closely as the quantum allows (the check states it).
    if (r.step_units > 1.0)
      CHECK(std::abs(f.rms - 1.0) <= 0.10);
    else
      CHECK(f.rms <= 1.10);
    CHECK(f.nan_mismatch == 0);
    std::printf("e2e %-45s rms1: %.3f b/s rms %.3f m\n", name.c_str(), bits_per_sample(r.file_bytes, map),
                f.rms);
  });
}

TEST_CASE("e2e: every shared DEM meets max-error 2 m", "[e2e]") {
  for_each_heavy_dem([](const std::string& dem, const ReadOptions& ro, const Heightmap& map,
                        const std::string& name, const std::string& pyr) {
    const auto r = build_pyramid_file(dem, ro, pyr, target(ErrorMode::MaxError, 2.0));
    const Finest f = compare_finest(pyr, map);
    CHECK(f.max <= 2.0 + 1e-6);
    CHECK(f.nan_mismatch == 0);
    std::printf("e2e %-45s max2: %.3f b/s max %.3f m rms %.3f m\n", name.c_str(),
                bits_per_sample(r.file_bytes, map), f.max, f.rms);
  });
}

TEST_CASE("e2e: decode_region equals the same window of a full decode, any level", "[e2e]") {
  iotest::TempDir dir;
  auto file = PyramidFile::open(synthetic_pyramid(dir, 7, 517, 389, 6, "s.pyr"));
  RegionDecoder full_dec(file, 0), roi_dec(file, size_t(1) << 20);
  std::mt19937 rng(42);
  for (int l = 0; l < file->level_count(); ++l) {
    const GridSize s = file->level_size(l);
    std::vector<int32_t> full(size_t(s.width * s.height));
    full_dec.decode_units(l, terrain::Rect{0, 0, s.width, s.height}, full.data(), s.width);
    for (int k = 0; k < 25; ++k) {
      const int64_t x0 = int64_t(rng() % uint64_t(s.width)), y0 = int64_t(rng() % uint64_t(s.height));
      const int64_t w = 1 + int64_t(rng() % uint64_t(s.width - x0)),
                    h = 1 + int64_t(rng() % uint64_t(s.height - y0));
      std::vector<int32_t> win(size_t(w * h));
      roi_dec.decode_units(l, terrain::Rect{x0, y0, w, h}, win.data(), w);
      bool same = true;
      for (int64_t y = 0; y < h && same; ++y)
        for (int64_t x = 0; x < w; ++x)
          if (win[size_t(y * w + x)] != full[size_t((y0 + y) * s.width + x0 + x)]) same = false;
      INFO("level " << l << " rect " << x0 << "," << y0 << " " << w << "x" << h);
      CHECK(same);
    }
  }
}

TEST_CASE("e2e: a 255x255 window touches at most 1.3x its area at its level", "[e2e]") {
  iotest::TempDir dir;
  auto file = PyramidFile::open(synthetic_pyramid(dir, 3, 1201, 1201, 4, "s.pyr"));
  const int top = file->level_count() - 1;
  std::mt19937 rng(5);
  double worst_level = 0, worst_all = 0, worst_reconstructed = 0;
  for (int k = 0; k < 20; ++k) {
    for (const size_t cache : {size_t(0), size_t(64) << 20}) {
      RegionDecoder dec(file, cache);  // cold: every residual tile it needs is decoded
      const int64_t x0 = int64_t(rng() % (1201 - 255)), y0 = int64_t(rng() % (1201 - 255));
      std::vector<int32_t> win(255 * 255);
      dec.decode_units(top, terrain::Rect{x0, y0, 255, 255}, win.data(), 255);
      const RegionStats s = dec.stats();
      const double area = 255.0 * 255.0;
      worst_level = std::max(worst_level, double(s.residual_samples_by_level[size_t(top)]) / area);
      worst_all = std::max(worst_all, double(s.residual_samples_decoded) / area);
      worst_reconstructed = std::max(worst_reconstructed, double(s.samples_reconstructed) / area);
    }
  }
  std::printf(
      "255x255 window at the finest level, cold cache, worst of 40: residual samples decoded at that level "
      "/ area = %.3f; all levels = %.3f; samples reconstructed (U + residual, all levels) / area = %.3f\n",
      worst_level, worst_all, worst_reconstructed);
  CHECK(worst_level <= 1.3);
  // The coarser windows (about 131, 69, 38 ... samples wide) also round up to whole 32-sample tiles,
  // so all levels together cost about 2.2x; a clipmap already holds those coarser levels.
  CHECK(worst_all <= 2.5);
  CHECK(worst_reconstructed <= 4.0 / 3.0 + 0.05);
}

TEST_CASE("e2e: corrupted pyramid files are rejected or the damaged tile reported, never a crash", "[e2e]") {
  iotest::TempDir dir;
  const std::vector<uint8_t> good = iotest::read_file(synthetic_pyramid(dir, 11, 200, 150, 3, "good.pyr"));
  std::mt19937 rng(99);
  int rejected = 0, reported = 0, unaffected = 0;
  for (int trial = 0; trial < 150; ++trial) {
    std::vector<uint8_t> bad = good;
    const int flips = 1 + int(rng() % 4);
    for (int f = 0; f < flips; ++f) bad[rng() % bad.size()] ^= uint8_t(1 + rng() % 255);
    const std::string path = dir.file("bad.pyr");
    iotest::write_file(path, bad);
    try {
      auto file = PyramidFile::open(path);
      RegionDecoder dec(file, 0);
      const int top = file->level_count() - 1;
      const GridSize s = file->level_size(top);
      std::vector<float> out(size_t(s.width * s.height));
      dec.decode_metres(top, terrain::Rect{0, 0, s.width, s.height}, out.data(), s.width);
      ++unaffected;  // the flip hit padding or a field nothing reads
    } catch (const Error& e) {
      CHECK(std::string(e.what()).find(path) != std::string::npos);
      (std::string(e.what()).find("band") != std::string::npos ? reported : rejected)++;
    }
  }
  std::printf("corruption: %d rejected on open, %d damaged tiles reported, %d unaffected\n", rejected,
              reported, unaffected);
  CHECK(rejected + reported >= 140);
}

TEST_CASE("e2e: pyramid-build fails cleanly on a truncated input and leaves no output", "[e2e]") {
  iotest::TempDir dir;
  const Heightmap map = synthesize_terrain(SynthOptions{.seed = 1, .width = 1201, .height = 1201});
  const std::vector<uint8_t> whole = iotest::hgt_bytes(map);
  // A copy of the prefix rather than resize(): GCC 12 under ASan warns (-Wstringop-overflow) on the
  // shrinking resize, a false positive.
  const std::vector<uint8_t> hgt(whole.begin(), whole.end() - 1000);
  const std::string in = dir.file("N10E010.hgt");
  iotest::write_file(in, hgt);
  const std::string out = dir.file("out.pyr");
  const auto r = iotest::run_tool(dir, {"pyramid-build", {in, "-o", out, "--rms", "1", "-q"}});
  CHECK(r.status == 3);
  CHECK(r.err.find(in) != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(out));
  for (auto& e : std::filesystem::directory_iterator(std::filesystem::path(out).parent_path()))
    CHECK(e.path().filename().string().find("out.pyr") == std::string::npos);
}

TEST_CASE("e2e: values beyond the coder's range are an option error naming the file, not an internal one",
          "[e2e]") {
  iotest::TempDir dir;
  // int32 millimetres with 2.8 km of relief (more than the 2^21 units a pyramid codes: found by the
  // calibration sample), and one spike the sample misses (found by the coder).
  const auto write = [&](const std::string& name, int64_t w, int64_t h, auto value) {
    Heightmap map;
    map.info.width = w;
    map.info.height = h;
    map.info.sample_type = SampleType::Int32;
    map.values.resize(size_t(w * h));
    for (int64_t y = 0; y < h; ++y)
      for (int64_t x = 0; x < w; ++x) map.values[size_t(y * w + x)] = value(x, y);
    const std::string path = dir.file(name);
    write_raw(path, map);
    return path;
  };
  const std::string wide = write("wide.raw", 300, 200, [](int64_t x, int64_t y) {
    return std::round(1500000 + 1400000 * std::sin(double(x) / 30) * std::cos(double(y) / 20));
  });
  const std::string spike = write("spike.raw", 3000, 300,
                                  [](int64_t x, int64_t y) { return x == 3 && y == 150 ? 3000000.0 : 0.0; });
  for (const std::string& in : {wide, spike})
    for (const char* mode : {"--lossless", "--step"}) {
      INFO(in << " " << mode);
      const std::string out = dir.file("out.pyr");
      std::vector<std::string> args = {in, "-o", out, mode, "-q"};
      if (std::string(mode) == "--step") args.insert(args.end() - 1, "2");
      const auto r = iotest::run_tool(dir, {"pyramid-build", args});
      CHECK(r.status == 1);
      CHECK(r.err.find(in) != std::string::npos);
      CHECK(r.err.find("2^2") != std::string::npos);
      CHECK(r.err.find("internal error") == std::string::npos);
      CHECK_FALSE(std::filesystem::exists(out));
    }
}

TEST_CASE("e2e: clipmap-view --max-screen-error picks the clipmap size and the original confirms it",
          "[e2e]") {
  // pyramid-build --rms 1, then clipmap-view with a 1-pixel tolerance: it must choose a size 2^k - 1,
  // record it in stats.json, and the screen-space analysis against the original input must find
  // every rendered level's 99.9th percentile within the tolerance. Usage errors come first.
  iotest::TempDir dir;
  const Heightmap map = synthesize_terrain(SynthOptions{.seed = 7, .width = 1201, .height = 1201});
  const std::string in = dir.file("N20E020.hgt"), pyr = dir.file("t.pyr"), out = dir.file("frames");
  iotest::write_file(in, iotest::hgt_bytes(map));
  REQUIRE(iotest::run_tool(dir, {"pyramid-build", {in, "-o", pyr, "--rms", "1", "-q"}}).status == 0);
  CHECK(iotest::run_tool(dir, {"clipmap-view", {pyr, "--n", "255", "--max-screen-error", "1"}}).status == 1);
  CHECK(iotest::run_tool(dir, {"clipmap-view", {pyr, "--max-screen-error", "0"}}).status == 1);
  {  // damaged pyramids: the documented exit codes (6 not a pyramid, 3 truncated), the file named
    const std::string text = dir.file("text.pyr"), cut = dir.file("cut.pyr");
    iotest::write_file(text,
                       std::string("this is not a pyramid file, though it is long enough for a header"));
    std::vector<uint8_t> bytes = iotest::read_file(pyr);
    bytes.resize(bytes.size() / 2);
    iotest::write_file(cut, bytes);
    const auto not_pyramid = iotest::run_tool(dir, {"clipmap-view", {text}});
    CHECK(not_pyramid.status == 6);
    CHECK(not_pyramid.err.find(text) != std::string::npos);
    const auto truncated = iotest::run_tool(dir, {"clipmap-view", {cut}});
    CHECK(truncated.status == 3);
    CHECK(truncated.err.find(cut) != std::string::npos);
  }
  const auto r = iotest::run_tool(dir, {"clipmap-view",
                                        {pyr, "--original", in, "--max-screen-error", "1", "--fov", "73.74",
                                         "--frames", "1", "--png-every", "0", "--out", out}});
  REQUIRE(r.status == 0);
  const auto pos = r.err.find("--max-screen-error 1 px: n = ");
  REQUIRE(pos != std::string::npos);
  const int n = std::atoi(r.err.c_str() + pos + 29);
  INFO(r.err << r.out);
  CHECK(n >= 15);
  CHECK(((n + 1) & n) == 0);
  const std::vector<uint8_t> json = iotest::read_file(out + "/stats.json");
  const std::string stats(json.begin(), json.end());
  CHECK(stats.find("\"n\": " + std::to_string(n)) != std::string::npos);
  CHECK(stats.find("\"max_screen_error_px\": 1") != std::string::npos);
  // The table: "level spacing rms_m max_m rms_px p99.9_px max_px" rows after its header.
  std::istringstream table(r.out.substr(r.out.find("p99.9_px")));
  std::string line;
  std::getline(table, line);
  int rows = 0;
  while (std::getline(table, line)) {
    std::istringstream row(line);
    int level;
    double spacing, rms_m, max_m, rms_px, p999_px, max_px;
    if (!(row >> level >> spacing >> rms_m >> max_m >> rms_px >> p999_px >> max_px)) break;
    INFO("level " << level);
    CHECK(p999_px <= 1.0);
    ++rows;
  }
  CHECK(rows >= 3);
}

TEST_CASE("e2e: terrain-info describes a pyramid from its index, --verify checks every level", "[e2e]") {
  // The per-level error figures terrain-info reads from the file must be exactly those pyramid-build
  // reported (both print the shortest exact form); a flipped byte in a level is found by --verify
  // only (exit 10), and --verify on a heightmap is a usage error.
  iotest::TempDir dir;
  const Heightmap map = synthesize_terrain(SynthOptions{.seed = 11, .width = 1201, .height = 1201});
  const std::string in = dir.file("N10E010.hgt"), pyr = dir.file("t.pyr"), report = dir.file("build.json");
  iotest::write_file(in, iotest::hgt_bytes(map));
  REQUIRE(iotest::run_tool(dir, {"pyramid-build", {in, "-o", pyr, "--rms", "2", "--json", report, "-q"}})
              .status == 0);
  const auto figures = [](const std::string& json, const std::string& key) {
    std::vector<std::string> found;
    for (size_t at = json.find(key); at != std::string::npos; at = json.find(key, at + 1))
      found.push_back(json.substr(at, json.find_first_of(",\n}", at) - at));
    return found;
  };
  const std::vector<uint8_t> build_bytes = iotest::read_file(report);
  const std::string build(build_bytes.begin(), build_bytes.end());
  const auto text = iotest::run_tool(dir, {"terrain-info", {pyr}});
  REQUIRE(text.status == 0);
  // This writer's version (the test named 2.0 until 2026-12-07: a ';' in its name kept ctest from
  // running it, see tests/CMakeLists.txt).
  CHECK(text.out.find("pyramid (.pyr) version " + std::to_string(container::kFormatMajor) + "." +
                      std::to_string(container::kFormatMinor)) != std::string::npos);
  CHECK(text.out.find("1201 x 1201 (finest level)") != std::string::npos);
  const auto json = iotest::run_tool(dir, {"terrain-info", {pyr, "--json", "--verify"}});
  REQUIRE(json.status == 0);
  CHECK(json.out.find("\"checksums_verified\": true") != std::string::npos);
  for (const std::string key : {"\"error_rms_m\"", "\"error_max_m\""}) {
    INFO(key);
    const auto expected = figures(build, key);
    CHECK(expected.size() >= 3);
    CHECK(figures(json.out, key) == expected);
  }

  std::vector<uint8_t> bytes = iotest::read_file(pyr);
  bytes[bytes.size() / 2] ^= 0x10;  // inside the finest level's blob (levels come coarsest first)
  const std::string bad = dir.file("bad.pyr");
  iotest::write_file(bad, bytes);
  CHECK(iotest::run_tool(dir, {"terrain-info", {bad}}).status == 0);  // index intact
  const auto verified = iotest::run_tool(dir, {"terrain-info", {bad, "--verify"}});
  CHECK(verified.status == 10);
  CHECK(verified.err.find(bad) != std::string::npos);
  CHECK(iotest::run_tool(dir, {"terrain-info", {in, "--verify"}}).status == 1);
}
