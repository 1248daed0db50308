// Hostile inputs that used to hang a tool or grow its memory without bound: FIFOs and devices given
// where a file is expected are refused at once with exit status 2, naming the file.
#include <sys/stat.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <random>
#include <string>

#include "container/container.h"
#include "container/internal/container_format.h"
#include "io/io_test_util.h"
#include "readers/image8.h"
#include "runtime/pyr_test_util.h"
#include "shared_data.h"

namespace {

// Runs a tool under `timeout 20` (a hang fails the test instead of the suite) and returns its status.
int run_bounded(const iotest::TempDir& dir, const std::string& tool, const std::vector<std::string>& args,
                std::string* err = nullptr) {
  std::string cmd = "timeout 20 ";  // appended piecewise: GCC 12 warns (-Wrestrict) on "literal" + string
  cmd += iotest::shell_quote(iotest::tool_path(tool));
  for (const auto& a : args) cmd.append(" ").append(iotest::shell_quote(a));
  const std::string err_file = dir.file(tool + ".err");
  cmd.append(" </dev/null >/dev/null 2>").append(iotest::shell_quote(err_file));
  const int raw = std::system(cmd.c_str());
  if (err) {
    const auto e = iotest::read_file(err_file);
    err->assign(e.begin(), e.end());
  }
  return raw != -1 && WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
}

}  // namespace

TEST_CASE("FIFOs and devices as inputs are refused at once (no hang, no endless read)",
          "[runtime][hostile]") {
  iotest::TempDir dir;
  const std::string fifo = dir.file("pipe.pyr");
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  const std::string raw = dir.file("g.raw"), pyr = dir.file("g.pyr");
  REQUIRE(
      iotest::run_tool(dir, {"terrain-synth", {"-o", raw, "--width", "64", "--height", "48", "-q"}}).status ==
      0);
  REQUIRE(iotest::run_tool(dir, {"pyramid-build", {raw, "-o", pyr, "--lossless", "-q"}}).status == 0);
  std::string err;
  CHECK(run_bounded(dir, "terrain-info", {fifo}, &err) == 2);
  CHECK_THAT(err, Catch::Contains("pipe.pyr") && Catch::Contains("not a regular file"));
  CHECK(run_bounded(dir, "terrain-report", {raw, fifo}, &err) == 2);
  CHECK_THAT(err, Catch::Contains("pipe.pyr"));
  CHECK(run_bounded(dir, "terrain-report", {fifo, pyr}) == 2);
  CHECK(run_bounded(dir, "pyramid-extract", {fifo, "-o", dir.file("x.tif")}) == 2);
  const std::string frames = dir.file("frames");
  CHECK(run_bounded(dir, "clipmap-view", {fifo, "--frames", "1", "--out", frames, "-q"}) == 2);
  CHECK(run_bounded(dir, "clipmap-view", {pyr, "--path", fifo, "--out", frames, "-q"}, &err) == 2);
  CHECK_THAT(err, Catch::Contains("not a regular file"));
  CHECK(run_bounded(dir, "clipmap-view", {pyr, "--path", "/dev/zero", "--out", frames, "-q"}) == 2);
}

