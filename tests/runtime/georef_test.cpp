// Georeference end to end: a GeoTIFF in a projected CRS, an ESRI .bil + .hdr + .prj and an SRTM tile
// go through pyramid-build, terrain-info shows the CRS and geotransform the .pyr stores, and
// pyramid-extract's GeoTIFF is read by GDAL (gdal-bin, tests only) with the input's origin, pixel
// size and CRS. PixelIsPoint inputs are shifted half a pixel; bad georeferences are exit 8.
#include <catch2/catch.hpp>
#include <cstdlib>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "runtime/gdal_test_util.h"

namespace {

using gdaltest::gdal;
using gdaltest::have_gdal;
using iotest::run_tool;
using iotest::shell_quote;

// Text without white space, so that JSON arrays compare on one line.
std::string squeezed(const std::string& s) {
  std::string out;
  for (const char c : s)
    if (c != ' ' && c != '\n' && c != '\t') out += c;
  return out;
}
// JSON numbers are written shortest (500000 is 5e+05).
constexpr const char* kUtmGeotransform = "\"geotransform\":[5e+05,30,0,5200000,0,-30]";

// "Origin = (...)" and "Pixel Size = (...)" lines of gdalinfo.
std::string line_of(const std::string& info, const std::string& head) {
  const size_t at = info.find(head);
  if (at == std::string::npos) return "(no " + head + ")";
  return info.substr(at, info.find('\n', at) - at);
}

// An SRTM tile under a name GDAL's SRTMHGT driver accepts, as a symbolic link in the test's folder.
std::string gdal_hgt(const iotest::TempDir& dir, const std::string& dem) {
  const std::string link = dir.file("N46W122.hgt");
  REQUIRE(std::system(("ln -sf " + shell_quote(dem) + " " + shell_quote(link)).c_str()) == 0);
  return link;
}

// Rainier's SRTM tile placed on UTM zone 10N (30 m samples, corner 500000 / 5200000) by
// gdal_translate with `options`, as `name` in dir; empty when the data or gdal-bin is missing.
std::string rainier_utm(const iotest::TempDir& dir, const std::string& options, const std::string& name) {
  const std::string dem = testdata::require("srtm3_N46W122_rainier_adams_cascades.hgt");
  if (dem.empty() || !have_gdal()) return {};
  const std::string out = dir.file(name);
  gdal(dir, "gdal_translate -q " + options + " -a_srs EPSG:32610 -a_ullr 500000 5200000 536030 5163970 " +
                shell_quote(gdal_hgt(dir, dem)) + " " + shell_quote(out));
  std::remove((out + ".aux.xml").c_str());  // GDAL's own side file would hide what the input says
  return out;
}

// input -> .pyr (lossless; float input on a `quantum` grid) -> GeoTIFF of `type`; gdalinfo of input and
// output agree on origin and pixel size, gdalsrsinfo on the CRS (as PROJ.4 text). Returns terrain-info --json
// of the .pyr.
std::string round_trip(const iotest::TempDir& dir, const std::string& input, const std::string& tag,
                       const std::string& type = "int16", const std::string& quantum = "") {
  const std::string pyr = dir.file(tag + ".pyr"), tif = dir.file(tag + "_out.tif");
  std::vector<std::string> build = {input, "-o", pyr, "--lossless", "-q"};
  if (!quantum.empty()) build.insert(build.end(), {"--quantum", quantum});
  const auto built = run_tool(dir, {"pyramid-build", build});
  INFO(built.err);
  REQUIRE(built.status == 0);
  const auto extracted = run_tool(dir, {"pyramid-extract", {pyr, "-o", tif, "--type", type, "-q"}});
  INFO(extracted.err);
  REQUIRE(extracted.status == 0);
  const std::string in_info = gdal(dir, "gdalinfo " + shell_quote(input));
  const std::string out_info = gdal(dir, "gdalinfo " + shell_quote(tif));
  CHECK(line_of(out_info, "Origin = ") == line_of(in_info, "Origin = "));
  CHECK(line_of(out_info, "Pixel Size = ") == line_of(in_info, "Pixel Size = "));
  CHECK(gdal(dir, "gdalsrsinfo -o proj4 " + shell_quote(tif)) ==
        gdal(dir, "gdalsrsinfo -o proj4 " + shell_quote(input)));
  const auto info = run_tool(dir, {"terrain-info", {pyr, "--json"}});
  REQUIRE(info.status == 0);
  return info.out;
}

}  // namespace

