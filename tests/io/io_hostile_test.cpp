// Hostile inputs and outputs of the readers and writers: tiny files describing huge images or grids
// (peak memory of the tool measured), damaged TIFFs, data after a gzip member, two builds of one
// output at once, and full disks for the image writers, the heat-map and the flight statistics.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zlib.h>

#include <array>
#include <catch2/catch.hpp>
#include <cstring>
#include <filesystem>
#include <set>

#include "io_test_util.h"
#include "readers/heightmap.h"

namespace fs = std::filesystem;
using iotest::Invocation;
using iotest::TempDir;
using terrain::ErrorCode;

namespace {

// Peak-RSS bounds are for the plain build; ASan's shadow memory and quarantine add a roughly fixed
// amount (a refused 60000^2 PNG peaks at 217 MiB under ASan, 134 MiB without). The failures these
// bounds catch were gigabytes.
#if defined(TERRAIN_TSAN_BUILD)  // ThreadSanitizer's shadow memory: 5-10x by its documentation
constexpr double kRssFactor = 4;
#elif defined(TERRAIN_SANITIZED)
constexpr double kRssFactor = 2;
#else
constexpr double kRssFactor = 1;
#endif

struct Measured {
  int status = -1;
  long peak_mib = 0;  // the tool's peak resident set (wait4's ru_maxrss)
  std::string err;
};

// Runs `tool args...` (stdout to /dev/null, stderr kept) under `timeout 120`, so that a hang fails
// the test rather than the suite, and reports the peak resident memory of the tool.
Measured run_measured(const TempDir& dir, const std::string& tool, const std::vector<std::string>& args) {
  const std::string err_file = dir.file(tool + ".measured.err");
  std::vector<std::string> argv_s = {"timeout", "120", iotest::tool_path(tool)};
  argv_s.insert(argv_s.end(), args.begin(), args.end());
  const pid_t pid = fork();
  if (pid == 0) {
    if (!freopen("/dev/null", "w", stdout) || !freopen(err_file.c_str(), "w", stderr)) _exit(127);
    std::vector<char*> argv;
    for (auto& a : argv_s) argv.push_back(a.data());
    argv.push_back(nullptr);
    execvp(argv[0], argv.data());
    _exit(127);
  }
  Measured r;
  int raw = 0;
  struct rusage usage {};
  REQUIRE(wait4(pid, &raw, 0, &usage) == pid);  // covers timeout's own waited-for child, the tool
  if (WIFEXITED(raw)) r.status = WEXITSTATUS(raw);
  r.peak_mib = usage.ru_maxrss / 1024;
  const auto e = iotest::read_file(err_file);
  r.err.assign(e.begin(), e.end());
  return r;
}

ErrorCode read_error(const std::string& path) {
  try {
    terrain::read_heightmap(path);
  } catch (const terrain::Error& e) {
    CHECK(std::string(e.what()).find(path) != std::string::npos);
    return e.code();
  }
  FAIL("no Error for " << path);
  return ErrorCode::NotFound;
}

void put_le(std::vector<uint8_t>& b, uint64_t v, int n) {
  for (int i = 0; i < n; ++i) b.push_back(uint8_t(v >> (8 * i)));
}

void put_be32(std::vector<uint8_t>& b, uint32_t v) {
  for (int i = 3; i >= 0; --i) b.push_back(uint8_t(v >> (8 * i)));
}

// A little-endian 16-bit grey TIFF of one strip, with its compression, strip offset and byte count
// as given (0: where the data really is) and RowsPerStrip only when rows_per_strip is not 0.
std::vector<uint8_t> tiff16(uint32_t width, uint32_t height, const std::vector<uint8_t>& data,
                            uint16_t compression = 1, uint32_t strip_offset = 0, uint32_t strip_bytes = 0,
                            uint32_t rows_per_strip = 0) {
  std::vector<uint8_t> b = {'I', 'I', 42, 0};
  put_le(b, 8, 4);
  const uint32_t entries = rows_per_strip ? 9 : 8, data_at = 8 + 2 + 12 * entries + 4;
  put_le(b, entries, 2);
  auto entry = [&](uint16_t tag, uint16_t type, uint32_t value) {
    put_le(b, tag, 2);
    put_le(b, type, 2);
    put_le(b, 1, 4);
    put_le(b, value, 4);  // a SHORT sits in the first two bytes, little endian
  };
  entry(256, 4, width);
  entry(257, 4, height);
  entry(258, 3, 16);
  entry(259, 3, compression);
  entry(262, 3, 1);
  entry(273, 4, strip_offset ? strip_offset : data_at);
  entry(277, 3, 1);
  if (rows_per_strip) entry(278, 4, rows_per_strip);
  entry(279, 4, strip_bytes ? strip_bytes : uint32_t(data.size()));
  put_le(b, 0, 4);
  b.insert(b.end(), data.begin(), data.end());
  return b;
}

void png_chunk(std::vector<uint8_t>& png, const char* type, const std::vector<uint8_t>& data) {
  put_be32(png, uint32_t(data.size()));
  std::vector<uint8_t> body(type, type + 4);
  body.insert(body.end(), data.begin(), data.end());
  png.insert(png.end(), body.begin(), body.end());
  put_be32(png, uint32_t(crc32(0, body.data(), uInt(body.size()))));
}

// A 16-bit grey PNG of value(x, y) = (x + 3y) mod 65536, Adam7-interlaced when asked; with
// `scanlines` false only a few bytes of image data follow the header (a tiny file claiming w x h).
std::vector<uint8_t> png16(uint32_t w, uint32_t h, bool interlaced, bool scanlines = true) {
  std::vector<uint8_t> raw;
  auto pass = [&](uint32_t x0, uint32_t y0, uint32_t dx, uint32_t dy) {
    if (x0 >= w) return;
    for (uint32_t y = y0; y < h; y += dy) {
      raw.push_back(0);  // filter: none
      for (uint32_t x = x0; x < w; x += dx) {
        const uint32_t v = (x + 3 * y) & 0xffff;
        raw.push_back(uint8_t(v >> 8));
        raw.push_back(uint8_t(v));
      }
    }
  };
  if (!scanlines)
    raw.assign(16, 0);
  else if (!interlaced)
    pass(0, 0, 1, 1);
  else
    for (const auto& p : std::vector<std::array<uint32_t, 4>>{{0, 0, 8, 8},
                                                              {4, 0, 8, 8},
                                                              {0, 4, 4, 8},
                                                              {2, 0, 4, 4},
                                                              {0, 2, 2, 4},
                                                              {1, 0, 2, 2},
                                                              {0, 1, 1, 2}})
      pass(p[0], p[1], p[2], p[3]);
  std::vector<uint8_t> z(compressBound(uLong(raw.size())));
  uLongf zn = uLongf(z.size());
  REQUIRE(compress2(z.data(), &zn, raw.data(), uLong(raw.size()), 9) == Z_OK);
  z.resize(zn);
  std::vector<uint8_t> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  std::vector<uint8_t> ihdr;
  put_be32(ihdr, w);
  put_be32(ihdr, h);
  ihdr.insert(ihdr.end(), {16, 0, 0, 0, uint8_t(interlaced ? 1 : 0)});
  png_chunk(png, "IHDR", ihdr);
  png_chunk(png, "IDAT", z);
  png_chunk(png, "IEND", {});
  return png;
}

std::set<std::string> listing(const TempDir& dir) {
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir.file(""))) names.insert(e.path().filename().string());
  return names;
}