TEST_CASE("constant and all-void grids and very loose targets build (they used to exit 70)",
          "[runtime][hostile]") {
  iotest::TempDir dir;
  const auto raw = [&](const std::string& name, const std::string& type, const std::string& nodata,
                       const std::vector<uint8_t>& sample) {
    std::vector<uint8_t> bytes;
    for (int i = 0; i < 300 * 200; ++i) bytes.insert(bytes.end(), sample.begin(), sample.end());
    iotest::write_file(dir.file(name), bytes);
    iotest::write_file(dir.file(name) + ".json",
                       "{\"width\": 300, \"height\": 200, \"type\": \"" + type + "\"" + nodata + "}");
    return dir.file(name);
  };
  const std::vector<std::string> inputs = {
      raw("c16.raw", "int16", "", {0xd2, 0x04}),                               // 1234 everywhere
      raw("cf.raw", "float32", "", {0x00, 0x00, 0x48, 0x41}),                  // 12.5 everywhere
      raw("nan.raw", "float32", ", \"nodata\": \"NaN\"", {0, 0, 0xc0, 0x7f}),  // every sample void
  };
  std::vector<uint8_t> white(size_t(64 * 48 * 3), 0xff);  // Terrain-RGB 0xFFFFFF: 1667721.5 m
  terrain::write_image8(dir.file("white.png"), 64, 48, 3, white.data());
  const std::vector<std::vector<std::string>> targets = {
      {"--rms", "1"}, {"--rms", "1e6"}, {"--max-error", "2"}, {"--max-error", "1e6"}, {"--step", "5"}};
  for (const std::string& in : {inputs[0], inputs[1], inputs[2], dir.file("white.png")})
    for (const auto& t : targets) {
      std::vector<std::string> args = {in, "-o", dir.file("out.pyr"), "-q"};
      args.insert(args.end(), t.begin(), t.end());
      std::string err;
      INFO(in << " " << t[0] << " " << t[1]);
      CHECK(run_bounded(dir, "pyramid-build", args, &err) == 0);
      CHECK(err.empty());
      if (in != dir.file("white.png")) CHECK(std::filesystem::file_size(dir.file("out.pyr")) < 4096);
    }
  const std::string dem = testdata::require("srtm3_N46W122_rainier_adams_cascades.hgt");
  if (dem.empty()) return;
  for (const auto& t : {std::vector<std::string>{"--rms", "1e6"}, {"--max-error", "1e6"}}) {
    INFO(t[0]);
    CHECK(run_bounded(dir, "pyramid-build", {dem, "-o", dir.file("r.pyr"), t[0], t[1], "-q"}) == 0);
  }
}

TEST_CASE("outputs never replace devices or inputs, and write errors are failures", "[runtime][hostile]") {
  iotest::TempDir dir;
  const std::string raw = dir.file("g.raw"), pyr = dir.file("g.pyr");
  REQUIRE(iotest::run_tool(dir, {"terrain-synth", {"-o", raw, "--width", "300", "--height", "240", "-q"}})
              .status == 0);
  std::string err;
  // -o /dev/null used to rename the temporary over the device node (as root).
  CHECK(run_bounded(dir, "pyramid-build", {raw, "-o", "/dev/null", "--lossless", "-q"}, &err) == 9);
  CHECK_THAT(err, Catch::Contains("/dev/null") && Catch::Contains("not a regular file"));
  struct stat st {};
  REQUIRE(::stat("/dev/null", &st) == 0);
  CHECK(S_ISCHR(st.st_mode));
  // The input, or its sidecar, as the output.
  const auto before = iotest::read_file(raw), sidecar = iotest::read_file(raw + ".json");
  CHECK(run_bounded(dir, "pyramid-build", {raw, "-o", raw, "--lossless", "-q"}, &err) == 9);
  CHECK_THAT(err, Catch::Contains("is the input"));
  CHECK(run_bounded(dir, "pyramid-build", {raw, "-o", raw + ".json", "--lossless", "-q"}) == 9);
  CHECK(iotest::read_file(raw) == before);
  CHECK(iotest::read_file(raw + ".json") == sidecar);
  // Reports that cannot be written: --json to a full device, data on a full stdout.
  REQUIRE(run_bounded(dir, "pyramid-build", {raw, "-o", pyr, "--lossless", "-q"}) == 0);
  CHECK(run_bounded(dir, "pyramid-build", {raw, "-o", pyr, "--lossless", "--json", "/dev/full", "-q"},
                    &err) == 9);
  CHECK_THAT(err, Catch::Contains("/dev/full"));
  CHECK(run_bounded(dir, "terrain-report", {raw, pyr, "--json", "/dev/full", "-q"}) == 9);
  CHECK(std::system(("timeout 20 " + iotest::shell_quote(iotest::tool_path("terrain-info")) + " " +
                     iotest::shell_quote(pyr) + " --json >/dev/full 2>/dev/null; test $? -eq 9")
                        .c_str()) == 0);
  const std::string device_link = dir.file("null.tif");  // a name that looks right, pointing at a device
  REQUIRE(::symlink("/dev/null", device_link.c_str()) == 0);
  CHECK(run_bounded(dir, "pyramid-extract", {pyr, "-o", device_link, "-q"}) == 9);
  // A full disk, as an 8 KiB file-size limit: exit 9, nothing left under the final or a temporary name.
  const std::string out = dir.file("big.pyr");
  const std::string cmd = "ulimit -f 8; timeout 20 " +
                          iotest::shell_quote(iotest::tool_path("pyramid-build")) + " " +
                          iotest::shell_quote(raw) + " -o " + iotest::shell_quote(out) +
                          " --lossless -q 2>/dev/null; test $? -eq 9";
  CHECK(std::system(("bash -c " + iotest::shell_quote(cmd)).c_str()) == 0);
  CHECK_FALSE(std::filesystem::exists(out));
  for (const auto& e : std::filesystem::directory_iterator(dir.file("")))
    CHECK(e.path().filename().string().find("big.pyr") == std::string::npos);
}

