// clipmap-view --edit-script --edit-pyramid (issue 20): edits written into the file during a flight,
// the clipmap refilling what they reach; its last frame equals a fresh flight's over the edited file.
#include <catch2/catch.hpp>
#include <fstream>
#include <string>

#include "build/pyramid_build.h"
#include "io/io_test_util.h"
#include "readers/terrain_generator.h"

using namespace terrain;

TEST_CASE("clipmap-view --edit-pyramid: the last frame equals a fresh flight over the edited file",
          "[clipmap][edit]") {
  iotest::TempDir dir;
  const std::string raw = dir.file("t.raw"), pyr = dir.file("t.pyr"), edited = dir.file("e.pyr");
  write_raw(raw, synthesize_terrain(SynthOptions{.seed = 9, .width = 257, .height = 257}));
  build::BuildFileOptions bo;
  bo.mode = container::ErrorMode::Rms;
  bo.target_metres = 1;
  build::build_pyramid_file(raw, {}, pyr, bo);
  iotest::write_file(edited, iotest::read_file(pyr));
  // A still camera south of the middle (30 m spacing), looking north at the edits: a pit at frame 3,
  // a channel at frame 6.
  const std::string path = dir.file("p.txt"), script = dir.file("e.txt");
  iotest::write_file(path, std::string("0 3840 1500 600 90 -20\n11 3840 1500 600 90 -20\n"));
  iotest::write_file(script,
                     std::string("0.1 brush 128 128 20 -60 smooth\n0.2 channel 100 110 160 150 4 30\n"));
  auto flight = [&](const std::string& file, const std::string& out, bool edit) {
    std::vector<std::string> args{file,   "--path",      path,  "--frames", "12",          "--n",
                                  "63",   "--width",     "160", "--height", "120",         "--budget",
                                  "4000", "--png-every", "11",  "--out",    dir.file(out), "-q"};
    if (edit) args.insert(args.end(), {"--edit-script", script, "--edit-pyramid"});
    const auto r = iotest::run_tool(dir, {"clipmap-view", args});
    INFO(r.err);
    REQUIRE(r.status == 0);
    return iotest::read_file(dir.file(out) + "/frame_00011.png");
  };
  const std::vector<uint8_t> before = flight(pyr, "orig", false);
  const std::vector<uint8_t> live = flight(edited, "live", true);
  CHECK(iotest::read_file(edited) != iotest::read_file(pyr));  // written through
  const std::vector<uint8_t> fresh = flight(edited, "fresh", false);
  CHECK(live == fresh);
  CHECK(live != before);  // the edits show
  // stats.csv counts the two edits.
  std::ifstream csv(dir.file("live") + "/stats.csv");
  std::string line;
  std::getline(csv, line);
  int column = 0, edits_column = -1;
  for (size_t at = 0, next; at != std::string::npos;
       at = next == std::string::npos ? next : next + 1, ++column) {
    next = line.find(',', at);
    if (line.substr(at, next == std::string::npos ? std::string::npos : next - at) == "edits")
      edits_column = column;
  }
  REQUIRE(edits_column >= 0);
  int edits = 0;
  while (std::getline(csv, line)) {
    size_t at = 0;
    for (int c = 0; c < edits_column; ++c) at = line.find(',', at) + 1;
    edits += std::stoi(line.substr(at));
  }
  CHECK(edits == 2);
}
