// SRTM .hgt tiles (optionally gzipped): size from the byte count, georeference from the file name.
#include <cctype>
#include <cstdio>
#include <filesystem>

#include "readers/internal/io_internal.h"

namespace terrain::io {
namespace {

constexpr uint64_t kSrtm3Bytes = 2ull * 1201 * 1201;
constexpr uint64_t kSrtm1Bytes = 2ull * 3601 * 3601;

// Finds "N27E086"-style coordinates anywhere in the file name (tiles are often renamed with prefixes).
bool parse_tile_name(const std::string& name, int& lat, int& lon) {
  for (size_t i = 0; i + 7 <= name.size(); ++i) {
    char ns = char(std::toupper(static_cast<unsigned char>(name[i])));
    char ew = char(std::toupper(static_cast<unsigned char>(name[i + 3])));
    if ((ns != 'N' && ns != 'S') || (ew != 'E' && ew != 'W')) continue;
    auto digit = [&](size_t k) { return std::isdigit(static_cast<unsigned char>(name[k])) != 0; };
    if (!digit(i + 1) || !digit(i + 2) || !digit(i + 4) || !digit(i + 5) || !digit(i + 6)) continue;
    if (i + 7 < name.size() && digit(i + 7)) continue;
    lat = (name[i + 1] - '0') * 10 + (name[i + 2] - '0');
    lon = (name[i + 4] - '0') * 100 + (name[i + 5] - '0') * 10 + (name[i + 6] - '0');
    if (lat > 90 || lon > 180) continue;
    if (ns == 'S') lat = -lat;
    if (ew == 'W') lon = -lon;
    return true;
  }
  return false;
}

// gzip keeps the uncompressed length modulo 2^32 in its last four bytes (ISIZE, little endian).
uint64_t gzip_uncompressed_size(const std::string& path, uint64_t file_size) {
  if (file_size < 18) fail(ErrorCode::Truncated, path, "too short to be a gzip stream");
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) fail(ErrorCode::NotFound, path, "cannot open");
  unsigned char magic[2] = {0, 0}, tail[4] = {0, 0, 0, 0};
  bool ok = std::fread(magic, 1, 2, f) == 2 && fseeko(f, -4, SEEK_END) == 0 && std::fread(tail, 1, 4, f) == 4;
  std::fclose(f);
  if (!ok) fail(ErrorCode::NotFound, path, "read error");
  if (magic[0] != 0x1f || magic[1] != 0x8b)
    fail(ErrorCode::CorruptData, path, "not a gzip stream (bad magic)");
  return uint64_t(tail[0]) | uint64_t(tail[1]) << 8 | uint64_t(tail[2]) << 16 | uint64_t(tail[3]) << 24;
}

}  // namespace

RawLayout probe_hgt_layout(const std::string& path, const ReadOptions& options) {
  uint64_t file_size = existing_file_size(path);
  RawLayout layout;
  layout.gzip = ends_with_ci(path, ".gz");
  uint64_t size = layout.gzip ? gzip_uncompressed_size(path, file_size) : file_size;
  layout.stored = options.sample_type ? stored_type_for(*options.sample_type) : StoredType::Int16;
  layout.big_endian = options.big_endian.value_or(true);
  GridInfo& g = layout.info;
  g.format = FileFormat::Hgt;
  g.sample_type = options.sample_type.value_or(SampleType::Int16);
  g.horizontal_units = "arc-second";
  g.nodata = -32768.0;

  const char* what = layout.gzip ? "uncompressed size " : "";
  if (options.width || options.height) {
    g.width = options.width.value_or(options.height.value_or(0));
    g.height = options.height.value_or(g.width);
    // A non-standard tile still spans one degree, so its spacing follows from the sample count.
    g.spacing_x = g.width > 1 ? 3600.0 / double(g.width - 1) : 3600.0;
    g.spacing_y = g.height > 1 ? 3600.0 / double(g.height - 1) : 3600.0;
    uint64_t need = layout_bytes(path, layout);
    if (size != need)
      fail(size < need ? ErrorCode::Truncated : ErrorCode::Oversized, path,
           std::string(what) + std::to_string(size) + " bytes, but " + std::to_string(g.width) + "x" +
               std::to_string(g.height) + " needs " + std::to_string(need));
  } else if (size == kSrtm3Bytes || size == kSrtm1Bytes) {
    g.width = g.height = size == kSrtm3Bytes ? 1201 : 3601;
    g.spacing_x = g.spacing_y = size == kSrtm3Bytes ? 3.0 : 1.0;
  } else {
    // Blame the nearer of the two standard tile sizes: short of it is truncation, past it oversize.
    uint64_t nearest =
        (size < kSrtm3Bytes || size - kSrtm3Bytes < kSrtm1Bytes - size) ? kSrtm3Bytes : kSrtm1Bytes;
    const char* tile = nearest == kSrtm3Bytes ? "1201x1201 (SRTM3)" : "3601x3601 (SRTM1)";
    if (size < nearest)
      fail(ErrorCode::Truncated, path,
           std::string("truncated: ") + what + std::to_string(size) + " bytes, " +
               std::to_string(nearest - size) + " short of a " + tile + " tile (" + std::to_string(nearest) +
               " bytes)");
    fail(ErrorCode::Oversized, path,
         std::string("oversized: ") + what + std::to_string(size) + " bytes, " +
             std::to_string(size - nearest) + " more than a " + tile + " tile (" + std::to_string(nearest) +
             " bytes)");
  }
  int lat = 0, lon = 0;
  if (parse_tile_name(std::filesystem::path(path).filename().string(), lat, lon)) {
    g.origin_x = double(lon);
    g.origin_y = double(lat + 1);  // row 0 is the northern edge, one degree above the SW corner
    g.crs_epsg = 4326;             // SRTM heights are on WGS 84 (EGM96 geoid)
  }
  apply_common_overrides(g, options);
  return layout;
}

}  // namespace terrain::io