TEST_CASE("a damaged TIFF is an error, not rows of zeros", "[runtime][hostile]") {
  iotest::TempDir dir;
  const std::string tif = dir.file("t.tif");
  REQUIRE(iotest::run_tool(dir, {"terrain-synth", {"-o", tif, "--width", "300", "--height", "200", "-q"}})
              .status == 0);
  const auto bytes = iotest::read_file(tif);
  REQUIRE(bytes.size() > 2000);
  REQUIRE(run_bounded(dir, "pyramid-build", {tif, "-o", dir.file("ok.pyr"), "--lossless", "-q"}) == 0);
  for (const size_t keep : {size_t(1000), bytes.size() / 2, bytes.size() - 10}) {
    INFO("truncated to " << keep << " of " << bytes.size() << " bytes");
    const std::string cut = dir.file("cut.tif");
    iotest::write_file(cut, std::vector<uint8_t>(bytes.begin(), bytes.begin() + ptrdiff_t(keep)));
    std::string err;
    CHECK(run_bounded(dir, "pyramid-build", {cut, "-o", dir.file("cut.pyr"), "--lossless", "-q"}, &err) ==
          10);
    CHECK_THAT(err, Catch::Contains("cut.tif"));
    CHECK_FALSE(std::filesystem::exists(dir.file("cut.pyr")));
  }
}

TEST_CASE("terrain-report against an input without the pyramid's voids gives finite figures and says so",
          "[runtime][hostile]") {
  iotest::TempDir dir;
  const int w = 120, h = 90;
  std::vector<uint8_t> with_voids, filled;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int16_t v = int16_t(200 + (x * 7 + y * 3) % 90);
      const int16_t stored = (x > 30 && x < 50 && y > 20 && y < 40) ? int16_t(-32768) : v;
      for (int b = 0; b < 2; ++b) with_voids.push_back(uint8_t(uint16_t(stored) >> (8 * b)));
      for (int b = 0; b < 2; ++b) filled.push_back(uint8_t(uint16_t(v) >> (8 * b)));
    }
  const std::string side = "{\"width\": 120, \"height\": 90, \"type\": \"int16\"";
  iotest::write_file(dir.file("voids.raw"), with_voids);
  iotest::write_file(dir.file("voids.raw.json"), side + ", \"nodata\": -32768}");
  iotest::write_file(dir.file("filled.raw"), filled);
  iotest::write_file(dir.file("filled.raw.json"), side + "}");
  REQUIRE(run_bounded(dir, "pyramid-build",
                      {dir.file("voids.raw"), "-o", dir.file("v.pyr"), "--rms", "1", "-q"}) == 0);
  const iotest::ToolResult r =
      iotest::run_tool(dir, {"terrain-report", {dir.file("filled.raw"), dir.file("v.pyr"), "--json", "-"}});
  CHECK(r.status == 10);
  CHECK(r.out.find("nan") == std::string::npos);
  CHECK(r.out.find("inf") == std::string::npos);
  CHECK(r.out.find("\"voids_added\": 361") != std::string::npos);  // 19 x 19 samples
}

