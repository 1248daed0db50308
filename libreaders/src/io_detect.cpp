// Format detection (file name first, then magic bytes) and the format-independent entry points.
#include <cstdio>
#include <cstring>

#include "readers/internal/io_internal.h"

namespace terrain {
namespace {

enum class Kind { Hgt, Esri, Image, Raw };

Kind detect_kind(const std::string& path, const ReadOptions& options) {
  using io::ends_with_ci;
  if (ends_with_ci(path, ".hgt") || ends_with_ci(path, ".hgt.gz")) return Kind::Hgt;
  if (ends_with_ci(path, ".bil") || ends_with_ci(path, ".flt")) return Kind::Esri;
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
           "unknown format: expected .hgt[.gz], .bil/.flt, .png/.tif/.exr, or a raw grid with a .json "
           "sidecar or --type/--width/--height");
}

}  // namespace

GridInfo probe(const std::string& path, const ReadOptions& options) {
  switch (detect_kind(path, options)) {
    case Kind::Hgt:
      return io::probe_hgt_layout(path, options).info;
    case Kind::Esri:
      return io::probe_esri_layout(path, options).info;
    case Kind::Image:
      return io::probe_image(path, options);
    case Kind::Raw:
      return io::probe_raw_layout(path, options).info;
  }
  return {};
}

std::unique_ptr<BandReader> open_band_reader(const std::string& path, const ReadOptions& options) {
  switch (detect_kind(path, options)) {
    case Kind::Hgt:
      return io::open_raw_stream(path, io::probe_hgt_layout(path, options));
    case Kind::Esri:
      return io::open_raw_stream(path, io::probe_esri_layout(path, options));
    case Kind::Image:
      return io::open_image_reader(path, options);
    case Kind::Raw:
      return io::open_raw_stream(path, io::probe_raw_layout(path, options));
  }
  return nullptr;
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
