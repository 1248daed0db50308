// Flat and mostly-empty terrain: all-zero residual bands cost a band-table record and no stream,
// empty codec tiles no payload; region decodes across empty and coded bands equal full decodes, and
// damaged band tables are rejected.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <random>

#include "build/pyramid_build.h"
#include "codec/codec.h"
#include "container/pyramid_file.h"
#include "core/bytes.h"
#include "io/io_test_util.h"
#include "readers/terrain_generator.h"
#include "runtime/region_decoder.h"

using namespace terrain;
using namespace terrain::container;
using namespace terrain::runtime;
using namespace terrain::build;

namespace {

std::string build_file(const std::string& src, const std::string& pyr, ErrorMode mode, double metres,
                       DownsampleChoice downsample = DownsampleChoice::Wavelet) {
  BuildFileOptions o;
  o.mode = mode;
  o.target_metres = metres;
  o.downsample = downsample;
  o.threads = 2;
  build_pyramid_file(src, {}, pyr, o);
  return pyr;
}

// Synthetic terrain with everything outside a disc (about 7 % of the area) set to sea level 0.
Heightmap island(int64_t w, int64_t h) {
  Heightmap map = synthesize_terrain(SynthOptions{.seed = 12, .width = w, .height = h});
  for (int64_t y = 0; y < h; ++y)
    for (int64_t x = 0; x < w; ++x) {
      const double dx = double(x - w / 3), dy = double(y - h / 4);
      if (dx * dx + dy * dy > 0.022 * double(w * h)) map.values[size_t(y * w + x)] = 0;
    }
  return map;
}

// A side x side raw grid (with sidecar) of `value` everywhere; returns its path.
std::string write_constant_grid(const iotest::TempDir& dir, const std::string& name, int64_t side,
                                double value) {
  Heightmap map = synthesize_terrain(SynthOptions{.seed = 1, .width = 16, .height = 16});  // the grid info
  map.info.width = map.info.height = side;
  map.values.assign(size_t(side * side), value);
  const std::string path = dir.file(name);
  write_raw(path, map);
  return path;
}

}  // namespace

TEST_CASE("a constant grid: every residual level is a few bytes of band table", "[e2e]") {
  iotest::TempDir dir;
  const std::string src = write_constant_grid(dir, "flat.raw", 1024, 57.0);
  const std::pair<ErrorMode, double> targets[] = {
      {ErrorMode::Lossless, 0}, {ErrorMode::Step, 5}, {ErrorMode::MaxError, 2}, {ErrorMode::Rms, 1}};
  for (const auto& [mode, metres] : targets) {
    INFO("mode " << int(mode) << " target " << metres);
    auto file = PyramidFile::open(build_file(src, dir.file("flat.pyr"), mode, metres));
    for (int l = 1; l < file->level_count(); ++l) {
      CHECK(file->container().level(uint32_t(l)).size <= 20);  // footer + one run record
      for (const BandView& b : file->bands(l)) CHECK(b.empty());
    }
    RegionDecoder dec(file);
    const int top = file->level_count() - 1;
    std::vector<int32_t> out(1024 * 1024);
    dec.decode_units(top, Rect{0, 0, 1024, 1024}, out.data(), 1024);
    const auto [lo, hi] = std::minmax_element(out.begin(), out.end());
    CHECK(*lo == *hi);  // still constant
    if (mode != ErrorMode::Rms) CHECK(std::abs(*lo - 57) <= int32_t(metres));
  }
}

// Issue 17's floor: an all-constant 4096^2 grid costs under 0.001 bits per sample at any target (the
// coarse bands are at least 16 rows, and neither the wavelet D, point sampling nor the default D that
// the optimal fit falls back to is stored).
TEST_CASE("a constant 4096^2 grid costs under 0.001 bits per sample at every target", "[e2e]") {
  iotest::TempDir dir;
  const std::string src = write_constant_grid(dir, "flat4k.raw", 4096, 123.0);
  const std::pair<ErrorMode, double> targets[] = {
      {ErrorMode::Lossless, 0}, {ErrorMode::Rms, 1}, {ErrorMode::Rms, 8}, {ErrorMode::MaxError, 0.5}};
  for (const auto& [mode, metres] : targets) {
    INFO("mode " << int(mode) << " target " << metres);
    for (const DownsampleChoice d :
         {DownsampleChoice::Wavelet, DownsampleChoice::Optimal, DownsampleChoice::Point}) {
      const std::string pyr = build_file(src, dir.file("flat4k.pyr"), mode, metres, d);
      auto file = PyramidFile::open(pyr);
      const double bits = 8.0 * double(std::filesystem::file_size(pyr)) / (4096.0 * 4096.0);
      CHECK(bits < 0.001);
      const FilterProvenance want = d == DownsampleChoice::Wavelet ? FilterProvenance::Wavelet
                                    : d == DownsampleChoice::Point ? FilterProvenance::Point
                                                                   : FilterProvenance::Fallback;
      const DownsampleFilter filter = d == DownsampleChoice::Wavelet ? DownsampleFilter::wavelet()
                                      : d == DownsampleChoice::Point ? DownsampleFilter::impulse()
                                                                     : DownsampleFilter::default_filter();
      CHECK(file->info().filter_provenance == want);
      CHECK(file->info().filter_size == 0);
      CHECK(file->downsample_filter().taps == filter.taps);
      for (const BandView& b : file->bands(0)) CHECK(b.rows >= 16);
    }
  }
}

