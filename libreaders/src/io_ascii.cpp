// ESRI ASCII grids (.asc, GDAL's AAIGrid): "ncols / nrows / xllcorner|xllcenter / yllcorner|yllcenter /
// cellsize (or dx, dy) / NODATA_value" lines, then nrows x ncols whitespace-separated values, row 0
// north. Streamed through a fixed buffer; a .prj beside the grid gives its CRS (apply_prj).
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <vector>

#include "readers/internal/io_internal.h"

namespace terrain::io {
namespace {

// Whitespace-separated tokens of a file, read in 1 MiB pieces; tokens are limited to 255 bytes.
class Tokens {
 public:
  explicit Tokens(const std::string& path) : path_(path) {
    file_ = std::fopen(path.c_str(), "rb");
    if (!file_) fail(ErrorCode::NotFound, path, std::string("cannot open: ") + std::strerror(errno));
    buffer_.resize(size_t(1) << 20);
  }
  ~Tokens() { std::fclose(file_); }
  Tokens(const Tokens&) = delete;
  Tokens& operator=(const Tokens&) = delete;

  // The next token, or false at the end of the file.
  bool next(std::string& token) {
    token.clear();
    for (;;) {
      if (pos_ == end_ && !refill()) return !token.empty();
      const char c = buffer_[pos_];
      const bool space = c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v';
      if (space) {
        ++pos_;
        if (!token.empty()) return true;
        continue;
      }
      if (token.size() >= 255) fail(ErrorCode::CorruptData, path_, "a value of more than 255 characters");
      token += c;
      ++pos_;
    }
  }

 private:
  bool refill() {
    end_ = std::fread(buffer_.data(), 1, buffer_.size(), file_);
    pos_ = 0;
    if (end_ == 0 && std::ferror(file_)) fail(ErrorCode::NotFound, path_, "read error");
    return end_ > 0;
  }
  const std::string& path_;
  FILE* file_ = nullptr;
  std::vector<char> buffer_;
  size_t pos_ = 0, end_ = 0;
};

bool parse_number(const std::string& t, double& v) {
  const char* begin = t.data() + (!t.empty() && t[0] == '+' ? 1 : 0);
  const auto res = std::from_chars(begin, t.data() + t.size(), v);
  return res.ec == std::errc() && res.ptr == t.data() + t.size();
}

bool is_keyword(const std::string& t) {
  return !t.empty() && ((t[0] >= 'a' && t[0] <= 'z') || (t[0] >= 'A' && t[0] <= 'Z'));
}

struct AsciiHeader {
  GridInfo info;
  std::string first_value;  // the token after the header (the first sample), empty for an empty grid
};

// Reads the header keywords (any order, any case) and leaves `tokens` after the first value.
AsciiHeader read_header(const std::string& path, Tokens& tokens) {
  std::map<std::string, double> keys;
  std::string token, value;
  while (tokens.next(token) && is_keyword(token)) {
    const std::string key = to_lower(token);
    if (keys.size() > 16) fail(ErrorCode::MissingField, path, "too many header lines");
    if (!tokens.next(value)) fail(ErrorCode::MissingField, path, "header keyword " + token + " has no value");
    double v = 0;
    if (!parse_number(value, v) && !(to_lower(value) == "nan" && key == "nodata_value"))
      fail(ErrorCode::MissingField, path, token + " is not a number: \"" + value + "\"");
    keys[key] = to_lower(value) == "nan" ? std::nan("") : v;
    token.clear();
  }
  const auto get = [&](const char* key) -> std::optional<double> {
    auto it = keys.find(key);
    return it == keys.end() ? std::nullopt : std::optional<double>(it->second);
  };
  const auto dimension = [&](const char* key) {
    const auto v = get(key);
    if (!v) fail(ErrorCode::MissingField, path, std::string("missing ") + key);
    if (!(*v >= 1 && *v <= 2147483648.0) || *v != std::floor(*v))
      fail(ErrorCode::MissingField, path, std::string(key) + " must be a positive integer");
    return int64_t(*v);
  };
  AsciiHeader h;
  GridInfo& g = h.info;
  g.format = FileFormat::EsriAscii;
  g.width = dimension("ncols");
  g.height = dimension("nrows");
  const auto cell = get("cellsize");
  const auto dx = get("dx"), dy = get("dy");
  if (!cell && !(dx && dy)) fail(ErrorCode::MissingField, path, "missing cellsize (or dx and dy)");
  g.spacing_x = dx ? *dx : *cell;
  g.spacing_y = dy ? *dy : *cell;
  if (!(std::isfinite(g.spacing_x) && g.spacing_x > 0 && std::isfinite(g.spacing_y) && g.spacing_y > 0))
    fail(ErrorCode::MissingField, path, "cellsize must be finite and positive");
  const auto xc = get("xllcenter"), yc = get("yllcenter");
  const auto xl = get("xllcorner"), yl = get("yllcorner");
  if (xc) g.origin_x = *xc;
  if (xl) g.origin_x = *xl + 0.5 * g.spacing_x;
  if (yc) g.origin_y = *yc + double(g.height - 1) * g.spacing_y;
  if (yl) g.origin_y = *yl + (double(g.height) - 0.5) * g.spacing_y;
  if (!g.origin_x || !g.origin_y)
    fail(ErrorCode::MissingField, path, "missing xllcorner/xllcenter or yllcorner/yllcenter");
  if (auto nd = get("nodata_value")) g.nodata = *nd;
  h.first_value = token;
  return h;
}

// Whether the values hold a fraction or an exponent (then float32, else int32), as GDAL decides.
bool has_fraction(Tokens& tokens, std::string token) {
  do {
    if (token.find_first_of(".eE") != std::string::npos && to_lower(token) != "nan") return true;
  } while (tokens.next(token));
  return false;
}

GridInfo probe_info(const std::string& path, const ReadOptions& options) {
  existing_file_size(path);
  Tokens tokens(path);
  AsciiHeader h = read_header(path, tokens);
  GridInfo& g = h.info;
  const bool fraction = (g.nodata && *g.nodata != std::floor(*g.nodata)) ||
                        (!h.first_value.empty() && has_fraction(tokens, h.first_value));
  g.sample_type = fraction ? SampleType::Float32 : SampleType::Int32;
  std::string prj = path.substr(0, path.size() - 4) + ".prj";
  apply_prj(prj, g);
  apply_common_overrides(g, options);
  return g;
}

class AsciiGridReader final : public BandReader {
 public:
  AsciiGridReader(std::string path, const GridInfo& info)
      : path_(std::move(path)),
        info_(info),
        tokens_(path_),
        first_(read_header(path_, tokens_).first_value) {}
  const GridInfo& info() const override { return info_; }