// Runs a shell command line in `dir` with writes limited to `kib` KiB (ulimit -f); its exit status.
int run_with_file_limit(const TempDir& dir, int kib, const std::string& command) {
  const std::string cmd = "cd " + iotest::shell_quote(dir.file("")) + " && ulimit -f " + std::to_string(kib) +
                          " && timeout 120 " + command + " >/dev/null 2>&1";
  const int raw = std::system(("bash -c " + iotest::shell_quote(cmd)).c_str());
  return raw != -1 && WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
}

}  // namespace

TEST_CASE("tiny images claiming huge sizes are refused from the header, in bounded memory", "[io][hostile]") {
  TempDir dir;
  // 99 bytes: an interlaced 60000^2 16-bit PNG, which OpenImageIO would decode whole (7 GB).
  const std::vector<uint8_t> huge = png16(60000, 60000, true, false);
  REQUIRE(huge.size() < 128);
  iotest::write_file(dir.file("huge.png"), huge);
  // 2^28 x 1 (2.9 GB before) and 1 x (2^31 - 1) (an abort inside OpenImageIO before: an error
  // message for every missing row, past its 16 MB limit), in a few hundred bytes each.
  iotest::write_file(dir.file("wide.tif"), tiff16(1u << 28, 1, std::vector<uint8_t>(100), 1, 0, 1u << 29));
  iotest::write_file(dir.file("tall.tif"),
                     tiff16(1, 0x7fffffff, std::vector<uint8_t>(100), 1, 0, 0xfffffffe));
  iotest::write_file(dir.file("tall1.tif"),
                     tiff16(1, 0x7fffffff, std::vector<uint8_t>(100), 1, 0, 0xfffffffe, 1));
  for (const char* name : {"huge.png", "wide.tif", "tall.tif", "tall1.tif"}) {
    const Measured r = run_measured(dir, "terrain-info", {dir.file(name)});
    INFO(name << ": " << r.err << " peak " << r.peak_mib << " MiB");
    CHECK((r.status == 5 || r.status == 10));  // dimensions beyond the limits / undecodable image
    CHECK(r.err.find(name) != std::string::npos);
    CHECK(r.peak_mib < 200 * kRssFactor);
  }
  CHECK(run_measured(dir, "terrain-info", {dir.file("wide.tif")}).err.find("2^20") != std::string::npos);
  CHECK(run_measured(dir, "terrain-info", {dir.file("huge.png")}).err.find("interlaced") !=
        std::string::npos);
}

