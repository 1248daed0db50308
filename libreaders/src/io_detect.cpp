// Format detection (file name first, then magic bytes) and the format-independent entry points.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <vector>

#include "core/text.h"
#include "readers/internal/io_internal.h"

namespace terrain {
namespace {

enum class Kind { Hgt, Esri, Ascii, Image, Raw };

Kind detect_kind(const std::string& path, const ReadOptions& options) {
  using io::ends_with_ci;
  if (ends_with_ci(path, ".hgt") || ends_with_ci(path, ".hgt.gz")) return Kind::Hgt;
  if (ends_with_ci(path, ".bil") || ends_with_ci(path, ".flt")) return Kind::Esri;
  if (ends_with_ci(path, ".asc")) return Kind::Ascii;
  for (const char* ext : {".png", ".tif", ".tiff", ".exr"})
    if (ends_with_ci(path, ext)) return Kind::Image;
  for (const char* ext : {".raw", ".bin", ".r16", ".r32", ".dat"})
    if (ends_with_ci(path, ext)) return Kind::Raw;

  // Unknown extension: look at the magic bytes.
  io::existing_file_size(path);
  unsigned char magic[4] = {0, 0, 0, 0};
  size_t got = 0;
  if (FILE* f = std::fopen(path.c_str(), "rb")) {
    got = std::fread(magic, 1, 4, f);
    std::fclose(f);
  } else {
    io::fail(ErrorCode::NotFound, path, std::string("cannot open: ") + std::strerror(errno));
  }
  if (got == 4) {
    if (std::memcmp(magic, "\x89PNG", 4) == 0 || std::memcmp(magic, "II*\0", 4) == 0 ||
        std::memcmp(magic, "MM\0*", 4) == 0 || std::memcmp(magic, "\x76\x2f\x31\x01", 4) == 0)
      return Kind::Image;
  }
  if (options.width || options.height || options.sample_type || io::file_exists(path + ".json"))
    return Kind::Raw;
  io::fail(ErrorCode::UnknownType, path,
           "unknown format: expected .hgt[.gz], .bil/.flt, .asc, .png/.tif/.exr, or a raw grid with a .json "
           "sidecar or --type/--width/--height");
}

// Values that came from a file (a header, a sidecar) or an override and that no stage can use: a
// MissingField error naming the file and the field, whatever the format.
const GridInfo& checked(const GridInfo& g, const std::string& path) {
  const auto bad = [&](const std::string& field, const std::string& rule) {
    io::fail(ErrorCode::MissingField, path, field + " " + rule);
  };
  if (!(std::isfinite(g.spacing_x) && g.spacing_x > 0)) bad("spacing_x", "must be finite and positive");
  if (!(std::isfinite(g.spacing_y) && g.spacing_y > 0)) bad("spacing_y", "must be finite and positive");
  if (!(std::isfinite(g.vertical_scale) && g.vertical_scale > 0))
    bad("vertical_scale", "must be finite and positive");
  if (!std::isfinite(g.vertical_offset)) bad("vertical_offset", "must be finite");
  constexpr size_t kMaxUnits = 31;  // the .pyr stores units in 32-byte fields
  if (g.horizontal_units.size() > kMaxUnits) bad("horizontal_units", "must be at most 31 bytes");
  for (const char c : g.horizontal_units)
    if (static_cast<unsigned char>(c) < 0x20) bad("horizontal_units", "must be printable text");
  if (g.origin_x && !std::isfinite(*g.origin_x)) bad("origin_x", "must be finite");
  if (g.origin_y && !std::isfinite(*g.origin_y)) bad("origin_y", "must be finite");
  if (!is_crs_text(g.crs_text))
    bad("crs_text", "must be at most " + std::to_string(kMaxCrsTextBytes) +
                        " bytes of text without control characters (it has " +
                        std::to_string(g.crs_text.size()) + " bytes)");
  if (g.crs_epsg && !(*g.crs_epsg >= 1 && *g.crs_epsg <= 999999)) bad("crs_epsg", "must be 1..999999");
  return g;
}

}  // namespace

GridInfo probe(const std::string& path, const ReadOptions& options) {
  switch (detect_kind(path, options)) {
    case Kind::Hgt:
      return checked(io::probe_hgt_layout(path, options).info, path);
    case Kind::Esri:
      return checked(io::probe_esri_layout(path, options).info, path);
    case Kind::Ascii:
      return checked(io::probe_ascii_grid(path, options), path);
    case Kind::Image:
      return checked(io::probe_image(path, options), path);
    case Kind::Raw:
      return checked(io::probe_raw_layout(path, options).info, path);
  }
  return {};
}

int64_t BandReader::read_rows_int32(int64_t, int32_t*, uint8_t*) {
  throw std::logic_error(
      "BandReader::read_rows_int32: this reader decodes to doubles only (reads_int32 is false)");
}

int64_t BandReader::skip_rows(int64_t rows) {
  const int64_t w = info().width;
  // In chunks of about 1 MiB of doubles, so that skipping costs no more memory than reading.
  const int64_t chunk = std::clamp<int64_t>((int64_t(1) << 17) / std::max<int64_t>(w, 1), 1, 256);
  std::vector<double> values(size_t(std::min(chunk, std::max<int64_t>(rows, 0)) * w));
  std::vector<uint8_t> valid(values.size());
  int64_t skipped = 0;
  while (skipped < rows) {
    const int64_t n = read_rows(std::min(chunk, rows - skipped), values.data(), valid.data());
    if (n <= 0) break;
    skipped += n;
  }
  return skipped;
}

std::unique_ptr<BandReader> open_band_reader(const std::string& path, const ReadOptions& options) {
  std::unique_ptr<BandReader> reader;
  switch (detect_kind(path, options)) {
    case Kind::Hgt:
      reader = io::open_raw_stream(path, io::probe_hgt_layout(path, options));
      break;
    case Kind::Esri:
      reader = io::open_raw_stream(path, io::probe_esri_layout(path, options));
      break;
    case Kind::Ascii:
      reader = io::open_ascii_grid(path, options);
      break;
    case Kind::Image:
      reader = io::open_image_reader(path, options);
      break;
    case Kind::Raw:
      reader = io::open_raw_stream(path, io::probe_raw_layout(path, options));
      break;
  }
  if (reader) checked(reader->info(), path);
  return reader;
}

Heightmap read_heightmap(const std::string& path, const ReadOptions& options) {
  auto reader = open_band_reader(path, options);
  Heightmap map;
  map.info = reader->info();
  const int64_t w = map.info.width, h = map.info.height;
  if (uint64_t(w) * uint64_t(h) > (uint64_t(1) << 34))
    io::fail(ErrorCode::DimensionMismatch, path, "grid too large to hold in memory; use the band reader");
  map.values.resize(size_t(w * h));
  map.valid.resize(size_t(w * h));
  // Rows land directly in place, so no band buffer is needed on top of the result.
  constexpr int64_t kBandRows = 256;
  int64_t row = 0;
  while (row < h) {
    int64_t n = reader->read_rows(kBandRows, map.values.data() + row * w, map.valid.data() + row * w);
    if (n <= 0) io::fail(ErrorCode::Truncated, path, "reader stopped at row " + std::to_string(row));
    row += n;
  }
  bool all_valid = true;
  for (uint8_t v : map.valid) all_valid = all_valid && v;
  if (all_valid) map.valid.clear();
  return map;
}

}  // namespace terrain
