// Height sources of the geometry clipmap: the compressed pyramid (through the region decoder), an
// analytic function, and the original input's levels T_l in memory (the reference flight's source). Both
// repeat the nearest edge sample outside a bounded level, so the clipmap never needs to special-case the
// terrain's border.
#include "runtime/height_source.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "core/clones.h"
#include "pyramid/level_units.h"
#include "pyramid/reference.h"
#include "readers/heightmap.h"
#include "runtime/internal/toroidal_rows.h"
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

// Level units to metres, in double as the decoder's decode_metres does. Compiled for AVX2 and for
// the baseline (picked at load time); no FMA, so both round identically.
TERRAIN_TARGET_CLONES("avx2", "default")
void units_to_metres(const int32_t* units, int64_t count, double scale, double offset, float* out) {
  for (int64_t i = 0; i < count; ++i) out[i] = float(units[i] * scale + offset);
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

void HeightSource::fill_units(int, const Rect&, const HeldUnits*, float*, int32_t*, int64_t, FillSplit*) {
  throw std::logic_error(
      "HeightSource::fill_units: this source has no integer units (refines_units() is false)");
}

void RegionDecoderSource::fill(int level, const Rect& rect, float* out, int64_t out_stride) {
  fill_units(level, rect, nullptr, out, nullptr, out_stride, nullptr);
}

void RegionDecoderSource::fill_units(int level, const Rect& rect, const HeldUnits* coarser, float* out,
                                     int32_t* units_out, int64_t out_stride, FillSplit* split) {
  if (rect.width <= 0 || rect.height <= 0) return;
  const GridSize size = level_size(level);
  // Decode the part of the level nearest to rect (at least one sample), then replicate its edges.
  const int64_t cx0 = clamp64(rect.x0, 0, size.width - 1),
                cx1 = clamp64(rect.x0 + rect.width - 1, 0, size.width - 1);
  const int64_t cy0 = clamp64(rect.y0, 0, size.height - 1),
                cy1 = clamp64(rect.y0 + rect.height - 1, 0, size.height - 1);
  const int64_t w = cx1 - cx0 + 1, h = cy1 - cy0 + 1;
  const Rect inside{cx0, cy0, w, h};
  units_.resize(size_t(w * h));
  bool refined = false;
  if (coarser && level > 0) {
    // The caller's coarser level, when it holds U's whole window: no recursion, only the residual.
    const Rect need = upsample_required_window(inside, size);
    const Rect& held = coarser->region;
    if (need.x0 >= held.x0 && need.y0 >= held.y0 && need.x0 + need.width <= held.x0 + held.width &&
        need.y0 + need.height <= held.y0 + held.height) {
      window_.resize(size_t(need.width * need.height));
      const int64_t n = coarser->n;
      const RowRuns runs(n, need.x0, need.width);
      for (int64_t y = 0; y < need.height; ++y)
        runs.gather(coarser->data + ((need.y0 + y) % n + n) % n * n, window_.data() + y * need.width);
      decoder_->decode_refined(
          level, inside, CoarseWindow{window_.data(), need.width, need, level_size(level - 1)}, units_.data(),
          w, split ? &split->upsample : nullptr, split ? &split->residual : nullptr);
      refined = true;
    }
  }
  if (!refined) decoder_->decode_units(level, inside, units_.data(), w);
  // Voids (NaN metres in the decoder's output) become 0 m.
  const bool voids = level == level_count() - 1 && decoder_->file().info().void_count > 0;
  if (voids) {
    valid_.resize(size_t(h * size.width));
    decoder_->file().container().mask_rows(uint64_t(cy0), uint64_t(h), valid_.data());
  }
  const double scale = decoder_->metres_per_unit(), offset = decoder_->metres_offset();
  // Rect columns inside0 .. inside1 - 1 lie in the level, at decoded column x + shift.
  const int64_t inside0 = std::clamp<int64_t>(cx0 - rect.x0, 0, rect.width);
  const int64_t inside1 = std::clamp<int64_t>(cx1 + 1 - rect.x0, 0, rect.width);
  const int64_t shift = rect.x0 - cx0;
  for (int64_t y = 0; y < rect.height; ++y) {
    const int64_t sy = clamp64(rect.y0 + y, cy0, cy1) - cy0;
    const int32_t* row = units_.data() + sy * w;
    const uint8_t* ok = voids ? valid_.data() + sy * size.width + cx0 : nullptr;  // ok[i]: decoded column i
    auto metres = [&](int64_t i) { return ok && !ok[i] ? 0.0f : float(row[i] * scale + offset); };
    float* o = out + y * out_stride;
    if (inside1 > inside0)
      units_to_metres(row + inside0 + shift, inside1 - inside0, scale, offset, o + inside0);
    if (ok)
      for (int64_t x = inside0; x < inside1; ++x)
        if (!ok[x + shift]) o[x] = 0.0f;
    std::fill(o, o + inside0, metres(0));
    std::fill(o + inside1, o + rect.width, metres(w - 1));
    if (units_out) {
      int32_t* u = units_out + y * out_stride;
      std::fill(u, u + inside0, row[0]);
      if (inside1 > inside0) std::copy(row + inside0 + shift, row + inside1 + shift, u + inside0);
      std::fill(u + inside1, u + rect.width, row[w - 1]);
    }
  }
}

FunctionHeightSource::FunctionHeightSource(int levels, GridSize finest, double spacing_m, Function f,
                                           bool unbounded)
    : levels_(levels), finest_(finest), spacing_m_(spacing_m), f_(std::move(f)), unbounded_(unbounded) {
  if (levels < 1 || levels > 30)
    throw std::invalid_argument("FunctionHeightSource: level count must be 1..30");
  if (finest.width < 1 || finest.height < 1)
    throw std::invalid_argument("FunctionHeightSource: empty finest level");
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

GridHeightSource::GridHeightSource(std::vector<GridSize> sizes, std::vector<std::vector<float>> levels,
                                   double spacing_m)
    : sizes_(std::move(sizes)), levels_(std::move(levels)), spacing_m_(spacing_m) {
  if (sizes_.empty() || sizes_.size() != levels_.size())
    throw std::invalid_argument("GridHeightSource: one grid per level needed");
  for (size_t l = 0; l < sizes_.size(); ++l)
    if (sizes_[l].width < 1 || sizes_[l].height < 1 ||
        levels_[l].size() != size_t(sizes_[l].width * sizes_[l].height))
      throw std::invalid_argument("GridHeightSource: level " + std::to_string(l) +
                                  " has the wrong number of samples");
  if (!(spacing_m_ > 0) || !std::isfinite(spacing_m_))
    throw std::invalid_argument("GridHeightSource: spacing must be a positive number of metres");
}

void GridHeightSource::fill(int level, const Rect& rect, float* out, int64_t out_stride) {
  const GridSize s = level_size(level);
  const float* z = levels_[size_t(level)].data();
  for (int64_t y = 0; y < rect.height; ++y) {
    const float* row = z + std::clamp<int64_t>(rect.y0 + y, 0, s.height - 1) * s.width;
    float* o = out + y * out_stride;
    for (int64_t x = 0; x < rect.width; ++x) o[x] = row[std::clamp<int64_t>(rect.x0 + x, 0, s.width - 1)];
  }
}

GridHeightSource original_source(const std::string& input, const ReadOptions& read_options, GridSize finest,
                                 int level_count, const DownsampleFilter& filter, double spacing_m) {
  const Heightmap map = read_heightmap(input, read_options);
  if (map.width() != finest.width || map.height() != finest.height)
    throw std::invalid_argument(input + ": " + std::to_string(map.width()) + "x" +
                                std::to_string(map.height()) +
                                " samples, but the pyramid's finest level is " +
                                std::to_string(finest.width) + "x" + std::to_string(finest.height));
  const LevelUnits units = level_units(map.info, 0);
  BuildOptions bo;
  bo.level_count = level_count;
  bo.value_scale = units.value_scale;
  bo.threads = 1;
  // The compressed file's D, so that the reference's coarse levels are the T_l it approximates.
  bo.use_fixed_filter = true;
  bo.fixed_filter = filter;
  const ReferenceLevels reference = reference_levels(map, bo);
  if (int(reference.levels.size()) != level_count)
    throw std::invalid_argument(input + ": the reference pyramid has " +
                                std::to_string(reference.levels.size()) + " levels, expected " +
                                std::to_string(level_count));
  const double metres_per_unit = map.info.vertical_scale / units.value_scale,
               offset = map.info.vertical_offset;
  std::vector<std::vector<float>> levels(static_cast<size_t>(level_count));
  for (int l = 0; l < level_count; ++l) {
    const std::vector<int32_t>& r = reference.levels[size_t(l)];
    levels[size_t(l)].resize(r.size());
    for (size_t i = 0; i < r.size(); ++i) levels[size_t(l)][i] = float(r[i] * metres_per_unit + offset);
  }
  std::vector<uint8_t> valid = map.valid;
  if (!valid.empty()) {  // voids read as 0 m, as RegionDecoderSource gives them
    std::vector<float>& f = levels.back();
    for (size_t i = 0; i < f.size(); ++i)
      if (!valid[i]) f[i] = 0.0f;
  }
  GridHeightSource src(reference.sizes, std::move(levels), spacing_m);
  src.finest_valid = std::move(valid);
  return src;
}

}  // namespace terrain::runtime
