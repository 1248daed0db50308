// pyramid-extract read back by a client nobody here wrote: GDAL's gdalinfo and gdal_translate
// (Debian's gdal-bin, tests only; the toolchain itself stays GDAL-free).
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "build/pyramid_build.h"
#include "container/pyramid_file.h"
#include "io/io_test_util.h"
#include "runtime/gdal_test_util.h"
#include "runtime/region_decoder.h"
#include "shared_data.h"

namespace {

using gdaltest::gdal;
using gdaltest::have_gdal;
using iotest::run_tool;
using iotest::shell_quote;

// The samples of a GDAL-readable raster as raw little-endian values (ENVI), via gdal_translate.
template <class T>
std::vector<T> gdal_samples(const iotest::TempDir& dir, const std::string& tif, const char* type) {
  const std::string envi = dir.file("samples.bil");
  gdal(dir, "gdal_translate -q -of ENVI -ot " + std::string(type) + " " + shell_quote(tif) + " " +
                shell_quote(envi));
  const auto bytes = iotest::read_file(envi);
  std::vector<T> v(bytes.size() / sizeof(T));
  std::memcpy(v.data(), bytes.data(), v.size() * sizeof(T));
  return v;
}

}  // namespace

TEST_CASE(
    "pyramid-extract: lossless SRTM -> GeoTIFF int16 is bit-exact with the input, and GDAL sees its "
    "georeference",
    "[runtime][extract][gdal]") {
  const std::string dem = testdata::require("srtm3_N46W122_rainier_adams_cascades.hgt");
  if (dem.empty() || !have_gdal()) return;
  iotest::TempDir dir;
  const std::string pyr = dir.file("r.pyr"), tif = dir.file("r.tif");
  REQUIRE(run_tool(dir, {"pyramid-build", {dem, "-o", pyr, "--lossless", "-q"}}).status == 0);
  REQUIRE(run_tool(dir, {"pyramid-extract", {pyr, "-o", tif, "--type", "int16", "-q"}}).status == 0);
  const std::string info = gdal(dir, "gdalinfo " + shell_quote(tif));
  CHECK_THAT(info, Catch::Contains("Size is 1201, 1201"));
  CHECK_THAT(info, Catch::Contains("Origin = (-122.000416666666666,47.000416666666666)"));
  CHECK_THAT(info, Catch::Contains("Pixel Size = (0.000833333333333,-0.000833333333333)"));
  CHECK_THAT(info, Catch::Contains("ID[\"EPSG\",4326]"));
  CHECK_THAT(info, Catch::Contains("NoData Value=-32768"));
  const std::vector<int16_t> got = gdal_samples<int16_t>(dir, tif, "Int16");
  const auto hgt = iotest::read_file(dem);
  REQUIRE(got.size() == size_t(1201 * 1201));
  size_t differ = 0;
  for (size_t i = 0; i < got.size(); ++i)
    differ += got[i] != int16_t(uint16_t(hgt[2 * i]) << 8 | hgt[2 * i + 1]);
  CHECK(differ == 0);
}

TEST_CASE("pyramid-extract: a float32 window of a coarse level equals the region decoder's metres, voids NaN",
          "[runtime][extract][gdal]") {
  const std::string dem = testdata::require("srtm3_N44E033_crimea_coast_mountains.hgt");  // has voids
  if (dem.empty() || !have_gdal()) return;
  iotest::TempDir dir;
  const std::string pyr = dir.file("c.pyr");
  REQUIRE(run_tool(dir, {"pyramid-build", {dem, "-o", pyr, "--rms", "1", "-q"}}).status == 0);
  const auto file = terrain::container::PyramidFile::open(pyr);
  const terrain::runtime::RegionDecoder decoder(file);
  for (const int level : {file->level_count() - 1, file->level_count() - 3}) {
    const terrain::Rect r{37, 21, 150, 97};
    const std::string tif = dir.file("w" + std::to_string(level) + ".tif");
    REQUIRE(
        run_tool(dir, {"pyramid-extract",
                       {pyr, "-o", tif, "--level", std::to_string(level), "--window", "37,21,150,97", "-q"}})
            .status == 0);
    std::vector<float> want(size_t(r.width * r.height));
    decoder.decode_metres(level, r, want.data(), r.width);
    const std::vector<float> got = gdal_samples<float>(dir, tif, "Float32");
    REQUIRE(got.size() == want.size());
    size_t differ = 0;
    for (size_t i = 0; i < got.size(); ++i)
      differ += !(got[i] == want[i] || (std::isnan(got[i]) && std::isnan(want[i])));
    CHECK(differ == 0);
    // The level's own spacing: 3" doubled per level below the finest.
    const double dx = 3.0 / 3600.0 * std::ldexp(1.0, file->level_count() - 1 - level);
    char origin[96];
    std::snprintf(origin, sizeof origin, "Origin = (%.15f,", 33.0 - 0.5 * dx + 37 * dx);
    CHECK_THAT(gdal(dir, "gdalinfo " + shell_quote(tif)), Catch::Contains(std::string(origin).substr(0, 20)));
  }
}

TEST_CASE("pyramid-extract: bad windows and options are usage errors", "[runtime][extract]") {
  iotest::TempDir dir;
  const std::string raw = dir.file("g.raw"), pyr = dir.file("g.pyr");
  REQUIRE(run_tool(dir, {"terrain-synth", {"-o", raw, "--width", "100", "--height", "80", "-q"}}).status ==
          0);
  REQUIRE(run_tool(dir, {"pyramid-build", {raw, "-o", pyr, "--lossless", "-q"}}).status == 0);
  CHECK(run_tool(dir, {"pyramid-extract", {pyr, "-o", dir.file("a.tif"), "--window", "90,0,20,5"}}).status ==
        1);
  CHECK(run_tool(dir, {"pyramid-extract", {pyr, "-o", dir.file("b.tif"), "--bbox", "0,0,1,1"}}).status == 1);
  CHECK(run_tool(dir, {"pyramid-extract", {pyr, "-o", dir.file("c.tif"), "--level", "9"}}).status == 1);
  CHECK(run_tool(dir, {"pyramid-extract", {pyr, "-o", dir.file("d.jpg")}}).status == 1);
  CHECK(run_tool(dir, {"pyramid-extract", {dir.file("missing.pyr"), "-o", dir.file("e.tif")}}).status == 2);
  // The raw output reads back through the project's own reader as the same integers.
  REQUIRE(
      run_tool(dir, {"pyramid-extract", {pyr, "-o", dir.file("out.raw"), "--type", "int16", "-q"}}).status ==
      0);
  const terrain::Heightmap a = terrain::read_heightmap(raw), b = terrain::read_heightmap(dir.file("out.raw"));
  CHECK(a.values == b.values);
}
