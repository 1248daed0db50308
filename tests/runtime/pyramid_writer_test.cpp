// The pyramid file writer puts levels in file order itself: the same bytes whatever order the bands
// arrive in, and no file written beyond the output's own exclusive temporary.
#include <sys/inotify.h>
#include <unistd.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "container/internal/held_bytes.h"
#include "container/pyramid_file.h"
#include "io/io_test_util.h"
#include "readers/terrain_generator.h"

using namespace terrain;
using namespace terrain::container;

namespace {

std::set<std::string> directory_listing(const std::string& dir) {
  std::set<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(dir)) names.insert(e.path().filename().string());
  return names;
}

// Names created in (or renamed into) a directory while the watch lives, seen through inotify, so
// that files created and removed again are caught too.
class DirectoryWatch {
 public:
  explicit DirectoryWatch(const std::string& dir) : fd_(inotify_init1(IN_NONBLOCK | IN_CLOEXEC)) {
    REQUIRE(fd_ >= 0);
    REQUIRE(inotify_add_watch(fd_, dir.c_str(), IN_CREATE | IN_MOVED_TO) >= 0);
  }
  ~DirectoryWatch() { ::close(fd_); }
  DirectoryWatch(const DirectoryWatch&) = delete;
  DirectoryWatch& operator=(const DirectoryWatch&) = delete;
  std::vector<std::string> created() {
    std::vector<std::string> names;
    alignas(inotify_event) char buf[1 << 16];
    for (ssize_t n; (n = ::read(fd_, buf, sizeof buf)) > 0;)
      for (char* p = buf; p < buf + n;) {
        const auto* e = reinterpret_cast<const inotify_event*>(p);
        if (e->len) names.emplace_back(e->name);
        p += sizeof(inotify_event) + e->len;
      }
    return names;
  }

 private:
  int fd_;
};

bool starts_with(const std::string& s, const std::string& prefix) { return s.rfind(prefix, 0) == 0; }

// Synthetic terrain with voids (a block and scattered samples), so that the mask is written too.
Heightmap terrain_with_voids(int64_t w, int64_t h) {
  Heightmap map = synthesize_terrain(SynthOptions{.seed = 3, .width = w, .height = h});
  map.valid.assign(map.values.size(), 1);
  for (int64_t y = h / 3; y < h / 3 + 40; ++y)
    for (int64_t x = 10; x < 90; ++x) map.valid[size_t(y * w + x)] = 0;
  for (int64_t k = 0; k < 300; ++k) map.valid[size_t((k * 7919) % (w * h))] = 0;
  return map;
}

// Replays recorded bands into a writer: `order` lists levels, one entry per band, each level's bands
// taken top to bottom; the mask rows go with each finest band, as the builder sends them.
void replay(const MemoryPyramid& p, const std::vector<int>& order, PyramidFileWriter& out) {
  out.begin(p.header);
  const int finest = int(p.header.levels.size()) - 1;
  const int64_t width = p.header.levels.back().width;
  std::vector<size_t> next(p.bands.size(), 0);
  for (int level : order) {
    const MemoryPyramid::Band& b = p.bands[size_t(level)][next[size_t(level)]++];
    if (level == finest) {
      const std::vector<uint8_t> all_valid(size_t(b.rows * width), 1);
      out.mask_rows(b.y0, b.rows, p.mask.empty() ? all_valid.data() : p.mask.data() + b.y0 * width);
    }
    out.band(level, b.y0, b.rows, std::vector<uint8_t>(b.bytes));
  }
}

}  // namespace

TEST_CASE("pyramid writer: the same file whatever order the bands arrive in", "[runtime][container]") {
  iotest::TempDir dir;
  const Heightmap map = terrain_with_voids(300, 1500);
  BuildOptions bo;
  bo.level_count = 4;
  UniformQuantizerCoder coder(3, 16);
  ContainerInfo info;
  const std::string json = "{\"test\":true}";

  // As the builder produces them (interleaved).
  const std::string produced = dir.file("produced.pyr");
  PyramidFileWriter direct(produced);
  const BuildResult result = build_pyramid(map, bo, coder, direct);
  direct.finish(result, info, json);
  const std::vector<uint8_t> expect = iotest::read_file(produced);
  REQUIRE(result.void_count > 0);

  MemoryPyramid recorded;
  recorded.keep_reconstruction = false;
  build_pyramid(map, bo, coder, recorded);
  std::vector<int> level_order, reversed, shuffled;
  for (int l = 0; l < 4; ++l)
    for (size_t b = 0; b < recorded.bands[size_t(l)].size(); ++b) level_order.push_back(l);
  for (int l = 3; l >= 0; --l)
    for (size_t b = 0; b < recorded.bands[size_t(l)].size(); ++b) reversed.push_back(l);
  shuffled = level_order;
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(17));
  const std::vector<std::pair<std::string, std::vector<int>>> orders = {
      {"level order", level_order}, {"finest first", reversed}, {"shuffled", shuffled}};
  // Everything in memory; spilled from the first byte; spilled part way through a level.
  for (size_t limit : {ContainerWriter::kDefaultLevelMemoryLimit, size_t(0), size_t(100)})
    for (const auto& [name, order] : orders) {
      INFO(name << ", level memory limit " << limit);
      const std::string path = dir.file("replayed.pyr");
      PyramidFileWriter w(path);
      w.set_level_memory_limit(limit);
      replay(recorded, order, w);
      w.finish(result, info, json);
      CHECK(iotest::read_file(path) == expect);
      // Spill files have no name: only the two outputs are left.
      CHECK(directory_listing(dir.file("")) == std::set<std::string>{"produced.pyr", "replayed.pyr"});
    }

  const Container c = Container::open(produced);
  for (uint32_t l = 1; l < c.level_count(); ++l)  // contiguous, coarsest first
    CHECK(c.info().levels[l].blob_offset >=
          c.info().levels[l - 1].blob_offset + c.info().levels[l - 1].blob_size);
  CHECK(c.info().void_count == uint64_t(result.void_count));
  CHECK(c.mask() == map.valid);
}

