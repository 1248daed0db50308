// terrain-info: describe a heightmap file (format, size, type, min/max in metres, voids, spacing,
// georeference), streaming it band by band so any size fits in memory.
#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <iostream>
#include <vector>

#include "cli.h"
#include "json_writer.h"
#include "progress.h"
#include "pyramid/heightmap.h"

namespace {

int run(int argc, char** argv) {
  std::string path;
  cli::CommonFlags common;
  terrain::ReadOptions options;
  cli::ArgParser parser(
      "terrain-info", "FILE [read options] [--json]",
      "Describes a heightmap: detected format, dimensions, sample type, min/max in metres over\n"
      "valid samples, nodata count, spacing and units, georeference. Reads the file as a stream\n"
      "of row bands, so memory stays O(width). Formats: SRTM .hgt/.hgt.gz, ESRI .bil/.flt + .hdr,\n"
      "raw grids (.raw/.bin/.r16/.r32 with a <file>.json sidecar or --type/--width/--height),\n"
      "16-bit PNG/TIFF, float TIFF/EXR, Mapbox Terrain-RGB PNG. See docs/io.md.");
  parser.positional("FILE", "the heightmap to describe", &path);
  cli::add_read_options(parser, options);
  parser.add_common(common);
  if (auto status = parser.parse(argc, argv)) return *status;

  auto reader = terrain::open_band_reader(path, options);
  const terrain::GridInfo& g = reader->info();
  // About a million samples per band: large enough for fast reads, small enough for any width.
  const int64_t band_rows = std::max<int64_t>(1, (int64_t(1) << 20) / std::max<int64_t>(1, g.width));
  std::vector<double> values(size_t(band_rows * g.width));
  std::vector<uint8_t> valid(values.size());
  double lo = 0, hi = 0, sum = 0;
  int64_t valid_count = 0, nodata_count = 0;
  cli::Progress progress("terrain-info: reading " + path, g.height, !common.quiet && !common.json);
  while (int64_t n = reader->read_rows(band_rows, values.data(), valid.data())) {
    for (int64_t i = 0; i < n * g.width; ++i) {
      if (!valid[size_t(i)]) {
        ++nodata_count;
        continue;
      }
      double v = values[size_t(i)];
      if (valid_count == 0) lo = hi = v;
      lo = std::min(lo, v);
      hi = std::max(hi, v);
      sum += v;
      ++valid_count;
    }
    progress.update(reader->rows_read());
  }
  progress.finish();
  double min_m =
      std::min(lo * g.vertical_scale + g.vertical_offset, hi * g.vertical_scale + g.vertical_offset);
  double max_m =
      std::max(lo * g.vertical_scale + g.vertical_offset, hi * g.vertical_scale + g.vertical_offset);
  double mean_m = valid_count ? (sum / double(valid_count)) * g.vertical_scale + g.vertical_offset : 0.0;

  if (common.json) {
    cli::JsonWriter j(std::cout);
    j.begin_object();
    j.field("file", path).field("format", terrain::file_format_name(g.format));
    j.field("width", g.width).field("height", g.height);
    j.field("sample_type", terrain::sample_type_name(g.sample_type))
        .field("integer_valued", g.integer_valued());
    j.field("vertical_scale", g.vertical_scale).field("vertical_offset", g.vertical_offset);
    j.key("nodata_value");
    if (g.nodata)
      j.value(*g.nodata);
    else
      j.null();
    j.key("min_m");
    if (valid_count)
      j.value(min_m);
    else
      j.null();
    j.key("max_m");
    if (valid_count)
      j.value(max_m);
    else
      j.null();
    j.key("mean_m");
    if (valid_count)
      j.value(mean_m);
    else
      j.null();
    j.field("valid_count", valid_count).field("nodata_count", nodata_count);
    j.field("spacing_x", g.spacing_x)
        .field("spacing_y", g.spacing_y)
        .field("horizontal_units", g.horizontal_units);
    j.key("origin_x");
    if (g.origin_x)
      j.value(*g.origin_x);
    else
      j.null();
    j.key("origin_y");
    if (g.origin_y)
      j.value(*g.origin_y);
    else
      j.null();
    j.end_object();
    j.finish();
    return cli::kExitOk;
  }
  using cli::shortest;
  std::printf("file:         %s\n", path.c_str());
  std::printf("format:       %s\n", terrain::file_format_name(g.format));
  std::printf("dimensions:   %" PRId64 " x %" PRId64 "\n", g.width, g.height);
  std::printf("sample type:  %s\n", terrain::sample_type_name(g.sample_type));
  std::printf("vertical:     metres = value * %s + %s\n", shortest(g.vertical_scale).c_str(),
              shortest(g.vertical_offset).c_str());
  if (valid_count)
    // 10 significant digits hide binary noise such as 13.700000000000728; --json has the exact values.
    std::printf("min / max:    %.10g / %.10g m (mean %.6g m)\n", min_m, max_m, mean_m);
  else
    std::printf("min / max:    - (no valid samples)\n");
  if (g.nodata)
    std::printf("nodata:       %" PRId64 " of %" PRId64 " samples (value %s)\n", nodata_count,
                g.width * g.height, shortest(*g.nodata).c_str());
  else
    std::printf("nodata:       none defined\n");
  std::printf("spacing:      %s x %s %s\n", shortest(g.spacing_x).c_str(), shortest(g.spacing_y).c_str(),
              g.horizontal_units.c_str());
  if (g.origin_x && g.origin_y)
    std::printf("origin:       north-west sample at x %s, y %s\n", shortest(*g.origin_x).c_str(),
                shortest(*g.origin_y).c_str());
  else
    std::printf("origin:       unknown\n");
  return cli::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  return cli::run_tool("terrain-info", [&] { return run(argc, argv); });
}