// fuzz_read_image found it: OpenEXR allocates every header attribute's declared size before reading
// it, so 60 bytes declaring a 1.7 GB string took 2 GB. The plugin checks the sizes first.
TEST_CASE("an EXR attribute larger than its file is refused before OpenEXR allocates it", "[io][hostile]") {
  TempDir dir;
  std::vector<uint8_t> exr = {0x76, 0x2f, 0x31, 0x01, 0x02, 0x00, 0x00, 0x00};
  for (const char* text : {"capDate", "string"}) exr.insert(exr.end(), text, text + std::strlen(text) + 1);
  for (uint8_t b : {0x46, 0x72, 0x65, 0x65}) exr.push_back(b);  // 0x65657246 bytes
  for (int i = 0; i < 24; ++i) exr.push_back(uint8_t(i));
  iotest::write_file(dir.file("attr.exr"), exr);
  const Measured r = run_measured(dir, "terrain-info", {dir.file("attr.exr")});
  INFO(r.err << " peak " << r.peak_mib << " MiB");
  CHECK(r.status == 10);
  CHECK(r.err.find("capDate") != std::string::npos);
  CHECK(r.peak_mib < 200 * kRssFactor);
}

TEST_CASE("interlaced and plain PNGs read back exactly within the decode limit", "[io][hostile]") {
  TempDir dir;
  for (const bool interlaced : {false, true}) {
    INFO("interlaced " << interlaced);
    const std::string path = dir.file(interlaced ? "i.png" : "n.png");
    iotest::write_file(path, png16(301, 203, interlaced));
    const terrain::Heightmap map = terrain::read_heightmap(path);
    REQUIRE(map.width() == 301);
    REQUIRE(map.height() == 203);
    bool exact = true;
    for (int64_t y = 0; y < 203; ++y)
      for (int64_t x = 0; x < 301; ++x) exact = exact && map.at(x, y) == double((x + 3 * y) & 0xffff);
    CHECK(exact);
  }
}