TEST_CASE("georeference: a UTM GeoTIFF keeps EPSG 32610 and its geotransform through the pyramid",
          "[runtime][georef][gdal]") {
  iotest::TempDir dir;
  const std::string tif = rainier_utm(dir, "", "utm.tif");
  if (tif.empty()) return;
  const auto probe = run_tool(dir, {"terrain-info", {tif, "--json"}});
  REQUIRE(probe.status == 0);
  CHECK_THAT(probe.out, Catch::Contains("\"crs_epsg\": 32610"));
  CHECK_THAT(probe.out, Catch::Contains("\"origin_x\": 500015"));
  const std::string info = round_trip(dir, tif, "utm");
  CHECK_THAT(info, Catch::Contains("\"format_version\": \"3.4\""));
  // round_trip builds losslessly: the default D is then point sampling (provenance 3, .pyr 3.4).
  CHECK_THAT(info, Catch::Contains("\"downsample_filter\": \"point\""));
  CHECK_THAT(info, Catch::Contains("\"crs_epsg\": 32610"));
  CHECK_THAT(squeezed(info), Catch::Contains(kUtmGeotransform));
  CHECK_THAT(gdal(dir, "gdalinfo " + shell_quote(dir.file("utm_out.tif"))),
             Catch::Contains("ID[\"EPSG\",32610]"));
  const auto text = run_tool(dir, {"terrain-info", {dir.file("utm.pyr")}});
  CHECK_THAT(text.out, Catch::Contains("crs:          EPSG:32610"));
  CHECK_THAT(text.out, Catch::Contains("geotransform: 500000, 30, 0, 5200000, 0, -30"));
  // The raw output's sidecar keeps origin and CRS too.
  const std::string raw = dir.file("utm_out.raw");
  REQUIRE(run_tool(dir, {"pyramid-extract", {dir.file("utm.pyr"), "-o", raw, "-q"}}).status == 0);
  const auto raw_info = run_tool(dir, {"terrain-info", {raw, "--json"}});
  REQUIRE(raw_info.status == 0);
  CHECK_THAT(raw_info.out, Catch::Contains("\"crs_epsg\": 32610"));
  CHECK_THAT(squeezed(raw_info.out), Catch::Contains(kUtmGeotransform));
}

TEST_CASE("georeference: ESRI .bil + .hdr + .prj and ASCII grid + .prj keep their WKT and origin",
          "[runtime][georef][gdal]") {
  iotest::TempDir dir;
  for (const char* format : {"EHdr", "AAIGrid"}) {
    const std::string tag = std::string(format) == "EHdr" ? "bil" : "asc";
    const std::string input = rainier_utm(dir, std::string("-of ") + format, "utm." + tag);
    if (input.empty()) return;
    INFO(input);
    const std::string info = round_trip(dir, input, tag);
    CHECK_THAT(info, Catch::Contains("\"crs_epsg\": 32610"));  // the ESRI name WGS_1984_UTM_Zone_10N
    CHECK_THAT(info, Catch::Contains("\"crs_text\": \"PROJCS[\\\"WGS_1984_UTM_Zone_10N\\\""));
    CHECK_THAT(squeezed(info), Catch::Contains(kUtmGeotransform));
  }
}