TEST_CASE("forged .pyr fields with recomputed checksums are rejected on open", "[runtime][hostile]") {
  namespace info = terrain::container::layout::info;
  namespace sb = terrain::container::layout::sb;
  iotest::TempDir dir;
  const std::string raw = dir.file("g.raw"), pyr = dir.file("g.pyr");
  REQUIRE(
      iotest::run_tool(dir, {"terrain-synth", {"-o", raw, "--width", "90", "--height", "70", "-q"}}).status ==
      0);
  REQUIRE(iotest::run_tool(dir, {"pyramid-build", {raw, "-o", pyr, "--rms", "1", "-q"}}).status == 0);
  const std::vector<uint8_t> good = iotest::read_file(pyr);
  const size_t index = size_t(pyrtest::get_le(good, sb::kIndexOffset, 8));
  const auto rejected = [&](std::vector<uint8_t> b, const std::string& what) {
    pyrtest::reseal(b);
    const std::string forged = dir.file("forged.pyr");
    iotest::write_file(forged, b);
    INFO(what);
    try {
      terrain::container::Container::open(forged);
      FAIL_CHECK("accepted: " << what);
    } catch (const terrain::Error& e) {
      CHECK(e.code() == terrain::ErrorCode::CorruptData);
    }
    CHECK(run_bounded(dir, "terrain-info", {forged}) == 10);
  };
  {
    std::vector<uint8_t> b = good;  // untouched, resealed: still fine
    pyrtest::reseal(b);
    iotest::write_file(dir.file("same.pyr"), b);
    CHECK_NOTHROW(terrain::container::Container::open(dir.file("same.pyr")));
  }
  for (const double step : {0.0, -1.0, 0.5}) {
    std::vector<uint8_t> b = good;
    pyrtest::put_f64(b, index + info::kStepUnits, step);
    rejected(b, "step_units " + std::to_string(step));
  }
  {
    std::vector<uint8_t> b = good;
    pyrtest::put_f64(b, index + info::kTarget, -1.0);
    rejected(b, "target -1");
  }
  {
    std::vector<uint8_t> b = good;
    b[index + info::kVerticalUnits] = 0xC3;  // a lead byte with no continuation: invalid UTF-8
    b[index + info::kVerticalUnits + 1] = 'x';
    rejected(b, "invalid UTF-8 units");
  }
  {
    std::vector<uint8_t> b = good;  // 64 zero bytes after everything, the recorded size updated
    b.resize(b.size() + 64, 0);
    pyrtest::put_le(b, sb::kFileSize, b.size(), 8);
    rejected(b, "bytes after the last region");
  }
}

TEST_CASE("the rms target is calibrated on the whole input: a tile whose top rows are all sea still meets it",
          "[runtime][hostile]") {
  // 600 x 1500: the top 1100 rows flat sea (0), below them rough mountains. Calibrating on the
  // first 1024 rows alone saw only sea and chose a step far too large or too small.
  iotest::TempDir dir;
  const int w = 600, h = 1500;
  std::mt19937 rng(12345);
  std::uniform_real_distribution<double> noise(0, 32);
  std::vector<int16_t> heights(size_t(w * h), 0);
  for (size_t i = size_t(1100 * w); i < heights.size(); ++i) {
    const double x = double(i % size_t(w)), y = double(i / size_t(w));
    heights[i] = int16_t(std::lround(800 + 500 * std::sin(x / 23.0) * std::cos(y / 31.0) +
                                     90 * std::sin(x / 5.0 + y / 7.0) + noise(rng)));
  }
  std::vector<uint8_t> bytes(heights.size() * 2);
  std::memcpy(bytes.data(), heights.data(), bytes.size());  // little-endian host, as the sidecar says
  iotest::write_file(dir.file("coast.raw"), bytes);
  iotest::write_file(dir.file("coast.raw.json"), "{\"width\": 600, \"height\": 1500, \"type\": \"int16\"}");
  for (const double target : {1.0, 2.0}) {
    const iotest::ToolResult r =
        iotest::run_tool(dir, {"pyramid-build",
                               {dir.file("coast.raw"), "-o", dir.file("c.pyr"), "--rms",
                                std::to_string(target), "--json", "-", "-q"}});
    REQUIRE(r.status == 0);
    const iotest::ToolResult rep = iotest::run_tool(
        dir, {"terrain-report", {dir.file("coast.raw"), dir.file("c.pyr"), "--json", "-", "-q"}});
    REQUIRE(rep.status == 0);
    // The finest level's rms is the last "rms_m" of the report's levels.
    const size_t at = rep.out.rfind("\"rms_m\": ");
    REQUIRE(at != std::string::npos);
    const double rms = std::stod(rep.out.substr(at + 9));
    INFO("target " << target << " m, finest rms " << rms << " m");
    CHECK(std::abs(rms / target - 1) <= 0.10);
  }
}

