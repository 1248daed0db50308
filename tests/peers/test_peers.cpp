// terrain-bench's HTJ2K (OpenJPH) and JPEG XL (libjxl) peers: exact round trips where they claim
// lossless, declared bounds kept, and the HTJ2K step sweep ordered as its labels promise, on a
// synthetic grid reaching both int16 extremes (signedness and offsets) and on a real SRTM crop; and
// the report's HTJ2K table, from a quick terrain-bench run on a small raw grid.
#include <peers.h>
#include <readers/heightmap.h>

#include <algorithm>
#include <cmath>
#include <regex>

#include "io/io_test_util.h"
#include "shared_data.h"

namespace {

std::unique_ptr<peers::Peer> peer_named(const std::string& name) {
  for (auto& p : peers::all_peers())
    if (p->name() == name) return std::move(p);
  FAIL("peer " << name << " is not registered");
  return nullptr;
}

// Odd sizes (no power-of-two tiles or code-blocks fit), a ramp across the whole int16 range and
// deterministic noise, so a codec that drops the sign or the top bit fails.
peers::Image16 extreme_grid() {
  peers::Image16 img;
  img.width = 131;
  img.height = 67;
  img.samples.resize(size_t(img.sample_count()));
  uint32_t state = 7;
  for (int64_t y = 0; y < img.height; ++y)
    for (int64_t x = 0; x < img.width; ++x) {
      state = state * 1664525u + 1013904223u;
      const double ramp = -32768.0 + 65535.0 * double(x + y * img.width) / double(img.sample_count() - 1);
      const double noise = double(state >> 26) - 32.0;
      img.samples[size_t(y * img.width + x)] =
          int16_t(std::clamp(std::lround(ramp + noise), -32768L, 32767L));
    }
  img.samples.front() = -32768;
  img.samples.back() = 32767;
  return img;
}

// A 300x200 crop of an SRTM tile in its own integer metres (voids 0 and excluded, as terrain-bench
// codes them).
peers::Image16 srtm_crop(const std::string& path) {
  const terrain::Heightmap map = terrain::read_heightmap(path);
  peers::Image16 img;
  img.width = 300;
  img.height = 200;
  const int64_t x0 = map.width() / 2, y0 = map.height() / 3;
  for (int64_t y = 0; y < img.height; ++y)
    for (int64_t x = 0; x < img.width; ++x) {
      const bool valid = map.is_valid(x0 + x, y0 + y);
      img.samples.push_back(valid ? int16_t(std::lround(map.metres(x0 + x, y0 + y))) : int16_t(0));
      img.valid.push_back(valid ? 1 : 0);
    }
  return img;
}

// Every setting of the peer's full sweep: lossless settings exact, declared bounds kept, streams
// non-empty. Returns the results in sweep order.
std::vector<peers::Result> check_sweep(peers::Peer& peer, const peers::Image16& img) {
  std::vector<peers::Result> results;
  bool has_lossless = false;
  for (const peers::Setting& s : peer.sweep(false, img.unit_m)) {
    INFO(peer.name() << " " << s.label);
    peers::Result r = peers::measure(peer, img, s, 0, 1);
    CHECK(r.bytes > 0);
    if (s.max_error_bound == 0) {
      has_lossless = true;
      for (size_t i = 0; i < img.samples.size(); ++i)
        if (r.decoded[i] != img.samples[i]) FAIL("sample " << i << " decoded as " << r.decoded[i]);
    } else if (s.max_error_bound > 0) {
      CHECK(r.error.max_abs <= s.max_error_bound);
    }
    results.push_back(std::move(r));
  }
  CHECK(has_lossless == peer.lossless_capable());
  return results;
}

// HTJ2K's lossy settings come in increasing step order: bits never grow with the step and the rms
// error stays below the step (a quantiser's error is a fraction of its step; OpenJPH spreads the
// base step over the subbands by their synthesis gains).
void check_htj2k_steps(peers::Peer& peer, const peers::Image16& img,
                       const std::vector<peers::Result>& results) {
  const auto settings = peer.sweep(false, img.unit_m);
  double previous_bits = 1e9, previous_step = 0;
  for (size_t i = 0; i < settings.size(); ++i) {
    if (settings[i].max_error_bound >= 0) continue;
    INFO(settings[i].label);
    REQUIRE(settings[i].param > previous_step);
    CHECK(results[i].bits_per_sample <= previous_bits);
    CHECK(results[i].error.rms <= settings[i].param);
    previous_bits = results[i].bits_per_sample;
    previous_step = settings[i].param;
  }
}

}  // namespace

