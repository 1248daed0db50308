// The streaming band reader yields exactly the samples of a whole-file read, whatever the band height,
// for .hgt, .hgt.gz (made here with zlib), PNG and raw input.
#include <zlib.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cstring>
#include <filesystem>

#include "io_test_util.h"
#include "readers/heightmap.h"
#include "shared_data.h"

namespace {

// Band heights 1, 7, 64 and the whole height by default (plus `bands` when given instead).
void check_bands_match(const std::string& path, const terrain::ReadOptions& options = {},
                       std::vector<int64_t> bands = {1, 7, 64}) {
  terrain::Heightmap whole = terrain::read_heightmap(path, options);
  const int64_t w = whole.width(), h = whole.height();
  bands.push_back(h);
  for (int64_t band : bands) {
    INFO(path << " band height " << band);
    auto reader = terrain::open_band_reader(path, options);
    REQUIRE(reader->info().width == w);
    REQUIRE(reader->info().height == h);
    std::vector<double> values(size_t(band * w));
    std::vector<uint8_t> valid(values.size());
    int64_t row = 0;
    bool same = true;
    while (int64_t n = reader->read_rows(band, values.data(), valid.data())) {
      REQUIRE(n <= band);
      REQUIRE(row + n <= h);
      for (int64_t i = 0; i < n * w && same; ++i) {
        int64_t x = i % w, y = row + i / w;
        same = values[size_t(i)] == whole.at(x, y) && (valid[size_t(i)] != 0) == whole.is_valid(x, y);
      }
      row += n;
      REQUIRE(reader->rows_read() == row);
    }
    CHECK(same);
    CHECK(row == h);
    CHECK(reader->read_rows(band, values.data(), valid.data()) == 0);  // stays at the end
    // Integer storage: read_rows_int32 gives the same samples without doubles (0 where void).
    auto ints_reader = terrain::open_band_reader(path, options);
    if (!ints_reader->reads_int32()) {
      CHECK_THROWS_AS(ints_reader->read_rows_int32(band, nullptr, nullptr), std::logic_error);
      continue;
    }
    std::vector<int32_t> ints(values.size());
    row = 0;
    while (int64_t n = ints_reader->read_rows_int32(band, ints.data(), valid.data())) {
      REQUIRE(row + n <= h);
      for (int64_t i = 0; i < n * w && same; ++i) {
        int64_t x = i % w, y = row + i / w;
        same = (valid[size_t(i)] != 0) == whole.is_valid(x, y) &&
               double(ints[size_t(i)]) == (whole.is_valid(x, y) ? whole.at(x, y) : 0.0);
      }
      row += n;
    }
    CHECK(same);
    CHECK(row == h);
  }
  // skip_rows (a seek on raw and .hgt, reading and discarding on the others) lands where reading
  // would have: skip 0, a few rows, most of the grid, then read; skipping past the end stops there.
  for (int64_t skip : {int64_t(0), int64_t(3), h - 2}) {
    INFO(path << " skip " << skip);
    auto reader = terrain::open_band_reader(path, options);
    std::vector<double> values(static_cast<size_t>(w));
    std::vector<uint8_t> valid(values.size());
    REQUIRE(reader->read_rows(1, values.data(), valid.data()) == 1);
    const int64_t skipped = reader->skip_rows(skip);
    CHECK(skipped == std::min(skip, h - 1));
    CHECK(reader->rows_read() == 1 + skipped);
    if (1 + skipped < h) {
      REQUIRE(reader->read_rows(1, values.data(), valid.data()) == 1);
      bool same = true;
      for (int64_t x = 0; x < w; ++x)
        same = same && values[size_t(x)] == whole.at(x, 1 + skipped) &&
               (valid[size_t(x)] != 0) == whole.is_valid(x, 1 + skipped);
      CHECK(same);
    }
    CHECK(reader->skip_rows(h) == h - reader->rows_read());
    CHECK(reader->skip_rows(1) == 0);
  }
}

void gzip_file(const std::string& from, const std::string& to) {
  auto bytes = iotest::read_file(from);
  gzFile gz = gzopen(to.c_str(), "wb1");
  REQUIRE(gz != nullptr);
  REQUIRE(gzwrite(gz, bytes.data(), unsigned(bytes.size())) == int(bytes.size()));
  REQUIRE(gzclose(gz) == Z_OK);
}

// A width x height grid of `type` whose sample i (row-major) is f(i).
template <class F> terrain::Heightmap grid_of(int64_t width, int64_t height, terrain::SampleType type, F f) {
  terrain::Heightmap m;
  m.info.width = width;
  m.info.height = height;
  m.info.sample_type = type;
  for (int64_t i = 0; i < width * height; ++i) m.values.push_back(f(i));
  return m;
}

}  // namespace

TEST_CASE("band reader matches whole reads on hgt and hgt.gz", "[io][band]") {
  // N52E013 has 160 voids, so the valid mask is exercised too.
  auto hgt = testdata::require("srtm3_N52E013_berlin_flat_plain.hgt");
  if (hgt.empty()) return;
  check_bands_match(hgt);
  iotest::TempDir dir;
  std::string gz = dir.file("N52E013.hgt.gz");
  gzip_file(hgt, gz);
  terrain::Heightmap plain = terrain::read_heightmap(hgt), zipped = terrain::read_heightmap(gz);
  CHECK(plain.values == zipped.values);
  CHECK(plain.valid == zipped.valid);
  CHECK(terrain::compute_stats(zipped).nodata_count == 160);
  CHECK(*zipped.info.origin_x == 13.0);
  CHECK(*zipped.info.origin_y == 53.0);
  check_bands_match(gz);
}

