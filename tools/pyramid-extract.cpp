// pyramid-extract: any level and window of a .pyr back out as a heightmap file: GeoTIFF (streamed
// in bands, georeferenced, float32 or int16 with nodata), 16-bit PNG, float32 EXR or raw + JSON
// sidecar. Decoding goes through the region decoder, so only the tiles the window needs are read.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "cli.h"
#include "container/pyramid_file.h"
#include "export/geotiff.h"
#include "json_writer.h"
#include "progress.h"
#include "report_file.h"
#include "runtime/region_decoder.h"

namespace {

using terrain::Error;
using terrain::ErrorCode;

std::vector<double> parse_list(const std::string& option, const std::string& text, size_t count) {
  std::vector<double> v;
  std::stringstream ss(text);
  std::string part;
  while (std::getline(ss, part, ',')) v.push_back(cli::parse_double(option, part));
  if (v.size() != count)
    throw cli::UsageError(option + " takes " + std::to_string(count) + " comma-separated numbers");
  return v;
}

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// The level's geotransform (pixel corners) from the file's georeference of the finest sample centre.
std::optional<terrain::GeoTransform> level_geotransform(const terrain::container::ContainerInfo& info,
                                                        int level) {
  if (!info.georeference) return std::nullopt;
  // The stored geotransform is the finest level's; level l's samples are 2^(m-l) times larger, and
  // its sample (0, 0) is centred where the finest level's is (D is centred on even samples).
  const std::array<double, 6>& t = info.georeference->geotransform;
  const double f = std::ldexp(1.0, int(info.levels.size()) - 1 - level);  // level spacing / finest spacing
  terrain::GeoTransform g;
  g.dx = t[1] * f;
  g.dy = -t[5] * f;
  g.x0 = info.georeference->origin_x() - 0.5 * g.dx;
  g.y0 = info.georeference->origin_y() + 0.5 * g.dy;
  return g;
}

constexpr const char* kDescription =
    R"(Decodes one level (default: the finest) of a pyramid, whole or a window of it, to a heightmap
file chosen by OUT's extension: .tif/.tiff GeoTIFF (georeferenced when the pyramid is; float32
metres with NaN voids, or int16 with nodata -32768; streamed in bands: memory stays bounded for
any window), .png 16-bit grey (integer metres 0..65535), .exr float32, .raw + .raw.json sidecar.
PNG, EXR and raw hold the window in memory (8 bytes per sample).)";

