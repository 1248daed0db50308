// The mirrored virtual terrain: reflected base levels, and the coarser levels it lacks computed by D
// over one period of the reflected tiling (see mirrored_source.h for why that is exact).
#include "runtime/mirrored_source.h"

#include <algorithm>
#include <stdexcept>
#include <string>

#include "pyramid/levels.h"

namespace terrain::runtime {

int64_t MirroredSource::reflect(int64_t i, int64_t n) {
  if (n <= 1) return 0;
  const int64_t period = 2 * (n - 1);
  i = ((i % period) + period) % period;
  return i < n ? i : period - i;
}

MirroredSource::MirroredSource(HeightSource& base, GridSize finest, const DownsampleFilter& filter,
                               int64_t min_coarsest_side)
    : base_(base) {
  const int base_levels = base.level_count();
  if (base_levels < 1) throw std::invalid_argument("MirroredSource: the base has no levels");
  const GridSize bf = base.level_size(base_levels - 1);
  if (finest.width < bf.width || finest.height < bf.height || finest.width > (int64_t(1) << 30) ||
      finest.height > (int64_t(1) << 30))
    throw std::invalid_argument("MirroredSource: the virtual size must be " + std::to_string(bf.width) + "x" +
                                std::to_string(bf.height) + " (the base's) .. 2^30 a side");
  sizes_ = pyramid_level_sizes(finest, 0, min_coarsest_side);
  const int levels = int(sizes_.size());
  // The base levels that line up with their finer neighbour under reflection, from the finest down.
  int coarsest_lined = base_levels - 1;
  while (coarsest_lined > 0) {
    const GridSize c = base.level_size(coarsest_lined - 1), f = base.level_size(coarsest_lined);
    if (f.width - 1 != 2 * (c.width - 1) || f.height - 1 != 2 * (c.height - 1)) break;
    --coarsest_lined;
  }
  offset_ = levels - base_levels;
  first_mapped_ = std::max(0, coarsest_lined + offset_);
  if (first_mapped_ == 0) return;  // the virtual pyramid needs no computed level
  const int s = first_mapped_ - offset_;
  const GridSize cs = base.level_size(s);
  if (cs.width * cs.height > (int64_t(1) << 24))
    throw std::invalid_argument("MirroredSource: the base's coarsest lined-up level (" +
                                std::to_string(cs.width) + "x" + std::to_string(cs.height) +
                                ") is too large to hold in memory");
  std::vector<float> stored(size_t(cs.width * cs.height));
  base.fill(s, Rect{0, 0, cs.width, cs.height}, stored.data(), cs.width);
  // One period of the reflected stored level, then D level by level (p -> p/2 when even, else p).
  Tile finer;
  finer.px = cs.width > 1 ? 2 * (cs.width - 1) : 1;
  finer.py = cs.height > 1 ? 2 * (cs.height - 1) : 1;
  finer.z.resize(size_t(finer.px * finer.py));
  for (int64_t y = 0; y < finer.py; ++y)
    for (int64_t x = 0; x < finer.px; ++x)
      finer.z[size_t(y * finer.px + x)] =
          stored[size_t(reflect(y, cs.height) * cs.width + reflect(x, cs.width))];
  tiles_.resize(size_t(first_mapped_));
  const int r = DownsampleFilter::kRadius;
  for (int v = first_mapped_ - 1; v >= 0; --v) {
    Tile t;
    t.px = finer.px % 2 == 0 ? finer.px / 2 : finer.px;
    t.py = finer.py % 2 == 0 ? finer.py / 2 : finer.py;
    t.z.resize(size_t(t.px * t.py));
    for (int64_t j = 0; j < t.py; ++j)
      for (int64_t i = 0; i < t.px; ++i) {
        double sum = 0;
        for (int dy = -r; dy <= r; ++dy) {
          const int64_t fy = ((2 * j + dy) % finer.py + finer.py) % finer.py;
          for (int dx = -r; dx <= r; ++dx) {
            const int64_t fx = ((2 * i + dx) % finer.px + finer.px) % finer.px;
            sum += filter.tap(dx, dy) * double(finer.z[size_t(fy * finer.px + fx)]);
          }
        }
        t.z[size_t(j * t.px + i)] = float(sum);
      }
    tiles_[size_t(v)] = t;
    finer = std::move(t);
  }
}

int MirroredSource::base_level(int level) const {
  if (level < 0 || level >= level_count()) throw std::out_of_range("MirroredSource: no such level");
  return level < first_mapped_ ? -1 : level - offset_;
}

size_t MirroredSource::memory_bytes() const {
  size_t bytes = sizeof(*this) + sizes_.capacity() * sizeof(GridSize);
  for (const Tile& t : tiles_) bytes += t.z.capacity() * sizeof(float);
  return bytes + (xs_.capacity() + ys_.capacity()) * sizeof(int64_t) + window_.capacity() * sizeof(float);
}

void MirroredSource::fill(int level, const Rect& rect, float* out, int64_t out_stride) {
  const int b = base_level(level);
  if (rect.width <= 0 || rect.height <= 0) return;
  const GridSize vs = sizes_[size_t(level)];
  // Virtual coordinates clamped to the virtual extent (the edge repeats beyond it), then folded
  // into the base level (or the tile's period).
  const GridSize bs = b >= 0 ? base_.level_size(b) : GridSize{};
  const int64_t pw = b >= 0 ? bs.width : tiles_[size_t(level)].px,
                ph = b >= 0 ? bs.height : tiles_[size_t(level)].py;
  xs_.resize(size_t(rect.width));
  ys_.resize(size_t(rect.height));
  for (int64_t i = 0; i < rect.width; ++i) {
    const int64_t x = std::clamp<int64_t>(rect.x0 + i, 0, vs.width - 1);
    xs_[size_t(i)] = b >= 0 ? reflect(x, pw) : x % pw;
  }
  for (int64_t j = 0; j < rect.height; ++j) {
    const int64_t y = std::clamp<int64_t>(rect.y0 + j, 0, vs.height - 1);
    ys_[size_t(j)] = b >= 0 ? reflect(y, ph) : y % ph;
  }
  const float* src;
  int64_t stride;
  if (b >= 0) {
    // The base window the folded coordinates span (at most the rect's size, or the level).
    const auto [xlo, xhi] = std::minmax_element(xs_.begin(), xs_.end());
    const auto [ylo, yhi] = std::minmax_element(ys_.begin(), ys_.end());
    const int64_t wx0 = *xlo, wy0 = *ylo;
    stride = *xhi - *xlo + 1;
    const int64_t wh = *yhi - *ylo + 1;
    window_.resize(size_t(stride * wh));
    base_.fill(b, Rect{wx0, wy0, stride, wh}, window_.data(), stride);
    src = window_.data();
    for (int64_t& x : xs_) x -= wx0;
    for (int64_t& y : ys_) y -= wy0;
  } else {
    const Tile& t = tiles_[size_t(level)];
    src = t.z.data(), stride = t.px;
  }
  for (int64_t j = 0; j < rect.height; ++j) {
    const float* row = src + ys_[size_t(j)] * stride;
    float* o = out + j * out_stride;
    for (int64_t i = 0; i < rect.width; ++i) o[i] = row[xs_[size_t(i)]];
  }
}

}  // namespace terrain::runtime
