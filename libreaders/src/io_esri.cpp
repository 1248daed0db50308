// ESRI BIL / FLT grids: a whitespace-separated "KEY value" .hdr beside a fixed-layout sample file.
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "readers/internal/io_internal.h"

namespace terrain::io {
namespace {

std::string header_path_for(const std::string& path) {
  auto dot = path.find_last_of('.');
  auto slash = path.find_last_of('/');
  std::string base =
      (dot != std::string::npos && (slash == std::string::npos || dot > slash)) ? path.substr(0, dot) : path;
  for (const char* ext : {".hdr", ".HDR"})
    if (file_exists(base + ext)) return base + ext;
  return base + ".hdr";
}

using Header = std::map<std::string, std::string>;  // upper-case keyword -> value text

// `where` names the grid and its header in error messages.
Header read_header(const std::string& hdr, const std::string& where) {
  if (!file_exists(hdr))
    fail(ErrorCode::MissingField, where, "missing header file " + hdr + " for the ESRI grid");
  std::istringstream in(read_small_text_file(hdr, kSideFileLimit));
  Header out;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    if (++line_no > 10000) fail(ErrorCode::MissingField, where, "header has too many lines");
    std::istringstream ls(line);
    std::string key, value;
    if (!(ls >> key)) continue;
    std::string upper;
    for (char c : key) upper += char(c >= 'a' && c <= 'z' ? c - 32 : c);
    ls >> value;
    out[upper] = value;
  }
  return out;
}

std::optional<double> header_number(const Header& h, const std::string& key, const std::string& where) {
  auto it = h.find(key);
  if (it == h.end()) return std::nullopt;
  const std::string& t = it->second;
  double v = 0;
  const char* begin = t.data();
  if (!t.empty() && t[0] == '+') ++begin;
  auto res = std::from_chars(begin, t.data() + t.size(), v);
  if (res.ec != std::errc() || res.ptr != t.data() + t.size()) {
    if (to_lower(t) == "nan") return std::nan("");
    fail(ErrorCode::MissingField, where, key + " is not a number: \"" + t + "\"");
  }
  return v;
}

int64_t header_dimension(const Header& h, const std::string& key, const std::string& where) {
  auto v = header_number(h, key, where);
  if (!v) fail(ErrorCode::MissingField, where, "missing " + key);
  if (!(*v >= 1 && *v <= 2147483648.0) || *v != std::floor(*v))
    fail(ErrorCode::MissingField, where, key + " must be a positive integer");
  return int64_t(*v);
}

}  // namespace

void apply_prj(const std::string& prj, GridInfo& g) {
  // A .prj with a geographic and no projected system means degrees; spacing is kept in arc-seconds.
  // Its text is the CRS (kept as is, trailing white space trimmed; checked by is_crs_text).
  if (!file_exists(prj)) return;
  std::string text = read_small_text_file(prj, kSideFileLimit);
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back()))) text.pop_back();
  g.crs_text = text;
  g.crs_epsg = epsg_from_wkt(text);
  if (text.find("GEOGCS") != std::string::npos && text.find("PROJCS") == std::string::npos) {
    g.horizontal_units = "arc-second";
    g.spacing_x *= 3600.0;
    g.spacing_y *= 3600.0;
  }
}

