// terrain-info: describe a heightmap file (format, size, type, min/max in metres, voids, spacing,
// georeference), streaming it band by band so any size fits in memory; or a pyramid file (.pyr) from
// its header and index alone.
#include <algorithm>
#include <array>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "cli.h"
#include "container/container.h"
#include "container/pyramid_file.h"
#include "json_writer.h"
#include "progress.h"
#include "readers/heightmap.h"

namespace {

using terrain::container::Container;
using terrain::container::ContainerInfo;
using terrain::container::error_mode_name;
using terrain::container::ErrorMode;

// How the builder chose D (the decoder never needs it; edits and terrain-report do).
const char* filter_description(terrain::container::FilterProvenance p) {
  switch (p) {
    case terrain::container::FilterProvenance::Optimal:
      return "optimal (fitted to the terrain, taps stored)";
    case terrain::container::FilterProvenance::Fallback:
      return "fallback (the default tent: the fit was degenerate)";
    case terrain::container::FilterProvenance::Point:
      return "point (every level's samples are input samples)";
    case terrain::container::FilterProvenance::Wavelet:
      return "wavelet (the dual of the four-point U)";
  }
  return "unknown";
}

// GDAL's six terms, 15 significant digits (--json has the exact values).
void print_geotransform(const std::array<double, 6>& gt) {
  std::printf("geotransform: %.15g, %.15g, %.15g, %.15g, %.15g, %.15g\n", gt[0], gt[1], gt[2], gt[3], gt[4],
              gt[5]);
}

// The CRS line: "EPSG:n", the CRS text's first 60 bytes (--json has it whole), or "unknown".
void print_crs(uint32_t epsg, const std::string& text) {
  std::string line = epsg ? "EPSG:" + std::to_string(epsg) : std::string();
  if (!text.empty()) {
    std::string head = text.substr(0, 60);
    for (char& c : head)
      if (c == '\n' || c == '\r' || c == '\t') c = ' ';
    line += (line.empty() ? "" : ", ") + head + (text.size() > 60 ? "..." : "");
  }
  std::printf("crs:          %s\n", line.empty() ? "unknown" : line.c_str());
}

// A .pyr: what its header and index say (nothing is decoded); with verify, every level's checksum,
// band table and tile.
int describe_pyramid(const std::string& path, const cli::CommonFlags& common, bool verify) {
  const Container c = Container::open(path);
  // Checksums can be consistent and the structure still wrong (a forged band table, resealed):
  // --verify also parses every level's band table and decodes every tile of every band. The band
  // tables also give each level's bytes wherever an edit left them, and the dead bytes.
  // Without --verify the description needs the index only: a damaged band table is reported by
  // --verify, and the sizes then fall back to the level blobs' (dead bytes unknown).
  std::shared_ptr<const terrain::container::PyramidFile> pf;
  try {
    pf = terrain::container::PyramidFile::open(path);
  } catch (const terrain::Error&) {
    if (verify) throw;
  }
  if (verify) pf->verify();
  const auto level_bytes = [&](uint32_t l) {
    return pf ? pf->level_bytes(int(l)) : uint64_t(c.level(l).size);
  };
  const ContainerInfo& info = c.info();
  const uint64_t file_bytes = uint64_t(std::filesystem::file_size(path));
  const double finest_samples = double(info.width) * double(info.height);
  const std::string version = std::to_string(c.major_version()) + "." + std::to_string(c.minor_version());
  const auto& q = info.quantisation;
  if (common.json) {
    cli::JsonWriter j(std::cout);
    j.begin_object();
    j.field("file", path).field("format", "pyramid").field("format_version", version);
    j.field("width", int64_t(info.width)).field("height", int64_t(info.height));
    j.field("level_count", int64_t(info.levels.size()));
    j.field("spacing_x", info.spacing_x).field("spacing_y", info.spacing_y);
    j.field("horizontal_units", info.horizontal_units).field("vertical_units", info.vertical_units);
    j.field("vertical_scale", info.vertical_scale).field("vertical_offset", info.vertical_offset);
    j.key("georeference");
    if (info.georeference) {
      j.begin_object();
      const terrain::container::Georeference& geo = *info.georeference;
      j.field("origin_x", geo.origin_x()).field("origin_y", geo.origin_y());
      j.key("geotransform").begin_array();
      for (const double v : geo.geotransform) j.value(v);
      j.end_array();
      j.field("units", geo.units);
      j.key("crs_epsg");
      geo.crs_epsg ? j.value(int64_t(geo.crs_epsg)) : j.null();
      j.key("crs_text");
      geo.crs_text.empty() ? j.null() : j.value(geo.crs_text);
      j.end_object();
    } else {
      j.null();
    }
    j.field("error_mode", error_mode_name(q.mode)).field("target", q.target);
    j.field("step_units", q.step_units).field("step_m", q.step_metres);
    j.field("void_count", int64_t(info.void_count)).field("filter_size", int64_t(info.filter_size));
    j.field("downsample_filter", terrain::container::filter_provenance_name(info.filter_provenance));
    j.field("file_bytes", int64_t(file_bytes))
        .field("bits_per_sample", double(file_bytes) * 8 / finest_samples);
    j.field("checksums_verified", verify).field("tiles_decoded", verify);
    j.field("edited", c.edited()).field("edit_generation", int64_t(c.generation()));
    j.field("dead_bytes", int64_t(pf->dead_bytes()))
        .field("uncommitted_bytes", int64_t(c.uncommitted_bytes()));
    j.field("from_tail_superblock", c.from_tail_superblock());
    j.key("levels").begin_array();
    for (uint32_t l = 0; l < c.level_count(); ++l) {
      const auto& li = info.levels[l];
      j.begin_object();
      j.field("level", int64_t(l)).field("width", int64_t(li.width)).field("height", int64_t(li.height));
      j.field("bytes", int64_t(level_bytes(l)));
      j.field("residual_rms_units", li.stats.rms);
      const auto error = terrain::container::level_error_metres(info, l);
      j.key("error_rms_m");
      error ? j.value(error->rms) : j.null();
      j.key("error_max_m");
      error ? j.value(error->max_abs) : j.null();
      j.end_object();
    }
    j.end_array();
    j.field("metadata", std::string(c.metadata_json()));
    j.end_object();
    j.finish();
    return cli::kExitOk;
  }
  using cli::shortest;
  std::printf("file:         %s\n", path.c_str());
  std::printf("format:       pyramid (.pyr) version %s\n", version.c_str());
  std::printf("dimensions:   %" PRIu64 " x %" PRIu64 " (finest level), %zu levels\n", info.width, info.height,
              info.levels.size());
  std::printf("vertical:     metres = value * %s + %s\n", shortest(info.vertical_scale).c_str(),
              shortest(info.vertical_offset).c_str());
  if (q.mode == ErrorMode::Lossless)
    std::printf("error:        lossless\n");
  else  // --json has the exact step
    std::printf("error:        %s target %s m, step %.6g units (%.6g m)\n", error_mode_name(q.mode),
                shortest(q.target).c_str(), q.step_units, q.step_metres);
  std::printf("spacing:      %s x %s %s\n", shortest(info.spacing_x).c_str(),
              shortest(info.spacing_y).c_str(), info.horizontal_units.c_str());
  if (info.georeference) {
    const terrain::container::Georeference& geo = *info.georeference;
    const auto& gt = geo.geotransform;
    std::printf("origin:       north-west sample at x %s, y %s %s\n", shortest(geo.origin_x()).c_str(),
                shortest(geo.origin_y()).c_str(), geo.units.c_str());
    print_geotransform(gt);
    print_crs(geo.crs_epsg, geo.crs_text);
  } else {
    std::printf("origin:       unknown\n");
  }
  std::printf("voids:        %" PRIu64 " of %.0f samples\n", info.void_count, finest_samples);
  std::printf("D filter:     %s\n", filter_description(info.filter_provenance));
  std::printf("size:         %" PRIu64 " bytes, %.4f bits per finest sample\n", file_bytes,
              double(file_bytes) * 8 / finest_samples);
  if (c.edited() || c.uncommitted_bytes() > 0)
    std::printf("edits:        generation %" PRIu64 ", %" PRIu64
                " dead bytes (terrain-edit --compact drops them)%s%s\n",
                c.generation(), pf->dead_bytes(),
                c.uncommitted_bytes() ? (", " + std::to_string(c.uncommitted_bytes()) +
                                         " uncommitted bytes of an interrupted edit")
                                            .c_str()
                                      : "",
                c.from_tail_superblock() ? ", superblock torn: read through its tail copy" : "");
  std::printf("checksums:    %s\n", verify
                                        ? "every level verified, every band table parsed, every tile decoded"
                                        : "header and index verified (--verify: levels and tiles too)");
  std::printf("%5s %13s %12s %9s %12s %12s\n", "level", "size", "bytes", "bits/smp", "error_rms_m",
              "error_max_m");
  for (uint32_t l = 0; l < c.level_count(); ++l) {
    const auto& li = info.levels[l];
    const std::string size = std::to_string(li.width) + "x" + std::to_string(li.height);
    const size_t bytes = size_t(level_bytes(l));
    std::printf("%5u %13s %12zu %9.4f", l, size.c_str(), bytes,
                double(bytes) * 8 / double(li.width * li.height));
    if (const auto error = terrain::container::level_error_metres(info, l))
      std::printf(" %12.4f %12.4f\n", error->rms, error->max_abs);
    else
      std::printf(" %12s %12s\n", "-", "-");
  }
  if (!c.metadata_json().empty())
    std::printf("metadata:     %.*s\n", int(c.metadata_json().size()), c.metadata_json().data());
  return cli::kExitOk;
}

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
      "16-bit PNG/TIFF, float TIFF/EXR, Mapbox Terrain-RGB PNG. See docs/io.md.\n"
      "A pyramid file (.pyr, recognised by its magic bytes) is described from its header and index\n"
      "without decoding: levels, bytes, quantisation, the builder's error figures per level.");
  bool verify = false;
  parser.positional("FILE", "the heightmap or pyramid to describe", &path);
  parser.flag("--verify",
              "pyramid files: also check every level's checksum and band table and decode every tile (reads "
              "the whole file; a wrong band table or a damaged tile is exit 10, naming level, band record "
              "and field)",
              &verify);
  cli::add_read_options(parser, options);
  parser.add_common(common);
  if (auto status = parser.parse(argc, argv)) return *status;
  if (terrain::container::is_container_file(path)) {
    return describe_pyramid(path, common, verify);
  }
  if (verify) throw cli::UsageError("--verify applies to pyramid files only");

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
    // Values a grid may lack are written as null.
    auto field_or_null = [&j](const char* key, std::optional<double> v) {
      j.key(key);
      if (v)
        j.value(*v);
      else
        j.null();
    };
    const auto if_valid = [valid_count](double v) { return valid_count ? std::optional(v) : std::nullopt; };
    field_or_null("nodata_value", g.nodata);
    field_or_null("min_m", if_valid(min_m));
    field_or_null("max_m", if_valid(max_m));
    field_or_null("mean_m", if_valid(mean_m));
    j.field("valid_count", valid_count).field("nodata_count", nodata_count);
    j.field("spacing_x", g.spacing_x)
        .field("spacing_y", g.spacing_y)
        .field("horizontal_units", g.horizontal_units);
    field_or_null("origin_x", g.origin_x);
    field_or_null("origin_y", g.origin_y);
    j.key("geotransform");
    if (const auto gt = terrain::geotransform(g)) {
      j.begin_array();
      for (const double v : *gt) j.value(v);
      j.end_array();
    } else {
      j.null();
    }
    field_or_null("crs_epsg", g.crs_epsg ? std::optional<double>(*g.crs_epsg) : std::nullopt);
    j.key("crs_text");
    if (g.crs_text.empty())
      j.null();
    else
      j.value(g.crs_text);
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
  if (const auto gt = terrain::geotransform(g)) print_geotransform(*gt);
  print_crs(g.crs_epsg ? uint32_t(*g.crs_epsg) : 0, g.crs_text);
  return cli::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  return cli::run_tool("terrain-info", [&] { return run(argc, argv); });
}
