// Brush and channel edits added to a base source's heights, evaluated per level at the samples'
// finest-level positions.
#include "runtime/edit_overlay.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace terrain::runtime {

double edit_profile(EditShape shape, double r) {
  switch (shape) {
    case EditShape::Cone:
      return 1 - r;
    case EditShape::Flat:
      return 1;
    case EditShape::Smooth:
      break;
  }
  return (1 - r * r) * (1 - r * r);
}

namespace {

// Distance from (x, y) to the segment a - b.
double segment_distance(double x, double y, const TerrainEdit& e) {
  const double dx = e.x1 - e.x0, dy = e.y1 - e.y0, len2 = dx * dx + dy * dy;
  const double t = len2 > 0 ? std::clamp(((x - e.x0) * dx + (y - e.y0) * dy) / len2, 0.0, 1.0) : 0.0;
  return std::hypot(x - (e.x0 + t * dx), y - (e.y0 + t * dy));
}

}  // namespace

Rect edit_bounds(const TerrainEdit& e) {
  const int64_t x0 = int64_t(std::floor(std::min(e.x0, e.x1) - e.radius)),
                x1 = int64_t(std::ceil(std::max(e.x0, e.x1) + e.radius));
  const int64_t y0 = int64_t(std::floor(std::min(e.y0, e.y1) - e.radius)),
                y1 = int64_t(std::ceil(std::max(e.y0, e.y1) + e.radius));
  return Rect{x0, y0, x1 - x0 + 1, y1 - y0 + 1};
}

double edit_delta(const TerrainEdit& e, double x, double y) {
  const double r = segment_distance(x, y, e) / e.radius;
  return r < 1 ? e.height * edit_profile(e.shape, r) : 0.0;
}

const char* edit_shape_name(EditShape shape) {
  switch (shape) {
    case EditShape::Cone:
      return "cone";
    case EditShape::Flat:
      return "flat";
    case EditShape::Smooth:
      break;
  }
  return "smooth";
}

bool parse_edit_shape(const std::string& name, EditShape* out) {
  if (name == "cone") return *out = EditShape::Cone, true;
  if (name == "smooth") return *out = EditShape::Smooth, true;
  if (name == "flat") return *out = EditShape::Flat, true;
  return false;
}

Rect EditOverlaySource::add(const TerrainEdit& e) {
  if (!std::isfinite(e.x0 + e.y0 + e.x1 + e.y1 + e.radius + e.height))
    throw std::invalid_argument("terrain edit: every field must be a finite number");
  if (!(e.radius > 0) || e.radius > 1e9)
    throw std::invalid_argument("terrain edit: radius must be in (0, 1e9] samples");
  edits_.push_back(e);
  return edit_bounds(e);
}

void EditOverlaySource::fill(int level, const Rect& rect, float* out, int64_t out_stride) {
  base_.fill(level, rect, out, out_stride);
  add_edits(level, rect, out, out_stride);
}

void EditOverlaySource::fill_units(int level, const Rect& rect, const HeldUnits* coarser, float* out,
                                   int32_t* units_out, int64_t out_stride, FillSplit* split) {
  base_.fill_units(level, rect, coarser, out, units_out, out_stride, split);
  add_edits(level, rect, out, out_stride);
}

void EditOverlaySource::add_edits(int level, const Rect& rect, float* out, int64_t out_stride) const {
  if (rect.width <= 0 || rect.height <= 0 || edits_.empty()) return;
  const GridSize size = level_size(level);
  const double k = std::ldexp(1.0, level_count() - 1 - level);  // finest samples per sample of `level`
  for (const TerrainEdit& e : edits_) {
    // The level's samples the edit reaches, within rect (coordinates beyond the level repeat the
    // edge sample, as the base's do).
    const double r = e.radius;
    const int64_t ex0 = int64_t(std::floor((std::min(e.x0, e.x1) - r) / k)),
                  ex1 = int64_t(std::ceil((std::max(e.x0, e.x1) + r) / k));
    const int64_t ey0 = int64_t(std::floor((std::min(e.y0, e.y1) - r) / k)),
                  ey1 = int64_t(std::ceil((std::max(e.y0, e.y1) + r) / k));
    for (int64_t y = 0; y < rect.height; ++y) {
      const int64_t sy = std::clamp<int64_t>(rect.y0 + y, 0, size.height - 1);
      if (sy < ey0 || sy > ey1) continue;
      float* o = out + y * out_stride;
      for (int64_t x = 0; x < rect.width; ++x) {
        const int64_t sx = std::clamp<int64_t>(rect.x0 + x, 0, size.width - 1);
        if (sx < ex0 || sx > ex1) continue;
        o[x] += float(edit_delta(e, double(sx) * k, double(sy) * k));
      }
    }
  }
}

}  // namespace terrain::runtime
