// Every DEM in ../shared/data is read and checked against the figures in its MANIFEST.md table
// (dimensions, min/max in metres over valid samples, void count where the manifest states one).
#include <catch2/catch.hpp>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>

#include "readers/heightmap.h"
#include "shared_data.h"

namespace {

struct ManifestRow {
  int64_t width = 0, height = 0;
  double min_m = 0, max_m = 0;
  std::optional<int64_t> voids;  // absent when the manifest gives no count
};

std::string trim(const std::string& s) {
  auto b = s.find_first_not_of(" \t");
  auto e = s.find_last_not_of(" \t");
  return b == std::string::npos ? "" : s.substr(b, e - b + 1);
}

// Reads "<number> <sep> <number>" at the first place in `text` where it occurs (sep is 'x' or '/'),
// e.g. "1201x1201" or "192 / 8840 (2572, 1608)". std::regex is avoided: GCC 12 warns inside it.
bool find_pair(const std::string& text, char sep, double& a, double& b) {
  for (size_t i = 0; i < text.size(); ++i) {
    if (!(std::isdigit(static_cast<unsigned char>(text[i])) ||
          (text[i] == '-' && i + 1 < text.size() && std::isdigit(static_cast<unsigned char>(text[i + 1])))))
      continue;
    if (i > 0 && (std::isdigit(static_cast<unsigned char>(text[i - 1])) || text[i - 1] == '.')) continue;
    const char* start = text.c_str() + i;
    char* end = nullptr;
    a = std::strtod(start, &end);
    const char* p = end;
    while (*p == ' ') ++p;
    if (*p != sep) continue;
    ++p;
    while (*p == ' ') ++p;
    char* end2 = nullptr;
    b = std::strtod(p, &end2);
    if (end2 != p) return true;
  }
  return false;
}

// Parses the "## Files" markdown table of MANIFEST.md, keyed by file name.
std::map<std::string, ManifestRow> parse_manifest(const std::string& path) {
  std::ifstream in(path);
  REQUIRE(in.good());
  std::map<std::string, ManifestRow> rows;
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("| ", 0) != 0) continue;
    std::vector<std::string> cols;
    std::stringstream ss(line.substr(1));
    std::string col;
    while (std::getline(ss, col, '|')) cols.push_back(trim(col));
    if (cols.size() < 10) continue;
    const std::string& name = cols[0];
    if (name.size() < 5 || (name.substr(name.size() - 4) != ".hgt" && name.substr(name.size() - 4) != ".png"))
      continue;
    ManifestRow r;
    double w = 0, h = 0;
    REQUIRE(find_pair(cols[5], 'x', w, h));
    r.width = int64_t(w);
    r.height = int64_t(h);
    // "raw 0 / 43798 -> 0 / 4379.8 m": the figures after the arrow are the metres.
    std::string mm = cols[8];
    if (auto arrow = mm.find("->"); arrow != std::string::npos) mm = mm.substr(arrow + 2);
    REQUIRE(find_pair(mm, '/', r.min_m, r.max_m));
    if (cols[9] == "0")
      r.voids = 0;
    else if (cols[9].find(" sample") != std::string::npos &&
             std::isdigit(static_cast<unsigned char>(cols[9][0])))
      r.voids = std::stoll(cols[9]);  // "160 samples (1.11e-4)"
    rows[name] = r;
  }
  return rows;
}

terrain::ReadOptions options_for(const std::string& name) {
  terrain::ReadOptions o;
  if (name.find("pugetsound") != std::string::npos) o.vertical_scale = 0.1;  // manifest: value x 0.1 = metres
  return o;
}

}  // namespace