TEST_CASE("band reader matches whole reads on PNG", "[io][band]") {
  // A PNG written here takes every band height (a 1-row band costs one OIIO call per row, which is
  // slow under sanitizers on a 1025-row image); the shared Puget Sound PNG takes the larger bands.
  iotest::TempDir dir;
  const terrain::Heightmap m = grid_of(211, 97, terrain::SampleType::UInt16,
                                       [](int64_t i) { return double((i * 2654435761u) % 65536); });
  std::string png = dir.file("band.png");
  terrain::write_image16(png, m);
  check_bands_match(png);
  CHECK(terrain::read_heightmap(png).values == m.values);

  auto puget = testdata::require("pugetsound_ps_height_1k.png");
  if (puget.empty()) return;
  terrain::ReadOptions o;
  o.vertical_scale = 0.1;
  check_bands_match(puget, o, {64, 300});
}

TEST_CASE("band reader matches whole reads on raw", "[io][band]") {
  iotest::TempDir dir;
  terrain::Heightmap m = grid_of(301, 150, terrain::SampleType::Float32,
                                 [](int64_t i) { return double(float(double(i % 977) * 0.5 - 17.25)); });
  m.info.nodata = -1.0;
  m.valid.assign(m.values.size(), 1);
  m.valid[1234] = 0;
  m.values[1234] = 0;
  std::string path = dir.file("band.raw");
  terrain::write_raw(path, m, true);
  check_bands_match(path);

  // Integer types in both byte orders, with a nodata value: read_rows_int32 equals read_rows.
  for (auto type : {terrain::SampleType::Int16, terrain::SampleType::UInt16, terrain::SampleType::Int32})
    for (bool big : {false, true}) {
      INFO("type " << int(type) << " big-endian " << big);
      terrain::Heightmap g = grid_of(67, 41, type, [type](int64_t i) {
        const int64_t v = (i * 2654435761u) % 60000;
        return double(type == terrain::SampleType::UInt16  ? v
                      : type == terrain::SampleType::Int16 ? v - 30000
                                                           : v * 9973 - 2e8);
      });
      g.info.nodata = g.values[100];
      std::string ints = dir.file("ints.raw");
      terrain::write_raw(ints, g, big);
      check_bands_match(ints);
    }

  // The nodata test compares stored integers: a value that no sample of the type can hold (a
  // fraction, or outside the type's range) voids nothing; an integral one voids exactly its samples.
  for (const double nodata : {100.5, 70000.0, -1.0, 1234.0})
    for (bool big : {false, true}) {
      INFO("nodata " << nodata << " big-endian " << big);
      terrain::Heightmap g = grid_of(53, 29, terrain::SampleType::UInt16,
                                     [](int64_t i) { return double(i % 97 == 0 ? 1234 : i % 3000); });
      g.info.nodata = nodata;
      std::string nd_path = dir.file("nodata.raw");
      terrain::write_raw(nd_path, g, big);
      auto nd_reader = terrain::open_band_reader(nd_path);
      std::vector<int32_t> ints(size_t(53 * 29));
      std::vector<uint8_t> valid(ints.size());
      REQUIRE(nd_reader->read_rows_int32(29, ints.data(), valid.data()) == 29);
      int64_t voids = 0, expected = 0;
      for (size_t i = 0; i < ints.size(); ++i) {
        voids += valid[i] == 0;
        expected += double(g.values[i]) == nodata;
        if (valid[i]) CHECK(ints[i] == int32_t(g.values[i]));
      }
      CHECK(voids == expected);
      CHECK(expected == (nodata == 1234.0 ? 17 : 0));  // 16 multiples of 97, and i = 1234
      check_bands_match(nd_path);
    }

  // A file cut short after it was opened (the probe checks its size): seeking past its end is
  // refused as reading would be, naming the file.
  std::string cut = dir.file("cut.raw");
  terrain::write_raw(cut, m);
  auto reader = terrain::open_band_reader(cut);
  std::filesystem::resize_file(cut, std::filesystem::file_size(cut) - 301 * 4 * 10);
  CHECK(reader->skip_rows(139) == 139);
  CHECK_THROWS_WITH(reader->skip_rows(2),
                    Catch::Contains("cut.raw") && Catch::Contains("data ends in row 140"));
}

TEST_CASE("stream_stats equals compute_stats", "[io][band]") {
  auto hgt = testdata::require("srtm3_N44E033_crimea_coast_mountains.hgt");
  if (hgt.empty()) return;
  auto reader = terrain::open_band_reader(hgt);
  terrain::GridStats streamed = terrain::stream_stats(*reader, 13);
  terrain::GridStats whole = terrain::compute_stats(terrain::read_heightmap(hgt));
  CHECK(streamed.min_m == whole.min_m);
  CHECK(streamed.max_m == whole.max_m);
  CHECK(streamed.mean_m == Approx(whole.mean_m).epsilon(1e-12));
  CHECK(streamed.nodata_count == 852);  // MANIFEST.md
  CHECK(streamed.valid_count == whole.valid_count);
}