TEST_CASE("georeference: an ASCII grid with xllcenter, float values and an OGC WKT .prj",
          "[runtime][georef][gdal]") {
  if (!have_gdal()) return;
  iotest::TempDir dir;
  // Cell centres given, float values, a void: GDAL places the corner half a cell out.
  const std::string centre = dir.file("centre.asc");
  {
    std::ofstream a(centre);
    a << "ncols 4\nnrows 3\nxllcenter 1000\nyllcenter 2000\ncellsize 10\nNODATA_value -9999\n"
         "1.5 2 3 4\n5 -9999 7 8.25\n9 10 11 12\n";
  }
  {
    // An OGC WKT 1 .prj, whose outermost AUTHORITY names the EPSG code.
    std::ofstream prj(dir.file("centre.prj"));
    const std::string wkt = gdal(dir, "gdalsrsinfo -o wkt1 EPSG:25832");
    prj << wkt.substr(wkt.find_first_not_of(" \n"));  // GDAL's .prj reader wants WKT on line 1
  }
  const auto probe = run_tool(dir, {"terrain-info", {centre, "--json"}});
  REQUIRE(probe.status == 0);
  CHECK_THAT(probe.out, Catch::Contains("\"crs_epsg\": 25832"));
  CHECK_THAT(probe.out,
             Catch::Contains("\"sample_type\": \"float32\"") && Catch::Contains("\"nodata_count\": 1"));
  CHECK_THAT(squeezed(round_trip(dir, centre, "centre", "float32", "0.25")),
             Catch::Contains("\"geotransform\":[995,10,0,2025,0,-10]"));
}

TEST_CASE("georeference: an SRTM tile stays EPSG 4326 with its north-west corner",
          "[runtime][georef][gdal]") {
  const std::string dem = testdata::require("srtm3_N46W122_rainier_adams_cascades.hgt");
  if (dem.empty() || !have_gdal()) return;
  iotest::TempDir dir;
  const std::string info = round_trip(dir, gdal_hgt(dir, dem), "hgt");
  CHECK_THAT(info, Catch::Contains("\"crs_epsg\": 4326"));
  CHECK_THAT(info, Catch::Contains("\"units\": \"degree\""));
  CHECK_THAT(gdal(dir, "gdalinfo " + shell_quote(dir.file("hgt_out.tif"))),
             Catch::Contains("Origin = (-122.000416666666666,47.000416666666666)"));
}

TEST_CASE("georeference: tiled int16 and float32 GeoTIFFs (nodata tag) stream and round-trip exactly",
          "[runtime][georef][gdal]") {
  iotest::TempDir dir;
  // 1201 rows and columns: the last tile row and column are partial.
  for (const char* type : {"Int16", "Float32"}) {
    const std::string tag = std::string("tiled_") + type;
    const std::string tif = rainier_utm(
        dir,
        std::string("-ot ") + type + " -a_nodata -32768 -co TILED=YES -co BLOCKXSIZE=256 -co BLOCKYSIZE=128",
        tag + ".tif");
    if (tif.empty()) return;
    INFO(tif);
    const auto probe = run_tool(dir, {"terrain-info", {tif, "--json"}});
    REQUIRE(probe.status == 0);
    CHECK_THAT(probe.out, Catch::Contains("\"nodata_value\": -32768"));
    const std::string info = round_trip(dir, tif, tag, "int16", std::string(type) == "Float32" ? "1" : "");
    CHECK_THAT(squeezed(info), Catch::Contains(kUtmGeotransform));
    // The same samples as GDAL reads from the input.
    const std::string a = dir.file(tag + "_in.bil"), b = dir.file(tag + "_out.bil");
    gdal(dir, "gdal_translate -q -of ENVI -ot Int16 " + shell_quote(tif) + " " + shell_quote(a));
    gdal(dir, "gdal_translate -q -of ENVI -ot Int16 " + shell_quote(dir.file(tag + "_out.tif")) + " " +
                  shell_quote(b));
    CHECK(iotest::read_file(a) == iotest::read_file(b));
  }
}

TEST_CASE("georeference: a PixelIsPoint GeoTIFF is shifted half a pixel to its corner",
          "[runtime][georef][gdal]") {
  iotest::TempDir dir;
  // GDAL stores the tiepoint of pixel (0, 0)'s centre, 500015 / 5199985, and flags PixelIsPoint:
  // read as a corner it would put the grid 15 m east and north of where it is.
  const std::string tif = rainier_utm(dir, "-mo AREA_OR_POINT=Point", "point.tif");
  if (tif.empty()) return;
  CHECK_THAT(gdal(dir, "gdalinfo " + shell_quote(tif)), Catch::Contains("AREA_OR_POINT=Point"));
  const auto probe = run_tool(dir, {"terrain-info", {tif, "--json"}});
  REQUIRE(probe.status == 0);
  CHECK_THAT(probe.out, Catch::Contains("\"origin_x\": 500015"));
  CHECK_THAT(probe.out, Catch::Contains("\"origin_y\": 5199985"));
  CHECK_THAT(squeezed(probe.out), Catch::Contains(kUtmGeotransform));
  // Our output is PixelIsArea; GDAL places both at the same corner.
  CHECK_THAT(squeezed(round_trip(dir, tif, "point")), Catch::Contains(kUtmGeotransform));
}