TEST_CASE("htj2k: reversible 5/3 is exact over the whole int16 range, the 9/7 steps ordered") {
  auto peer = peer_named("htj2k");
  const peers::Image16 img = extreme_grid();
  const auto results = check_sweep(*peer, img);
  check_htj2k_steps(*peer, img, results);
}

TEST_CASE("jpegxl: lossless effort 7 is exact over the whole int16 range") {
  auto peer = peer_named("jpegxl");
  const peers::Image16 img = extreme_grid();
  const auto results = check_sweep(*peer, img);
  REQUIRE(results.size() == 1);
  // 16-bit noise around a ramp: lossless must still beat the raw 2 bytes per sample.
  CHECK(results[0].bits_per_sample < 16);
}

TEST_CASE("htj2k and jpegxl: exact and within bounds on a Rainier crop, lossless below 16 bits/sample") {
  const std::string path = testdata::require("srtm3_N46W122_rainier_adams_cascades.hgt");
  if (path.empty()) return;
  const peers::Image16 img = srtm_crop(path);
  for (const char* name : {"htj2k", "jpegxl"}) {
    auto peer = peer_named(name);
    const auto results = check_sweep(*peer, img);
    const auto settings = peer->sweep(false, img.unit_m);
    for (size_t i = 0; i < settings.size(); ++i)
      if (settings[i].max_error_bound == 0) {
        INFO(name);
        // Mountain relief in metres codes in well under half its 16-bit raw size.
        CHECK(results[i].bits_per_sample < 8);
      }
    if (std::string(name) == "htj2k") check_htj2k_steps(*peer, img, results);
  }
}

TEST_CASE("terrain-bench --markdown: the HTJ2K table has a ratio to HTJ2K and to the best peer per target") {
  iotest::TempDir dir;
  // Rolling hills of 0-1400 m with metre noise, as int16 raw with a sidecar.
  const int width = 200, height = 150;
  std::vector<uint8_t> bytes;
  uint32_t state = 3;
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      state = state * 1664525u + 1013904223u;
      const auto h = int16_t(
          std::lround(700 + 600 * std::sin(x / 17.0) * std::cos(y / 23.0) + 2.0 * x + double(state >> 30)));
      bytes.push_back(uint8_t(uint16_t(h) & 0xff));
      bytes.push_back(uint8_t(uint16_t(h) >> 8));
    }
  iotest::write_file(dir.file("hills.raw"), bytes);
  iotest::write_file(dir.file("hills.json"),
                     std::string("{\"width\": 200, \"height\": 150, \"type\": \"int16\"}"));
  const iotest::ToolResult r =
      iotest::run_tool(dir, {"peers/terrain-bench",
                             {"--quick", "--threads", "1", "--peers", "htj2k,jpegxl,charls", "--work-dir",
                              dir.file(""), "--markdown", dir.file("bench.md"), dir.file("hills.raw")}});
  INFO(r.err);
  REQUIRE(r.status == 0);
  const auto md_bytes = iotest::read_file(dir.file("bench.md"));
  const std::string md(md_bytes.begin(), md_bytes.end());
  const size_t section = md.find("## Pyramid against HTJ2K and the best peer");
  REQUIRE(section != std::string::npos);
  const size_t row = md.find("\n| hills |", section);
  REQUIRE(row != std::string::npos);
  const std::string line = md.substr(row + 1, md.find('\n', row + 1) - row - 1);
  INFO(line);
  // DEM, five targets, three speed columns.
  std::vector<std::string> cells;
  for (size_t at = 2; at < line.size();) {
    const size_t end = line.find(" |", at);
    cells.push_back(line.substr(at, end - at));
    at = end + 3;
  }
  REQUIRE(cells.size() == 9);
  // Lossless: both the pyramid and HTJ2K's 5/3 are exact, so both ratios exist.
  CHECK(
      std::regex_match(cells[1], std::regex(R"([0-9]+\.[0-9]{2} / [0-9]+\.[0-9]{2} (htj2k|jpegxl|charls))")));
  // JPEG XL's lossless rate is its one figure; HTJ2K's decode speed comes as 9/7 / 5/3.
  CHECK(std::regex_match(cells[7], std::regex(R"([0-9.]+ / [0-9.]+)")));
  CHECK(std::regex_match(cells[8], std::regex(R"([0-9.]+)")));
}
