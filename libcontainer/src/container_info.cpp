// Error-mode names and the consistency rules of a pyramid description, shared by writer and reader.
#include <cmath>
#include <stdexcept>
#include <string>

#include "container/container.h"
#include "core/text.h"

namespace terrain::container {

const char* error_mode_name(ErrorMode mode) {
  switch (mode) {
    case ErrorMode::Rms:
      return "rms";
    case ErrorMode::MaxError:
      return "max-error";
    case ErrorMode::Step:
      return "step";
    case ErrorMode::Lossless:
      return "lossless";
  }
  return "unknown";
}

const char* filter_provenance_name(FilterProvenance provenance) {
  switch (provenance) {
    case FilterProvenance::Optimal:
      return "optimal";
    case FilterProvenance::Fallback:
      return "fallback";
    case FilterProvenance::Wavelet:
      return "wavelet";
    case FilterProvenance::Point:
      return "point";
  }
  return "unknown";
}

std::optional<LevelError> level_error_metres(const ContainerInfo& info, size_t level) {
  const std::optional<LevelError>& e = info.levels.at(level).error;
  if (!e) return std::nullopt;
  const double metres_per_unit = std::abs(info.vertical_scale);
  return LevelError{e->rms * metres_per_unit, e->max_abs * metres_per_unit};
}

namespace {
// Units are shown to people and written into JSON: well-formed UTF-8 without control characters.
bool printable_utf8(const std::string& s) {
  for (size_t i = 0; i < s.size();) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    if (c < 0x20 || c == 0x7F) return false;
    const int extra = c < 0x80                          ? 0
                      : (c & 0xE0) == 0xC0 && c >= 0xC2 ? 1
                      : (c & 0xF0) == 0xE0              ? 2
                      : (c & 0xF8) == 0xF0 && c <= 0xF4 ? 3
                                                        : -1;
    if (extra < 0) return false;
    for (int k = 1; k <= extra; ++k)
      if (i + size_t(k) >= s.size() || (static_cast<unsigned char>(s[i + size_t(k)]) & 0xC0) != 0x80)
        return false;
    i += size_t(extra) + 1;
  }
  return true;
}

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("invalid pyramid description: " + what);
}
}  // namespace

void validate_info(const ContainerInfo& info) {
  // 2^31 per side keeps width*height (and any per-sample index) far from 64-bit overflow.
  constexpr uint64_t kMaxSide = uint64_t(1) << 31;
  require(info.width >= 1 && info.height >= 1, "finest level must be at least 1x1");
  require(info.width <= kMaxSide && info.height <= kMaxSide, "finest level exceeds 2^31 samples per side");
  require(!info.levels.empty(), "no levels");
  require(info.levels.size() <= kMaxLevels, "more than " + std::to_string(kMaxLevels) + " levels");
  const LevelInfo& finest = info.levels.back();
  require(finest.width == info.width && finest.height == info.height,
          "finest level is " + std::to_string(finest.width) + "x" + std::to_string(finest.height) +
              ", grid is " + std::to_string(info.width) + "x" + std::to_string(info.height));
  for (size_t l = 0; l < info.levels.size(); ++l) {
    const std::optional<LevelError>& e = info.levels[l].error;
    require(!e || (std::isfinite(e->rms) && std::isfinite(e->max_abs) && e->rms >= 0 && e->max_abs >= 0),
            "level " + std::to_string(l) + " error figures must be finite and non-negative (rms " +
                (e ? std::to_string(e->rms) + ", max " + std::to_string(e->max_abs) : std::string()) + ")");
  }
  for (size_t l = info.levels.size() - 1; l > 0; --l) {
    const LevelInfo& fine = info.levels[l];
    const LevelInfo& coarse = info.levels[l - 1];
    require(coarse.width == (fine.width + 1) / 2 && coarse.height == (fine.height + 1) / 2,
            "level " + std::to_string(l - 1) + " is " + std::to_string(coarse.width) + "x" +
                std::to_string(coarse.height) + ", expected ceil-half of level " + std::to_string(l) + " (" +
                std::to_string(fine.width) + "x" + std::to_string(fine.height) + ")");
  }
  require(std::isfinite(info.spacing_x) && std::isfinite(info.spacing_y) && info.spacing_x > 0 &&
              info.spacing_y > 0,
          "spacing must be finite and positive");
  require(
      std::isfinite(info.vertical_scale) && std::isfinite(info.vertical_offset) && info.vertical_scale != 0,
      "vertical scale must be finite and non-zero, offset finite");
  require(info.horizontal_units.size() <= kMaxUnitsLength && info.vertical_units.size() <= kMaxUnitsLength,
          "units strings are limited to " + std::to_string(kMaxUnitsLength) + " bytes");
  require(printable_utf8(info.horizontal_units) && printable_utf8(info.vertical_units),
          "units strings must be printable UTF-8");
  if (info.georeference) {
    const Georeference& g = *info.georeference;
    const auto& gt = g.geotransform;
    for (size_t i = 0; i < 6; ++i)
      require(std::isfinite(gt[i]), "georeference geotransform[" + std::to_string(i) + "] must be finite");
    require(gt[1] != 0 && gt[5] != 0, "georeference pixel size (geotransform[1], [5]) must be non-zero");
    require(gt[2] == 0 && gt[4] == 0, "georeference rotation terms (geotransform[2], [4]) must be 0");
    require(std::isfinite(g.origin_x()) && std::isfinite(g.origin_y()), "georeference origin must be finite");
    require(is_crs_text(g.crs_text), "georeference crs_text must be at most " +
                                         std::to_string(kMaxCrsTextBytes) +
                                         " bytes without control characters");
    require(g.units.size() <= kMaxUnitsLength && printable_utf8(g.units),
            "georeference units must be at most " + std::to_string(kMaxUnitsLength) +
                " bytes of printable UTF-8");
  }
  require(info.filter_size <= kMaxFilterSize, "filter larger than " + std::to_string(kMaxFilterSize));
  require(info.filter.size() == size_t(info.filter_size) * info.filter_size,
          "filter has " + std::to_string(info.filter.size()) + " coefficients, size " +
              std::to_string(info.filter_size) + " needs its square");
  require(uint32_t(info.filter_provenance) <= uint32_t(FilterProvenance::Point), "unknown filter provenance");
  const Quantisation& q = info.quantisation;
  require(uint32_t(q.mode) <= uint32_t(ErrorMode::Lossless), "unknown error mode");
  require(std::isfinite(q.step_units) && std::isfinite(q.step_metres) && std::isfinite(q.target),
          "quantisation values must be finite");
  // libcodec's steps are at least 1 unit; a lossless file records target 0, the others a positive one.
  require(q.step_units >= 1 && q.step_metres > 0,
          "quantisation step must be at least 1 unit and positive in metres");
  require(q.mode == ErrorMode::Lossless ? q.target >= 0 : q.target > 0, "error target must be positive");
  for (size_t l = 0; l < info.levels.size(); ++l) {
    const ResidualStats& r = info.levels[l].stats;
    require(std::isfinite(r.mean) && std::isfinite(r.variance) && std::isfinite(r.rms) &&
                std::isfinite(r.min) && std::isfinite(r.max) && r.variance >= 0 && r.rms >= 0 &&
                r.min <= r.max,
            "level " + std::to_string(l) + " residual statistics must be finite and ordered");
  }
}

}  // namespace terrain::container