RawLayout probe_esri_layout(const std::string& path, const ReadOptions& options) {
  uint64_t size = existing_file_size(path);
  const bool is_flt = ends_with_ci(path, ".flt");
  const std::string hdr = header_path_for(path);
  const std::string where = path + " (header " + hdr + ")";
  Header h = read_header(hdr, where);

  RawLayout layout;
  GridInfo& g = layout.info;
  g.format = is_flt ? FileFormat::EsriFlt : FileFormat::EsriBil;
  g.height = header_dimension(h, "NROWS", where);
  g.width = header_dimension(h, "NCOLS", where);
  if (auto nb = header_number(h, "NBANDS", where); nb && *nb != 1)
    fail(ErrorCode::UnknownType, where,
         "only single-band grids are supported (NBANDS " + format_double(*nb) + ")");

  int nbits = is_flt ? 32 : 8;  // the BIL default is 8-bit unsigned
  if (auto nb = header_number(h, "NBITS", where)) {
    if (!(*nb == 8 || *nb == 16 || *nb == 32))
      fail(ErrorCode::UnknownType, where, "unsupported NBITS " + format_double(*nb));
    nbits = int(*nb);
  }
  std::string pixel = h.count("PIXELTYPE") ? to_lower(h["PIXELTYPE"]) : (is_flt ? "float" : "");
  if (pixel.empty()) pixel = nbits == 8 ? "unsignedint" : "signedint";
  if (pixel == "float" || pixel == "floatingpoint") {
    if (nbits != 32) fail(ErrorCode::UnknownType, where, "float grids must have NBITS 32");
    layout.stored = StoredType::Float32;
    g.sample_type = SampleType::Float32;
  } else if (pixel == "signedint" || pixel == "unsignedint") {
    bool is_signed = pixel == "signedint";
    if (nbits == 8 && !is_signed) {
      layout.stored = StoredType::UInt8;
      g.sample_type = SampleType::UInt16;  // widened: there is no 8-bit sample type
    } else if (nbits == 16) {
      layout.stored = is_signed ? StoredType::Int16 : StoredType::UInt16;
      g.sample_type = is_signed ? SampleType::Int16 : SampleType::UInt16;
    } else if (nbits == 32 && is_signed) {
      layout.stored = StoredType::Int32;
      g.sample_type = SampleType::Int32;
    } else {
      fail(ErrorCode::UnknownType, where,
           "unsupported NBITS " + std::to_string(nbits) + " for PIXELTYPE " + h["PIXELTYPE"]);
    }
  } else {
    fail(ErrorCode::UnknownType, where, "unknown PIXELTYPE \"" + h["PIXELTYPE"] + "\"");
  }

  if (h.count("BYTEORDER")) {
    std::string bo = to_lower(h["BYTEORDER"]);
    if (bo == "i" || bo == "lsbfirst")
      layout.big_endian = false;
    else if (bo == "m" || bo == "msbfirst")
      layout.big_endian = true;
    else
      fail(ErrorCode::UnknownType, where, "unknown BYTEORDER \"" + h["BYTEORDER"] + "\"");
  }
  if (auto layout_kw = h.find("LAYOUT"); layout_kw != h.end()) {
    std::string l = to_lower(layout_kw->second);
    if (l != "bil" && l != "bip" && l != "bsq")
      fail(ErrorCode::UnknownType, where, "unknown LAYOUT \"" + layout_kw->second + "\"");
  }
  if (auto skip = header_number(h, "SKIPBYTES", where)) {
    if (!(*skip >= 0 && *skip <= 4.0e18) || *skip != std::floor(*skip))
      fail(ErrorCode::MissingField, where, "SKIPBYTES must be a non-negative integer");
    layout.data_offset = uint64_t(*skip);
  }
  if (auto v = header_number(h, "NODATA", where)) g.nodata = *v;
  if (auto v = header_number(h, "NODATA_VALUE", where)) g.nodata = *v;

  auto cell = header_number(h, "CELLSIZE", where);
  auto xdim = header_number(h, "XDIM", where);
  auto ydim = header_number(h, "YDIM", where);
  g.spacing_x = xdim ? *xdim : cell.value_or(1.0);
  g.spacing_y = ydim ? *ydim : cell.value_or(1.0);
  if (auto ulx = header_number(h, "ULXMAP", where)) g.origin_x = *ulx;  // centre of the upper-left cell
  if (auto uly = header_number(h, "ULYMAP", where)) g.origin_y = *uly;
  if (auto xll = header_number(h, "XLLCORNER", where)) g.origin_x = *xll + 0.5 * g.spacing_x;
  if (auto yll = header_number(h, "YLLCORNER", where))
    g.origin_y = *yll + (double(g.height) - 0.5) * g.spacing_y;
  if (auto xc = header_number(h, "XLLCENTER", where)) g.origin_x = *xc;
  if (auto yc = header_number(h, "YLLCENTER", where)) g.origin_y = *yc + double(g.height - 1) * g.spacing_y;

  apply_prj(hdr.substr(0, hdr.size() - 4) + ".prj", g);

  apply_common_overrides(g, options);
  uint64_t need = layout_bytes(path, layout) + layout.data_offset;
  if (size != need)
    fail(ErrorCode::DimensionMismatch, path,
         "header " + hdr + " describes " + std::to_string(g.width) + "x" + std::to_string(g.height) + " " +
             std::to_string(nbits) + "-bit samples (" + std::to_string(need) + " bytes) but the file has " +
             std::to_string(size) + " bytes (" + (size < need ? "too short" : "too long") + ")");
  return layout;
}

}  // namespace terrain::io
