// terrain-bench's HTJ2K (OpenJPH) and JPEG XL (libjxl) peers: exact round trips where they claim
// lossless, declared bounds kept, and the HTJ2K step sweep ordered as its labels promise, on a
// synthetic grid reaching both int16 extremes (signedness and offsets) and on a real SRTM crop.
#include <peers.h>
#include <readers/heightmap.h>

#include <algorithm>
#include <cmath>

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