  int64_t read_rows(int64_t rows, double* values, uint8_t* valid) override {
    const int64_t n = std::min(rows, info_.height - rows_read_);
    if (n <= 0) return 0;
    const bool is_float = info_.sample_type == SampleType::Float32;
    const bool has_nodata = info_.nodata.has_value();
    const double nodata = has_nodata ? *info_.nodata : 0.0;
    std::string token;
    for (int64_t i = 0; i < n * info_.width; ++i) {
      const int64_t row = rows_read_ + i / info_.width, col = i % info_.width;
      const auto where = [&] { return "row " + std::to_string(row) + ", column " + std::to_string(col); };
      if (!first_.empty()) {
        token.swap(first_);
        first_.clear();
      } else if (!tokens_.next(token)) {
        fail(ErrorCode::Truncated, path_, "values end at " + where());
      }
      double v = 0;
      const bool nan = to_lower(token) == "nan";
      if (!nan && !parse_number(token, v))
        fail(ErrorCode::CorruptData, path_, "\"" + token + "\" at " + where() + " is not a number");
      if (nan) v = std::nan("");
      const bool is_void = has_nodata && (v == nodata || (std::isnan(v) && std::isnan(nodata)) ||
                                          (is_float && float(v) == float(nodata)));
      if (is_void) {
        values[i] = 0;
        valid[i] = 0;
        continue;
      }
      if (!std::isfinite(v)) fail(ErrorCode::NonFinite, path_, token + " at " + where());
      if (is_float) {
        v = double(float(v));
      } else if (v != std::floor(v) || v < -2147483648.0 || v > 2147483647.0) {
        fail(ErrorCode::CorruptData, path_, token + " at " + where() + " is not an int32 value");
      }
      values[i] = v;
      valid[i] = 1;
    }
    rows_read_ += n;
    if (rows_read_ == info_.height && tokens_.next(token))
      fail(ErrorCode::Oversized, path_,
           "more values than ncols x nrows (\"" + token + "\" after the last row)");
    return n;
  }

 private:
  std::string path_;
  GridInfo info_;
  Tokens tokens_;
  std::string first_;
};

}  // namespace

GridInfo probe_ascii_grid(const std::string& path, const ReadOptions& options) {
  return probe_info(path, options);
}

std::unique_ptr<BandReader> open_ascii_grid(const std::string& path, const ReadOptions& options) {
  return std::make_unique<AsciiGridReader>(path, probe_info(path, options));
}

}  // namespace terrain::io