TEST_CASE("held level bytes come back in order from memory and an unnamed spill file",
          "[runtime][container]") {
  iotest::TempDir dir;
  std::vector<uint8_t> bytes(5000);
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = uint8_t(i * 37 + i / 256);
  for (size_t limit : {size_t(0), size_t(1000), size_t(1) << 20}) {
    INFO("memory limit " << limit);
    detail::HeldBytes held(dir.file(""), limit);
    for (size_t pos = 0; pos < bytes.size(); pos += 777)
      held.append(bytes.data() + pos, std::min<size_t>(777, bytes.size() - pos));
    CHECK(held.size() == bytes.size());
    CHECK(held.spilled() == (limit < bytes.size()));
    CHECK(directory_listing(dir.file("")).empty());  // the spill file has no name
    std::vector<uint8_t> back;
    held.drain([&](const uint8_t* p, size_t n) { back.insert(back.end(), p, p + n); });
    CHECK(back == bytes);
    CHECK(held.size() == 0);
  }
  CHECK_THROWS_AS(detail::HeldBytes(dir.file("missing"), 0).append(bytes.data(), 1), Error);
}

TEST_CASE("pyramid writer: bands out of row order are refused", "[runtime][container]") {
  iotest::TempDir dir;
  PyramidFileWriter w(dir.file("x.pyr"));
  CHECK_THROWS_AS(w.band(0, 0, 1, {1, 2}), std::logic_error);  // before begin()
  PyramidHeader h;
  h.levels = {{2, 2}, {3, 3}};
  w.begin(h);
  CHECK_THROWS_AS(w.band(1, 1, 1, {1}), std::logic_error);  // skips row 0
  CHECK_THROWS_AS(w.band(2, 0, 1, {1}), std::logic_error);  // no such level
  w.band(1, 0, 2, {1});
  CHECK_THROWS_AS(w.band(1, 0, 1, {1}), std::logic_error);  // goes back
}

TEST_CASE("pyramid-build writes its output and nothing else, calibration trials no file at all", "[e2e]") {
  iotest::TempDir source, out;
  const std::string input = source.file("synth.raw");
  write_raw(input, synthesize_terrain(SynthOptions{.seed = 5, .width = 700, .height = 900}));
  for (const std::vector<std::string>& target :
       {std::vector<std::string>{"--max-error", "2"}, std::vector<std::string>{"--rms", "1"}}) {
    INFO(target[0]);
    DirectoryWatch watch(out.file(""));
    // Run in the output directory with TMPDIR there too: any file written by a relative name or in
    // the temp directory would show up in the watch.
    std::string cmd = "cd " + iotest::shell_quote(out.file(""));
    cmd.append(" && TMPDIR=. ").append(iotest::shell_quote(iotest::tool_path("pyramid-build")));
    for (const std::string& a : std::vector<std::string>{input, "-o", "out.pyr", "-q", target[0], target[1]})
      cmd.append(" ").append(iotest::shell_quote(a));
    REQUIRE(std::system(cmd.c_str()) == 0);
    int temps = 0;
    for (const std::string& name : watch.created()) {
      INFO(name);
      if (starts_with(name, "tsan.rodata.")) continue;  // ThreadSanitizer's own file in TMPDIR (TERRAIN_TSAN)
      // The container's own temporary (renamed onto out.pyr), and spill files only where the
      // filesystem lacks O_TMPFILE (unlinked at once).
      CHECK((name == "out.pyr" || starts_with(name, "out.pyr.tmp.") || starts_with(name, ".pyr-spill-")));
      temps += starts_with(name, "out.pyr.tmp.");
    }
    CHECK(temps == 1);
    CHECK(directory_listing(out.file("")) == std::set<std::string>{"out.pyr"});
    std::filesystem::remove(out.file("out.pyr"));
  }
}