TEST_CASE("sizes that wrap and oversized side files are refused before any allocation",
          "[runtime][hostile]") {
  iotest::TempDir dir;
  iotest::write_file(dir.file("zero.raw"), std::string());
  iotest::write_file(dir.file("zero.raw.json"),
                     "{\"width\": 2147483648, \"height\": 2147483648, \"type\": \"float32\"}");
  std::string err;
  CHECK(run_bounded(dir, "terrain-info", {dir.file("zero.raw")}, &err) == 5);  // 2^64 bytes wrapped to 0
  CHECK_THAT(err, Catch::Contains("zero.raw"));
  iotest::write_file(dir.file("e.bil"), std::string(100, '\0'));
  iotest::write_file(dir.file("e.hdr"), "NROWS 5\nNCOLS 10\n" + std::string(size_t(1) << 20, 'X') + "\n");
  CHECK(run_bounded(dir, "terrain-info", {dir.file("e.bil")}, &err) == 8);
  CHECK_THAT(err, Catch::Contains("e.hdr") && Catch::Contains("larger than"));
}

TEST_CASE("unusable values read from a file are exit 8 naming the file and the field", "[runtime][hostile]") {
  iotest::TempDir dir;
  iotest::write_file(dir.file("g.raw"), std::vector<uint8_t>(size_t(64 * 48 * 2), 7));
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"\"spacing_x\": -30", "spacing_x"},
      {"\"spacing_x\": 0", "spacing_x"},
      {"\"spacing_y\": \"NaN\"", "spacing_y"},
      {"\"vertical_scale\": 0", "vertical_scale"},
      {"\"vertical_scale\": -1", "vertical_scale"},
      {"\"horizontal_units\": \"" + std::string(100, 'm') + "\"", "horizontal_units"}};
  for (const auto& [field, name] : bad) {
    INFO(field);
    iotest::write_file(dir.file("g.raw.json"),
                       "{\"width\": 64, \"height\": 48, \"type\": \"int16\", " + field + "}");
    std::string err;
    CHECK(run_bounded(dir, "pyramid-build", {dir.file("g.raw"), "-o", dir.file("g.pyr"), "--lossless", "-q"},
                      &err) == 8);
    CHECK_THAT(err, Catch::Contains("g.raw") && Catch::Contains(name));
    CHECK(run_bounded(dir, "terrain-info", {dir.file("g.raw")}) == 8);
  }
}

TEST_CASE("mirror-tile refuses an output larger than the free disk before writing", "[runtime][hostile]") {
  iotest::TempDir dir;
  const std::string tile = dir.file("t.raw");
  REQUIRE(iotest::run_tool(dir, {"terrain-synth", {"-o", tile, "--width", "16", "--height", "16", "-q"}})
              .status == 0);
  std::string err;
  CHECK(
      run_bounded(dir, "mirror-tile",
                  {tile, "-o", dir.file("huge.raw"), "--out-width", "1048576", "--out-height", "2147483648"},
                  &err) == 9);
  CHECK_THAT(err, Catch::Contains("free"));
  CHECK_FALSE(std::filesystem::exists(dir.file("huge.raw")));
  CHECK(run_bounded(dir, "mirror-tile", {tile, "-o", tile}) == 1);  // usage: --out-width missing
  CHECK(run_bounded(dir, "mirror-tile", {tile, "-o", tile, "--out-width", "4", "--out-height", "4"}) == 9);
}