TEST_CASE("damaged TIFF strips are errors wherever the decoder reports one", "[io][hostile]") {
  TempDir dir;
  std::vector<uint8_t> pixels;
  for (uint32_t i = 0; i < 100 * 128; ++i) put_le(pixels, (i * 7) & 0xffff, 2);
  iotest::write_file(dir.file("good.tif"), tiff16(100, 128, pixels));
  const terrain::Heightmap map = terrain::read_heightmap(dir.file("good.tif"));
  REQUIRE(map.width() == 100);
  CHECK(map.at(99, 127) == double(((127 * 100 + 99) * 7) & 0xffff));
  iotest::write_file(dir.file("offset.tif"), tiff16(100, 128, pixels, 1, 1000000));  // past the end
  CHECK(read_error(dir.file("offset.tif")) == ErrorCode::CorruptData);
  iotest::write_file(dir.file("c999.tif"), tiff16(100, 128, pixels, 999));  // unknown compression
  CHECK(read_error(dir.file("c999.tif")) == ErrorCode::CorruptData);
  iotest::write_file(dir.file("lzw.tif"), tiff16(100, 128, pixels, 5));  // LZW tag, raw bytes
  CHECK(read_error(dir.file("lzw.tif")) == ErrorCode::CorruptData);
}

TEST_CASE("a gzip member followed by anything is refused", "[io][hostile]") {
  TempDir dir;
  const std::vector<uint8_t> raw(2 * 1201 * 1201, 0);
  const std::string path = dir.file("N10E010.hgt.gz");
  gzFile gz = gzopen(path.c_str(), "wb");
  REQUIRE(gz);
  REQUIRE(gzwrite(gz, raw.data(), unsigned(raw.size())) == int(raw.size()));
  REQUIRE(gzclose(gz) == Z_OK);
  CHECK(terrain::read_heightmap(path).width() == 1201);
  const std::vector<uint8_t> member = iotest::read_file(path);
  // Garbage that ends with the member's own last four bytes (the length the probe reads), and a
  // second copy of the member: gzread skipped the one and read on into the other.
  const std::vector<uint8_t> isize(member.end() - 4, member.end());
  std::vector<uint8_t> garbage = member;
  garbage.insert(garbage.end(), {'j', 'u', 'n', 'k'});
  garbage.insert(garbage.end(), isize.begin(), isize.end());
  iotest::write_file(path, garbage);
  CHECK(read_error(path) == ErrorCode::CorruptData);
  std::vector<uint8_t> two = member;
  two.insert(two.end(), member.begin(), member.end());
  iotest::write_file(path, two);
  CHECK(read_error(path) == ErrorCode::CorruptData);
  const iotest::ToolResult r = iotest::run_tool(dir, Invocation{"terrain-info", {path}});
  CHECK(r.status == 10);
  CHECK(r.err.find("after the end of the gzip stream") != std::string::npos);
}