TEST_CASE("every shared DEM matches MANIFEST.md dims, min, max and voids", "[io][manifest]") {
  auto files = testdata::all_dems();
  if (files.empty()) return;
  auto manifest_path = testdata::require("MANIFEST.md");
  if (manifest_path.empty()) return;
  auto manifest = parse_manifest(manifest_path);
  REQUIRE(manifest.size() >= 13);
  for (const auto& file : files) {
    std::string name = std::filesystem::path(file).filename().string();
    INFO(name);
    REQUIRE(manifest.count(name) == 1);
    const ManifestRow& row = manifest[name];
    terrain::Heightmap map = terrain::read_heightmap(file, options_for(name));
    CHECK(map.width() == row.width);
    CHECK(map.height() == row.height);
    terrain::GridStats s = terrain::compute_stats(map);
    // Terrain-RGB codes are 0.1 m steps; everything else is exact whole (or tenth) metres.
    double tol = map.info.sample_type == terrain::SampleType::TerrainRGB ? 0.05 : 1e-6;
    CHECK(std::abs(s.min_m - row.min_m) <= tol);
    CHECK(std::abs(s.max_m - row.max_m) <= tol);
    if (row.voids) CHECK(s.nodata_count == *row.voids);
    CHECK(s.valid_count + s.nodata_count == row.width * row.height);
  }
}

TEST_CASE("hgt georeference comes from the tile name", "[io][hgt]") {
  auto n = testdata::require("srtm3_N27E086_everest_himalaya.hgt");
  auto s = testdata::require("srtm3_S33W071_aconcagua_andes.hgt");
  if (n.empty() || s.empty()) return;
  terrain::GridInfo everest = terrain::probe(n);
  CHECK(everest.format == terrain::FileFormat::Hgt);
  CHECK(everest.sample_type == terrain::SampleType::Int16);
  CHECK(everest.spacing_x == 3.0);
  CHECK(everest.spacing_y == 3.0);
  CHECK(everest.horizontal_units == "arc-second");
  REQUIRE(everest.origin_x.has_value());
  REQUIRE(everest.origin_y.has_value());
  CHECK(*everest.origin_x == 86.0);
  CHECK(*everest.origin_y == 28.0);  // row 0 is the northern edge
  REQUIRE(everest.nodata.has_value());
  CHECK(*everest.nodata == -32768.0);
  terrain::GridInfo aconcagua = terrain::probe(s);
  CHECK(*aconcagua.origin_x == -71.0);
  CHECK(*aconcagua.origin_y == -32.0);  // manifest: S33W071's top row is 32S
}

TEST_CASE("Everest peak sits where the manifest says", "[io][hgt]") {
  auto n = testdata::require("srtm3_N27E086_everest_himalaya.hgt");
  if (n.empty()) return;
  terrain::Heightmap map = terrain::read_heightmap(n);
  int64_t best_x = 0, best_y = 0;
  for (int64_t y = 0; y < map.height(); ++y)
    for (int64_t x = 0; x < map.width(); ++x)
      if (map.at(x, y) > map.at(best_x, best_y)) best_x = x, best_y = y;
  double lat = *map.info.origin_y - double(best_y) * map.info.spacing_y / 3600.0;
  double lon = *map.info.origin_x + double(best_x) * map.info.spacing_x / 3600.0;
  // MANIFEST.md: max at 27.988N 86.925E.
  CHECK(std::abs(lat - 27.988) < 0.002);
  CHECK(std::abs(lon - 86.925) < 0.002);
}

TEST_CASE("Terrain-RGB is auto-detected for an RGBA PNG and decodes exactly", "[io][image]") {
  auto f = testdata::require("terrainrgb_fuji_512.png");
  if (f.empty()) return;
  terrain::GridInfo g = terrain::probe(f);
  CHECK(g.format == terrain::FileFormat::TerrainRgbImage);
  CHECK(g.sample_type == terrain::SampleType::TerrainRGB);
  CHECK(g.integer_valued());
  CHECK(g.vertical_scale == 0.1);
  CHECK(g.vertical_offset == -10000.0);
  terrain::ReadOptions explicit_rgb;
  explicit_rgb.terrain_rgb = true;
  terrain::Heightmap a = terrain::read_heightmap(f), b = terrain::read_heightmap(f, explicit_rgb);
  CHECK(a.values == b.values);
  bool integer_codes = true;  // 24-bit integer codes
  for (double v : a.values) integer_codes = integer_codes && v == std::floor(v) && v >= 0 && v < 16777216;
  CHECK(integer_codes);
}