TEST_CASE("georeference: bad georeferences are exit 8 naming the file and the field",
          "[runtime][georef][gdal]") {
  if (!have_gdal()) return;
  iotest::TempDir dir;
  // A small synthetic grid as a GeoTIFF with a chosen tiepoint and pixel size (GDAL writes NaN as is).
  const std::string raw = dir.file("g.raw");
  REQUIRE(run_tool(dir, {"terrain-synth", {"-o", raw, "--width", "40", "--height", "30", "-q"}}).status == 0);
  const std::string envi_hdr = dir.file("g.hdr");
  {
    std::ofstream h(envi_hdr);
    h << "ENVI\nsamples = 40\nlines = 30\nbands = 1\nheader offset = 0\nfile type = ENVI Standard\n"
         "data type = 2\ninterleave = bsq\nbyte order = 0\n";
  }
  const std::string base = dir.file("base.tif");
  gdal(dir, "gdal_translate -q -of GTiff " + shell_quote(raw) + " " + shell_quote(base));
  const auto refused = [&](const std::string& tif, const std::string& field) {
    const auto r = run_tool(dir, {"pyramid-build", {tif, "-o", dir.file("bad.pyr"), "--lossless", "-q"}});
    CHECK(r.status == 8);
    CHECK_THAT(r.err, Catch::Contains(tif) && Catch::Contains(field));
  };
  const std::string nan_tie = dir.file("nan.tif"), zero = dir.file("zero.tif");
  gdal(dir, "gdal_translate -q -a_srs EPSG:32610 -a_ullr nan 5200000 501200 5199100 " + shell_quote(base) +
                " " + shell_quote(nan_tie));
  refused(nan_tie, "ModelTiepoint");
  gdal(dir, "gdal_translate -q -a_srs EPSG:32610 -a_ullr 500000 5200000 500000 5199100 " + shell_quote(base) +
                " " + shell_quote(zero));
  refused(zero, "ModelPixelScale");
  const std::string gcps = dir.file("gcps.tif");  // three tiepoints: ground control points
  gdal(dir,
       "gdal_translate -q -a_srs EPSG:32610 -gcp 0 0 500000 5200000 -gcp 40 0 501200 5200000 -gcp 0 30 "
       "500000 5199100 " +
           shell_quote(base) + " " + shell_quote(gcps));
  refused(gcps, "ground control points");
  // An ESRI grid whose .prj is larger than the CRS text limit (8192 bytes).
  const std::string bil = dir.file("w.bil");
  gdal(dir, "gdal_translate -q -of EHdr " + shell_quote(base) + " " + shell_quote(bil));
  {
    std::ofstream prj(dir.file("w.prj"));
    prj << "PROJCS[\"" << std::string(9000, 'x') << "\"]";
  }
  refused(bil, "crs_text");
  // Rotated and south-up geotransforms: GDAL writes them as ModelTransformation (through a VRT
  // that gives the geotransform).
  for (const auto& [gt, field] :
       {std::pair<std::string, std::string>{"500000, 30, 2, 5200000, 2, -30", "rotation"},
        {"500000, 30, 0, 5190000, 0, 30", "flipped"}}) {
    const std::string vrt = dir.file("t.vrt"), tif = dir.file(field + ".tif");
    {
      std::ofstream v(vrt);
      v << "<VRTDataset rasterXSize=\"40\" rasterYSize=\"30\"><GeoTransform>" << gt
        << "</GeoTransform><VRTRasterBand dataType=\"Int16\" band=\"1\"><SimpleSource><SourceFilename>"
        << base
        << "</SourceFilename><SourceBand>1</SourceBand></SimpleSource></VRTRasterBand></VRTDataset>\n";
    }
    gdal(dir, "gdal_translate -q " + shell_quote(vrt) + " " + shell_quote(tif));
    refused(tif, "ModelTransformation");
    refused(tif, field);
  }
}