TEST_CASE("a wide grid builds in bounded memory, and one beyond the row limit is refused at once",
          "[io][hostile]") {
  TempDir dir;
  // Zeros, as sparse files: wide, but nothing on disk.
  const auto zeros = [&](const std::string& name, int64_t w, int64_t h) {
    const std::string path = dir.file(name);
    iotest::write_file(path, std::string());
    fs::resize_file(path, uint64_t(w * h * 2));
    iotest::write_file(path + ".json", "{\"width\": " + std::to_string(w) +
                                           ", \"height\": " + std::to_string(h) + ", \"type\": \"int16\"}");
    return path;
  };
  const std::string wide = zeros("wide.raw", 131072, 64);
  const Measured built =
      run_measured(dir, "pyramid-build", {wide, "-o", dir.file("wide.pyr"), "--lossless", "-q"});
  INFO(built.err << " peak " << built.peak_mib << " MiB");
  CHECK(built.status == 0);
  // 131072 x 64 int16 samples are 16 MiB; about 5.6 KB per column before (730 MB), 3.5 KB now.
  CHECK(built.peak_mib < 600 * kRssFactor);
  const std::string wider = zeros("wider.raw", 4194304, 64);
  const Measured refused =
      run_measured(dir, "pyramid-build", {wider, "-o", dir.file("wider.pyr"), "--lossless", "-q"});
  INFO(refused.err);
  CHECK(refused.status == 5);
  CHECK(refused.err.find("2^20") != std::string::npos);
  CHECK(refused.peak_mib < 100 * kRssFactor);
  CHECK_FALSE(fs::exists(dir.file("wider.pyr")));
}

TEST_CASE("concurrent builds of one output all succeed and leave one whole file", "[io][hostile]") {
  TempDir dir;
  const std::string raw = dir.file("g.raw"), out = dir.file("same.pyr");
  REQUIRE(iotest::run_tool(dir, {"terrain-synth", {"-o", raw, "--width", "400", "--height", "300", "-q"}})
              .status == 0);
  const Invocation build{"pyramid-build", {raw, "-o", out, "--rms", "1", "-q"}};
  for (const auto& r : iotest::run_tools(dir, {build, build, build})) {
    INFO(r.err);
    CHECK(r.status == 0);
  }
  CHECK(iotest::run_tool(dir, Invocation{"terrain-info", {out, "--verify", "-q"}}).status == 0);
  for (const std::string& name : listing(dir))
    CHECK(name.find(".tmp") == std::string::npos);  // no temporary left behind
}

TEST_CASE(
    "full disks: image writers, the heat-map and the flight statistics fail with exit 9 and leave "
    "nothing under the final name",
    "[io][hostile]") {
  TempDir dir;
  const std::string synth = iotest::shell_quote(iotest::tool_path("terrain-synth"));
  for (const char* name : {"s.png", "s.tif", "s.exr", "s.raw"}) {
    INFO(name);
    CHECK(run_with_file_limit(dir, 16, synth + " -o " + name + " --width 512 --height 512 -q") == 9);
  }
  CHECK(listing(dir).empty());
  // Whole files still written where the limit allows them.
  REQUIRE(run_with_file_limit(dir, 4096, synth + " -o g.png --width 256 --height 200 -q") == 0);
  REQUIRE(iotest::run_tool(
              dir, {"pyramid-build", {dir.file("g.png"), "-o", dir.file("g.pyr"), "--rms", "2", "-q"}})
              .status == 0);  // lossy: a heat-map of ~50 KB
  const std::string report = iotest::shell_quote(iotest::tool_path("terrain-report"));
  CHECK(run_with_file_limit(dir, 4, report + " g.png g.pyr --heatmap h.png -q") == 9);
  CHECK_FALSE(fs::exists(dir.file("h.png")));
  // Frames that cannot be written: exit 9, and neither stats.csv nor its temporary is left.
  const std::string view = iotest::shell_quote(iotest::tool_path("clipmap-view"));
  CHECK(run_with_file_limit(dir, 1, view + " g.pyr --frames 2 --width 160 --height 120 --out f -q") == 9);
  for (const std::string& name : listing(dir)) CHECK(name.find(".tmp") == std::string::npos);
  if (fs::exists(dir.file("f"))) {
    CHECK_FALSE(fs::exists(dir.file("f/stats.csv")));
    for (const auto& e : fs::directory_iterator(dir.file("f")))
      CHECK(e.path().filename().string().find("stats") == std::string::npos);
  }
}
