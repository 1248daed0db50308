// Height sources of the geometry clipmap: the compressed pyramid (through the region decoder) and
// an analytic function. Both repeat the nearest edge sample outside a bounded level, so the clipmap
// never needs to special-case the terrain's border.
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "runtime/clipmap.h"
#include "runtime/region_decoder.h"

namespace terrain::runtime {

namespace {

int64_t clamp64(int64_t v, int64_t lo, int64_t hi) { return std::min(std::max(v, lo), hi); }

std::vector<GridSize> sizes_from_finest(GridSize finest, int levels) {
  std::vector<GridSize> sizes(size_t(std::max(levels, 0)));
  GridSize s = finest;
  for (int l = levels - 1; l >= 0; --l) {
    sizes[size_t(l)] = s;
    s = GridSize{coarse_extent(s.width), coarse_extent(s.height)};
  }
  return sizes;
}

}  // namespace

RegionDecoderSource::RegionDecoderSource(std::shared_ptr<const RegionDecoder> decoder, double spacing_m)
    : decoder_(std::move(decoder)), spacing_m_(spacing_m) {
  if (!decoder_) throw std::invalid_argument("RegionDecoderSource: no decoder");
  if (!(spacing_m_ > 0) || !std::isfinite(spacing_m_))
    throw std::invalid_argument("RegionDecoderSource: spacing must be a positive number of metres (" +
                                decoder_->file().path() + ")");
}

int RegionDecoderSource::level_count() const { return decoder_->file().level_count(); }

GridSize RegionDecoderSource::level_size(int level) const { return decoder_->file().level_size(level); }

void RegionDecoderSource::fill(int level, const Rect& rect, float* out, int64_t out_stride) {
  if (rect.width <= 0 || rect.height <= 0) return;
  const GridSize size = level_size(level);
  // Decode the part of the level nearest to rect (at least one sample), then replicate its edges.
  const int64_t cx0 = clamp64(rect.x0, 0, size.width - 1), cx1 = clamp64(rect.x0 + rect.width - 1, 0, size.width - 1);
  const int64_t cy0 = clamp64(rect.y0, 0, size.height - 1), cy1 = clamp64(rect.y0 + rect.height - 1, 0, size.height - 1);
  const int64_t w = cx1 - cx0 + 1, h = cy1 - cy0 + 1;
  scratch_.resize(size_t(w * h));
  const bool voids = level == level_count() - 1 && decoder_->file().info().void_count > 0;
  if (voids) {
    decoder_->decode_metres(level, Rect{cx0, cy0, w, h}, scratch_.data(), w);
  } else {
    // Units into a reused buffer, converted here: no per-call allocation (decode_metres makes one).
    units_.resize(size_t(w * h));
    decoder_->decode_units(level, Rect{cx0, cy0, w, h}, units_.data(), w);
    const double scale = decoder_->metres_per_unit(), offset = decoder_->metres_offset();
    for (size_t i = 0; i < units_.size(); ++i) scratch_[i] = float(units_[i] * scale + offset);
  }
  for (int64_t y = 0; y < rect.height; ++y) {
    const float* src = scratch_.data() + (clamp64(rect.y0 + y, cy0, cy1) - cy0) * w;
    float* o = out + y * out_stride;
    const int64_t inside0 = std::clamp<int64_t>(cx0 - rect.x0, 0, rect.width);
    const int64_t inside1 = std::clamp<int64_t>(cx1 + 1 - rect.x0, 0, rect.width);
    for (int64_t x = 0; x < inside0; ++x) o[x] = src[0];
    for (int64_t x = inside0; x < inside1; ++x) o[x] = src[rect.x0 + x - cx0];
    for (int64_t x = inside1; x < rect.width; ++x) o[x] = src[w - 1];
    if (voids)
      for (int64_t x = 0; x < rect.width; ++x)
        if (std::isnan(o[x])) o[x] = 0.0f;
  }
}

FunctionHeightSource::FunctionHeightSource(int levels, GridSize finest, double spacing_m, Function f, bool unbounded)
    : levels_(levels), finest_(finest), spacing_m_(spacing_m), f_(std::move(f)), unbounded_(unbounded) {
  if (levels < 1 || levels > 30) throw std::invalid_argument("FunctionHeightSource: level count must be 1..30");
  if (finest.width < 1 || finest.height < 1) throw std::invalid_argument("FunctionHeightSource: empty finest level");
  if (!f_) throw std::invalid_argument("FunctionHeightSource: no function");
}

GridSize FunctionHeightSource::level_size(int level) const {
  return sizes_from_finest(finest_, levels_).at(size_t(level));
}

void FunctionHeightSource::fill(int level, const Rect& rect, float* out, int64_t out_stride) {
  const GridSize size = level_size(level);
  for (int64_t y = 0; y < rect.height; ++y) {
    const int64_t sy = unbounded_ ? rect.y0 + y : clamp64(rect.y0 + y, 0, size.height - 1);
    for (int64_t x = 0; x < rect.width; ++x) {
      const int64_t sx = unbounded_ ? rect.x0 + x : clamp64(rect.x0 + x, 0, size.width - 1);
      out[y * out_stride + x] = f_(level, sx, sy);
    }
  }
  samples_ += std::max<int64_t>(rect.width, 0) * std::max<int64_t>(rect.height, 0);
}

}  // namespace terrain::runtime