int run(int argc, char** argv) {
  std::string input, output, json_path, type_name = "float32";
  std::optional<int> level;
  std::optional<std::vector<double>> window, bbox;
  int64_t band_rows = 256;
  cli::CommonFlags common;
  cli::ArgParser parser("pyramid-extract",
                        "PYRAMID.pyr -o OUT [--level L] [--window X,Y,W,H | --bbox W,S,E,N] [options]",
                        kDescription);
  parser.positional("PYRAMID", "the .pyr file", &input);
  parser.option("-o,--output", "OUT", "file to write (required)", &output);
  parser.option("--level", "L", "level to extract, 0 = coarsest (default: the finest)",
                [&](const std::string& v) { level = int(cli::parse_int("--level", v, 0, 63)); });
  parser.option("--window", "X,Y,W,H", "window in the level's samples (default: the whole level)",
                [&](const std::string& v) { window = parse_list("--window", v, 4); });
  parser.option("--bbox", "W,S,E,N", "window by map coordinates (the samples whose centres lie inside)",
                [&](const std::string& v) { bbox = parse_list("--bbox", v, 4); });
  parser.option("--type", "T", "sample type of GeoTIFF / raw output: float32 (default) or int16",
                [&](const std::string& v) {
                  if (v != "float32" && v != "int16") throw cli::UsageError("--type is float32 or int16");
                  type_name = v;
                });
  parser.option("--band-rows", "N", "rows decoded at a time (default 256)",
                [&](const std::string& v) { band_rows = cli::parse_int("--band-rows", v, 1, 1 << 20); });
  parser.option("--json", "FILE", "write a JSON report to FILE ('-' for stdout)", &json_path);
  parser.add_common(common, false);
  if (auto status = parser.parse(argc, argv)) return *status;
  if (output.empty()) throw cli::UsageError("missing -o OUT");
  if (window && bbox) throw cli::UsageError("give --window or --bbox, not both");

  const auto file = terrain::container::PyramidFile::open(input);
  const terrain::container::ContainerInfo& info = file->info();
  const int l = level.value_or(file->level_count() - 1);
  if (l >= file->level_count())
    throw cli::UsageError("--level " + std::to_string(l) + ": the pyramid has levels 0.." +
                          std::to_string(file->level_count() - 1));
  const terrain::GridSize size = file->level_size(l);
  const std::optional<terrain::GeoTransform> level_gt = level_geotransform(info, l);
  terrain::Rect rect{0, 0, size.width, size.height};
  if (window) {
    const auto& w = *window;
    for (double v : w)
      if (v != std::floor(v)) throw cli::UsageError("--window takes whole sample numbers");
    rect = terrain::Rect{int64_t(w[0]), int64_t(w[1]), int64_t(w[2]), int64_t(w[3])};
  } else if (bbox) {
    if (!level_gt) throw cli::UsageError("--bbox needs a georeferenced pyramid (this one has none)");
    const auto& b = *bbox;  // west, south, east, north
    const terrain::GeoTransform& g = *level_gt;
    const double cx0 = g.x0 + 0.5 * g.dx, cy0 = g.y0 - 0.5 * g.dy;  // centre of sample (0, 0)
    const int64_t x0 = std::max<int64_t>(0, int64_t(std::ceil((b[0] - cx0) / g.dx - 1e-9)));
    const int64_t x1 = std::min<int64_t>(size.width - 1, int64_t(std::floor((b[2] - cx0) / g.dx + 1e-9)));
    const int64_t y0 = std::max<int64_t>(0, int64_t(std::ceil((cy0 - b[3]) / g.dy - 1e-9)));
    const int64_t y1 = std::min<int64_t>(size.height - 1, int64_t(std::floor((cy0 - b[1]) / g.dy + 1e-9)));
    if (x1 < x0 || y1 < y0)
      throw cli::UsageError("--bbox holds no sample centre of level " + std::to_string(l));
    rect = terrain::Rect{x0, y0, x1 - x0 + 1, y1 - y0 + 1};
  }
  if (rect.width < 1 || rect.height < 1 || rect.x0 < 0 || rect.y0 < 0 || rect.x0 > size.width - rect.width ||
      rect.y0 > size.height - rect.height)
    throw cli::UsageError("--window is not inside level " + std::to_string(l) + " (" +
                          std::to_string(size.width) + "x" + std::to_string(size.height) + ")");

  const terrain::runtime::RegionDecoder decoder(file);
  const bool geotiff = ends_with(output, ".tif") || ends_with(output, ".tiff");
  const bool int16 = type_name == "int16";
  std::optional<terrain::GeoTransform> gt;
  if (level_gt) {
    gt = *level_gt;
    gt->x0 += rect.x0 * gt->dx;
    gt->y0 -= rect.y0 * gt->dy;
  }
  cli::Progress progress("extracting", rect.height, !common.quiet);
  std::vector<float> band(size_t(rect.width * std::min(band_rows, rect.height)));
  const auto decode_band = [&](int64_t y, int64_t rows, float* out) {
    decoder.decode_metres(l, terrain::Rect{rect.x0, rect.y0 + y, rect.width, rows}, out, rect.width);
  };
  if (geotiff) {
    terrain::GeoTiffOptions o;
    o.type = int16 ? terrain::SampleType::Int16 : terrain::SampleType::Float32;
    o.geotransform = gt;
    if (info.georeference) {
      const terrain::container::Georeference& geo = *info.georeference;
      if (geo.crs_epsg) o.epsg = int(geo.crs_epsg);
      o.geographic = geo.units == "degree";
      o.crs_text = geo.crs_text;
    }
    terrain::GeoTiffWriter writer(output, rect.width, rect.height, o);
    for (int64_t y = 0; y < rect.height; y += band_rows) {
      const int64_t rows = std::min(band_rows, rect.height - y);
      decode_band(y, rows, band.data());
      writer.write_rows(band.data(), rows);
      progress.update(y + rows);
    }
    writer.finish();
  } else {
    if (!ends_with(output, ".png") && !ends_with(output, ".exr") && !ends_with(output, ".raw"))
      throw cli::UsageError("-o " + output + ": the extension must be .tif, .tiff, .png, .exr or .raw");
    terrain::Heightmap map;
    map.info.width = rect.width;
    map.info.height = rect.height;
    map.info.spacing_x = info.spacing_x * std::ldexp(1.0, file->level_count() - 1 - l);
    map.info.spacing_y = info.spacing_y * std::ldexp(1.0, file->level_count() - 1 - l);
    map.info.horizontal_units = info.horizontal_units;
    if (gt) map.info.origin_x = gt->x0 + 0.5 * gt->dx, map.info.origin_y = gt->y0 - 0.5 * gt->dy;
    if (info.georeference && info.georeference->crs_epsg)
      map.info.crs_epsg = int(info.georeference->crs_epsg);
    if (info.georeference) map.info.crs_text = info.georeference->crs_text;
    const bool png = ends_with(output, ".png");
    map.info.sample_type = png || int16 ? terrain::SampleType::Int16 : terrain::SampleType::Float32;
    if (png) map.info.sample_type = terrain::SampleType::UInt16;
    map.values.resize(size_t(rect.width * rect.height));
    for (int64_t y = 0; y < rect.height; y += band_rows) {
      const int64_t rows = std::min(band_rows, rect.height - y);
      decode_band(y, rows, band.data());
      for (int64_t i = 0; i < rows * rect.width; ++i) {
        const float v = band[size_t(i)];
        const size_t k = size_t(y * rect.width + i);
        if (std::isnan(v)) {
          if (map.valid.empty()) map.valid.assign(map.values.size(), 1);
          map.valid[k] = 0;
        } else {
          map.values[k] = double(v);
        }
      }
      progress.update(y + rows);
    }
    if (!map.valid.empty())
      map.info.nodata = map.info.sample_type == terrain::SampleType::Float32 ? std::nan("") : -32768.0;
    if (ends_with(output, ".exr"))
      terrain::write_exr(output, map);
    else if (png)
      terrain::write_image16(output, map);
    else
      terrain::write_raw(output, map);
  }
  progress.finish();

  if (!json_path.empty()) {
    cli::ReportFile report(json_path);
    std::ostream& os = report.stream();
    cli::JsonWriter j(os);
    j.begin_object();
    j.key("input").value(input).key("output").value(output).key("level").value(int64_t(l));
    j.key("window").begin_array();
    for (int64_t v : {rect.x0, rect.y0, rect.width, rect.height}) j.value(v);
    j.end_array();
    j.key("type").value(geotiff ? type_name : std::string(ends_with(output, ".png") ? "uint16" : type_name));
    if (gt) {
      j.key("geotransform").begin_array();
      for (double v : {gt->x0, gt->dx, 0.0, gt->y0, 0.0, -gt->dy}) j.value(v);
      j.end_array();
    }
    j.end_object();
    j.finish();
    report.finish();
  }
  if (common.verbose)
    std::cerr << "pyramid-extract: level " << l << ", " << rect.width << "x" << rect.height << " samples at ("
              << rect.x0 << ", " << rect.y0 << ") -> " << output << "\n";
  return cli::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  return cli::run_tool("pyramid-extract", [&] { return run(argc, argv); });
}
