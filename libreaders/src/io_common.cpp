// Plumbing shared by the readers and writers: names, error messages, file sizes, atomic writes.
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <system_error>

#include "core/file.h"
#include "core/text.h"
#include "readers/internal/io_internal.h"

namespace terrain {

const char* sample_type_name(SampleType t) {
  static constexpr const char* kNames[] = {"int16", "uint16", "int32", "float32", "terrain-rgb"};
  return enum_name(t, kNames);
}

std::optional<SampleType> sample_type_from_name(const std::string& name) {
  std::string n = io::to_lower(name);
  if (n == "int16" || n == "i16" || n == "short") return SampleType::Int16;
  if (n == "uint16" || n == "u16") return SampleType::UInt16;
  if (n == "int32" || n == "i32") return SampleType::Int32;
  if (n == "float32" || n == "f32" || n == "float") return SampleType::Float32;
  return std::nullopt;
}

const char* file_format_name(FileFormat f) {
  static constexpr const char* kNames[] = {"srtm-hgt",          "raw",       "esri-bil", "esri-flt", "image",
                                           "terrain-rgb-image", "esri-ascii"};
  return enum_name(f, kNames);
}

std::optional<std::array<double, 6>> geotransform(const GridInfo& info) {
  if (!info.origin_x || !info.origin_y) return std::nullopt;
  const double per_unit = info.horizontal_units == "arc-second" ? 1.0 / 3600.0 : 1.0;
  const double dx = info.spacing_x * per_unit, dy = info.spacing_y * per_unit;
  return std::array<double, 6>{*info.origin_x - 0.5 * dx, dx, 0.0, *info.origin_y + 0.5 * dy, 0.0, -dy};
}

namespace io {

std::optional<int> epsg_from_wkt(const std::string& wkt) {
  // The outermost object's identifier is the last one, followed only by closing brackets.
  for (const char* tag : {"AUTHORITY[\"EPSG\",", "ID[\"EPSG\","}) {
    const size_t at = wkt.rfind(tag);
    if (at == std::string::npos) continue;
    size_t i = at + std::strlen(tag);
    if (i < wkt.size() && wkt[i] == '"') ++i;
    int code = 0;
    const auto res = std::from_chars(wkt.data() + i, wkt.data() + wkt.size(), code);
    if (res.ec != std::errc() || code <= 0) continue;
    size_t j = size_t(res.ptr - wkt.data());
    if (j < wkt.size() && wkt[j] == '"') ++j;
    if (j >= wkt.size() || wkt[j] != ']') continue;
    bool outermost = true;
    for (size_t k = j + 1; k < wkt.size(); ++k)
      if (wkt[k] != ']' && !std::isspace(static_cast<unsigned char>(wkt[k]))) outermost = false;
    if (outermost) return code;
  }
  // ESRI WKT (what GDAL writes to .prj files) names instead of identifying: the common names.
  const bool projected = wkt.find("PROJCS[") != std::string::npos;
  if (!projected && wkt.rfind("GEOGCS[\"GCS_WGS_1984\"", 0) == 0) return 4326;
  const std::string utm = "PROJCS[\"WGS_1984_UTM_Zone_";
  if (wkt.rfind(utm, 0) == 0) {
    int zone = 0;
    const char* p = wkt.data() + utm.size();
    const auto res = std::from_chars(p, wkt.data() + wkt.size(), zone);
    if (res.ec == std::errc() && zone >= 1 && zone <= 60 && res.ptr + 1 < wkt.data() + wkt.size() &&
        res.ptr[1] == '"' && (res.ptr[0] == 'N' || res.ptr[0] == 'S'))
      return (res.ptr[0] == 'N' ? 32600 : 32700) + zone;
  }
  return std::nullopt;
}

void fail(ErrorCode code, const std::string& path, const std::string& problem) {
  throw Error(code, path + ": " + problem);
}

std::string to_lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return char(c >= 'A' && c <= 'Z' ? c + 32 : c); });
  return s;
}

bool ends_with_ci(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && to_lower(s.substr(s.size() - suffix.size())) == to_lower(suffix);
}

bool file_exists(const std::string& path) {
  std::error_code ec;
  return std::filesystem::is_regular_file(path, ec);
}

uint64_t existing_file_size(const std::string& path) {
  std::error_code ec;
  auto status = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(status)) fail(ErrorCode::NotFound, path, "no such file");
  if (!std::filesystem::is_regular_file(status)) fail(ErrorCode::NotFound, path, "not a regular file");
  auto size = std::filesystem::file_size(path, ec);
  if (ec) fail(ErrorCode::NotFound, path, "cannot read size: " + ec.message());
  return size;
}

