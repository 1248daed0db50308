// Hostile inputs that used to hang a tool or grow its memory without bound: FIFOs and devices given
// where a file is expected are refused at once with exit status 2, naming the file.
#include <sys/stat.h>

#include <catch2/catch.hpp>
#include <string>

#include "io/io_test_util.h"

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