TEST_CASE("mostly sea: empty bands hold no stream and region decode equals full decode", "[e2e]") {
  iotest::TempDir dir;
  const std::string src = dir.file("island.raw");
  const Heightmap map = island(700, 900);
  write_raw(src, map);
  for (ErrorMode mode : {ErrorMode::Step, ErrorMode::Lossless}) {
    INFO("mode " << int(mode));
    auto file = PyramidFile::open(build_file(src, dir.file("island.pyr"), mode, 3));
    size_t empty = 0, coded = 0;
    for (int l = 0; l < file->level_count(); ++l)
      for (const BandView& b : file->bands(l)) (b.empty() ? empty : coded) += 1;
    CHECK(empty > 0);
    CHECK(coded > 0);
    RegionDecoder full_dec(file, 0), roi_dec(file, size_t(1) << 20);
    std::mt19937 rng(3);
    for (int l = 0; l < file->level_count(); ++l) {
      const GridSize s = file->level_size(l);
      std::vector<int32_t> full(size_t(s.width * s.height));
      full_dec.decode_units(l, Rect{0, 0, s.width, s.height}, full.data(), s.width);
      for (int k = 0; k < 20; ++k) {
        const int64_t x0 = int64_t(rng() % uint64_t(s.width)), y0 = int64_t(rng() % uint64_t(s.height));
        const int64_t w = 1 + int64_t(rng() % uint64_t(s.width - x0)),
                      h = 1 + int64_t(rng() % uint64_t(s.height - y0));
        std::vector<int32_t> win(size_t(w * h));
        roi_dec.decode_units(l, Rect{x0, y0, w, h}, win.data(), w);
        bool same = true;
        for (int64_t y = 0; y < h; ++y)
          for (int64_t x = 0; x < w; ++x)
            same = same && win[size_t(y * w + x)] == full[size_t((y0 + y) * s.width + x0 + x)];
        INFO("level " << l << " rect " << x0 << "," << y0 << " " << w << "x" << h);
        CHECK(same);
      }
      if (l == file->level_count() - 1 && mode == ErrorMode::Lossless) {
        bool exact = true;
        for (size_t i = 0; i < full.size(); ++i) exact = exact && full[i] == int32_t(map.values[i]);
        CHECK(exact);
      }
    }
  }
}