int stored_bytes(StoredType t) {
  switch (t) {
    case StoredType::UInt8:
      return 1;
    case StoredType::Int16:
    case StoredType::UInt16:
      return 2;
    case StoredType::Int32:
    case StoredType::Float32:
      return 4;
  }
  return 1;
}

StoredType stored_type_for(SampleType t) {
  switch (t) {
    case SampleType::Int16:
      return StoredType::Int16;
    case SampleType::UInt16:
      return StoredType::UInt16;
    case SampleType::Int32:
    case SampleType::TerrainRGB:
      return StoredType::Int32;
    case SampleType::Float32:
      return StoredType::Float32;
  }
  return StoredType::Int16;
}

uint64_t layout_bytes(const std::string& path, const RawLayout& layout) {
  const auto& g = layout.info;
  // 2^31 per side keeps width*height*bytes far below 2^64 and every row index within int64.
  constexpr int64_t kMaxSide = int64_t(1) << 31;
  if (g.width <= 0 || g.height <= 0 || g.width > kMaxSide || g.height > kMaxSide)
    fail(ErrorCode::DimensionMismatch, path,
         "invalid dimensions " + std::to_string(g.width) + "x" + std::to_string(g.height));
  check_row_width(path, g.width);
  const unsigned __int128 bytes = (unsigned __int128)g.width * (unsigned __int128)g.height *
                                  (unsigned __int128)stored_bytes(layout.stored);
  if (bytes > (unsigned __int128)(uint64_t(1) << 56))  // 64 PiB: beyond any grid, and no 64-bit wrap
    fail(ErrorCode::DimensionMismatch, path,
         "dimensions " + std::to_string(g.width) + "x" + std::to_string(g.height) +
             " need more than 2^56 bytes");
  return uint64_t(bytes);
}

void check_row_width(const std::string& path, int64_t width) {
  if (width > kMaxRowSamples)
    fail(ErrorCode::DimensionMismatch, path,
         "rows of " + std::to_string(width) + " samples are wider than the limit of " +
             std::to_string(kMaxRowSamples) + " (2^20; docs/io.md, \"Limits\")");
}

void apply_common_overrides(GridInfo& info, const ReadOptions& o) {
  if (o.spacing_x) info.spacing_x = *o.spacing_x;
  if (o.spacing_y) info.spacing_y = *o.spacing_y;
  if (o.vertical_scale) info.vertical_scale = *o.vertical_scale;
  if (o.vertical_offset) info.vertical_offset = *o.vertical_offset;
  if (o.nodata) info.nodata = *o.nodata;
}

std::string format_double(double v) {
  if (std::isnan(v)) return "NaN";
  if (std::isinf(v)) return v > 0 ? "Infinity" : "-Infinity";
  char buf[64];
  auto res = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, res.ptr);
}

std::string read_small_text_file(const std::string& path, size_t limit) {
  if (existing_file_size(path) > limit)  // also refuses FIFOs and devices before opening them
    fail(ErrorCode::MissingField, path, "side file larger than " + std::to_string(limit) + " bytes");
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(ErrorCode::NotFound, path, "cannot open");
  std::string text;
  text.resize(limit + 1);
  in.read(text.data(), std::streamsize(limit + 1));
  text.resize(size_t(in.gcount()));
  if (text.size() > limit)
    fail(ErrorCode::MissingField, path, "side file larger than " + std::to_string(limit) + " bytes");
  return text;
}

AtomicOutput::AtomicOutput(std::string target) : target_(std::move(target)) {
  check_output_path(target_);
  // Keep the extension last so that OpenImageIO chooses the writer from the temporary name too.
  const std::string ext = std::filesystem::path(target_).extension().string();
  ::close(create_temp_beside(target_, ext, &temp_));  // created exclusively; writers reopen it by name
}

AtomicOutput::~AtomicOutput() {
  if (!committed_) {
    std::error_code ec;
    std::filesystem::remove(temp_, ec);
  }
}

void AtomicOutput::commit() {
  check_output_path(target_);
  std::error_code ec;
  std::filesystem::rename(temp_, target_, ec);
  if (ec) fail(ErrorCode::WriteFailed, target_, "cannot rename " + temp_ + " into place: " + ec.message());
  committed_ = true;
}

double value_for_writing(const Heightmap& map, int64_t x, int64_t y, const std::string& path) {
  if (map.is_valid(x, y)) return map.at(x, y);
  if (!map.info.nodata)
    fail(ErrorCode::WriteFailed, path,
         "sample at row " + std::to_string(y) + ", column " + std::to_string(x) +
             " is void but the grid has no nodata value to write for it");
  return *map.info.nodata;
}

}  // namespace io
}  // namespace terrain