TEST_CASE("band tables: every damaged byte and every forged structure is rejected", "[runtime][container]") {
  iotest::TempDir dir;
  const std::string src = dir.file("island.raw");
  write_raw(src, island(300, 400));
  auto file = PyramidFile::open(build_file(src, dir.file("t.pyr"), ErrorMode::Step, 3));
  const int top = file->level_count() - 1;
  const LevelView v = file->container().level(uint32_t(top));
  const std::vector<uint8_t> blob(v.data, v.data + v.size);
  const int64_t height = int64_t(v.height);
  REQUIRE(parse_band_table(blob.data(), blob.size(), height, "t").size() == file->bands(top).size());
  const uint32_t table_bytes = bytes::get_u32(blob.data() + blob.size() - 12);
  const size_t table = blob.size() - 12 - table_bytes;
  for (size_t at = table; at < blob.size(); ++at)
    for (int bit = 0; bit < 8; ++bit) {
      std::vector<uint8_t> bad = blob;
      bad[at] ^= uint8_t(1u << bit);
      INFO("byte " << at << " bit " << bit);
      CHECK_THROWS_AS(parse_band_table(bad.data(), bad.size(), height, "t"), Error);
    }
  // Forged tables with a valid checksum: wrong heights, a stream past the blob, a zero-size stream,
  // a truncated record.
  const auto forged = [&](const std::vector<uint64_t>& varints, size_t streams) {
    std::vector<uint8_t> b(blob.begin(), blob.begin() + long(streams));
    const size_t start = b.size();
    for (uint64_t x : varints) bytes::put_varint(b, x);
    const uint32_t n = uint32_t(b.size() - start), crc = crc32c(b.data() + start, n);
    b.resize(b.size() + 12);
    bytes::put_u32(b.data() + b.size() - 12, n);
    std::memcpy(b.data() + b.size() - 8, "BND2", 4);
    bytes::put_u32(b.data() + b.size() - 4, crc);
    return b;
  };
  const uint64_t h = uint64_t(height);
  const std::vector<uint8_t> all_zero = forged({h, 1}, 0);  // one all-zero band: valid
  CHECK(parse_band_table(all_zero.data(), all_zero.size(), height, "t").size() == 1);
  for (const auto& [varints, streams] : std::vector<std::pair<std::vector<uint64_t>, size_t>>{
           {{h - 1, 1}, 0},               // one row short
           {{h + 1, 1}, 0},               // one row too many
           {{1, ((h - 1) << 1) | 1}, 0},  // valid: a run of h all-zero bands of 1 row
           {{1, (h << 1) | 1}, 0},        // a run past the level
           {{h, 2 << 1}, 1},              // a stream past the blob's streams
           {{h, 0}, 0},                   // a stream of size 0
           {{h}, 0},                      // a record without its code
           {{h, 1, 1, 1}, 0},             // a record past the level
       }) {
    const std::vector<uint8_t> b = forged(varints, streams);
    const bool valid = varints.size() == 2 && varints[0] == 1 && varints[1] == (((h - 1) << 1) | 1);
    INFO("forged table of " << varints.size() << " varints");
    if (valid)
      CHECK(parse_band_table(b.data(), b.size(), height, "t").size() == 1);
    else
      CHECK_THROWS_AS(parse_band_table(b.data(), b.size(), height, "t"), Error);
  }
}

TEST_CASE("rms targets with the default D: the calibration's choice, never larger than the wavelet D's file",
          "[e2e]") {
  // Two synthetic terrains nobody tuned on: the generator's ranges doubled with a texture of +-6 m
  // (rough) and flattened to a tenth (smooth): the default calibrates the wavelet D and point sampling and
  // keeps the smaller file whose rms is near the target, so it is never larger than the wavelet D's (the
  // metadata's option string aside), within 10 % of the target, and the file records the D it used.
  iotest::TempDir dir;
  Heightmap rough = synthesize_terrain(SynthOptions{.seed = 21, .width = 384, .height = 320});
  Heightmap smooth = rough;
  for (double& v : smooth.values) v = std::round(v / 10);
  std::mt19937 rng(4);  // rough: steeper relief and a few metres of sample-to-sample texture
  for (double& v : rough.values) v = std::round(2 * v + double(rng() % 13) - 6);
  const std::string sources[] = {dir.file("rough.raw"), dir.file("smooth.raw")};
  write_raw(sources[0], rough);
  write_raw(sources[1], smooth);
  for (const std::string& src : sources)
    for (double metres : {1.0, 2.0}) {
      INFO(src << " rms " << metres);
      const std::string wavelet = build_file(src, dir.file("w.pyr"), ErrorMode::Rms, metres);
      const auto wavelet_bytes = std::filesystem::file_size(wavelet);
      const std::string chosen =
          build_file(src, dir.file("a.pyr"), ErrorMode::Rms, metres, DownsampleChoice::Auto);
      CHECK(std::filesystem::file_size(chosen) <= wavelet_bytes + 16);
      auto file = PyramidFile::open(chosen);
      const FilterProvenance p = file->info().filter_provenance;
      CHECK((p == FilterProvenance::Wavelet || p == FilterProvenance::Point));
      CHECK(file->downsample_filter().is_point() == (p == FilterProvenance::Point));
      const auto e = level_error_metres(file->info(), file->info().levels.size() - 1);
      REQUIRE(e.has_value());
      CHECK(std::abs(e->rms / metres - 1) <= 0.10);
      std::printf("rms-D %s rms %.0f m: %s, %ju bytes (wavelet D %ju), rms %.3f m\n",
                  std::filesystem::path(src).filename().c_str(), metres,
                  p == FilterProvenance::Point ? "point" : "wavelet",
                  uintmax_t(std::filesystem::file_size(chosen)), uintmax_t(wavelet_bytes), e->rms);
    }
}
