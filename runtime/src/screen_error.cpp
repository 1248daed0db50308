// The screen-space geometric error of the rendered levels against the original data (L&H 2004 §9,
// Table 2) and the clipmap size it asks for.
#include "runtime/screen_error.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <stdexcept>

namespace terrain::runtime {

double triangle_size_px(int width, int height, double fov_y_deg, int n) {
  const double tan_half_h = std::tan(fov_y_deg * M_PI / 360.0) * double(width) / double(height);
  return 1.25 * double(width) / (double(n) * tan_half_h);
}

namespace {

// A window of the finest level with its true heights (and validity, when the truth has voids).
struct TruthWindow {
  Rect rect;             // on the finest level
  const float* z;        // rect.width * rect.height, row stride rect.width
  const uint8_t* valid;  // same layout, or null: all valid
};

// Appends |PL(T^_l) - truth| at every valid sample of `w` to err and their squares to sum2, PL being
// the renderer's triangulation of level l of `rendered` (shift = finest - l).
void accumulate_level_error(HeightSource& rendered, int l, int shift, const TruthWindow& w,
                            std::vector<float>& level, std::vector<float>& err, double& sum2) {
  const int64_t cx0 = w.rect.x0 >> shift, cy0 = w.rect.y0 >> shift;
  const int64_t cw = ((w.rect.x0 + w.rect.width - 1) >> shift) - cx0 + 2;
  const int64_t ch = ((w.rect.y0 + w.rect.height - 1) >> shift) - cy0 + 2;
  level.resize(size_t(cw * ch));
  rendered.fill(l, Rect{cx0, cy0, cw, ch}, level.data(), cw);  // beyond the level: edge samples, as drawn
  const double inv = 1.0 / double(int64_t(1) << shift);
  const auto z = [&](int64_t x, int64_t y) { return double(level[size_t((y - cy0) * cw + (x - cx0))]); };
  for (int64_t wy = 0; wy < w.rect.height; ++wy)
    for (int64_t wx = 0; wx < w.rect.width; ++wx) {
      const size_t i = size_t(wy * w.rect.width + wx);
      if (w.valid && !w.valid[i]) continue;
      const int64_t x = w.rect.x0 + wx, y = w.rect.y0 + wy;
      // PL(T^_l) at the fine sample: the renderer's triangles, diagonal (0,0)-(1,1) in each quad.
      const int64_t cx = x >> shift, cy = y >> shift;
      const double u = double(x) * inv - double(cx), v = double(y) * inv - double(cy);
      const double z00 = z(cx, cy), z11 = z(cx + 1, cy + 1);
      const double p = u >= v ? z00 + u * (z(cx + 1, cy) - z00) + v * (z11 - z(cx + 1, cy))
                              : z00 + v * (z(cx, cy + 1) - z00) + u * (z11 - z(cx, cy + 1));
      const double e = std::abs(p - double(w.z[i]));
      err.push_back(float(e));
      sum2 += e * e;
    }
}

// Table 2 statistics of levels first_level..finest of `rendered` over the truth windows.
std::vector<LevelScreenError> level_screen_errors(HeightSource& rendered,
                                                  const std::vector<TruthWindow>& windows, int first_level,
                                                  double s_px) {
  const int finest = rendered.level_count() - 1;
  size_t samples = 0;
  for (const TruthWindow& w : windows) samples += size_t(w.rect.width * w.rect.height);
  std::vector<LevelScreenError> out;
  std::vector<float> level, err;
  err.reserve(samples);
  for (int l = std::max(first_level, 0); l <= finest; ++l) {
    const int shift = finest - l;
    err.clear();
    double sum2 = 0;
    for (const TruthWindow& w : windows) accumulate_level_error(rendered, l, shift, w, level, err, sum2);
    LevelScreenError r;
    r.level = l;
    r.spacing_m = rendered.spacing_m() * double(int64_t(1) << shift);
    const double to_px = s_px / r.spacing_m;
    if (!err.empty()) {
      r.rms_m = std::sqrt(sum2 / double(err.size()));
      const size_t k = std::min(err.size() - 1, size_t(std::ceil(0.999 * double(err.size()))) - 1);
      std::nth_element(err.begin(), err.begin() + ptrdiff_t(k), err.end());
      r.p999_px = double(err[k]) * to_px;
      r.max_m = double(*std::max_element(err.begin() + ptrdiff_t(k), err.end()));
    }
    r.rms_px = r.rms_m * to_px;
    r.max_px = r.max_m * to_px;
    out.push_back(r);
  }
  return out;
}

}  // namespace

std::vector<LevelScreenError> screen_space_error(HeightSource& rendered, const GridHeightSource& original,
                                                 int first_level, double s_px) {
  const int finest = original.level_count() - 1;
  if (rendered.level_count() != original.level_count() ||
      !(rendered.level_size(finest) == original.level_size(finest)))
    throw std::invalid_argument("screen_space_error: the rendered and original pyramids differ in size");
  const GridSize fs = original.level_size(finest);
  const std::vector<uint8_t>& valid = original.finest_valid;
  const TruthWindow whole{Rect{0, 0, fs.width, fs.height}, original.level(finest).data(),
                          valid.empty() ? nullptr : valid.data()};
  return level_screen_errors(rendered, {whole}, first_level, s_px);
}

std::vector<LevelScreenError> estimate_screen_space_error(HeightSource& source, int first_level, double s_px,
                                                          int64_t max_samples) {
  const int finest = source.level_count() - 1;
  const GridSize fs = source.level_size(finest);
  // The whole finest level when it is small enough, otherwise a k x k grid of equal windows spread
  // evenly over it (k^2 windows of side `side` within max_samples): bounded time and memory on any
  // pyramid, and every part of the terrain represented.
  std::vector<Rect> rects;
  if (fs.width * fs.height <= max_samples) {
    rects.push_back(Rect{0, 0, fs.width, fs.height});
  } else {
    constexpr int64_t kSide = 256;
    const int64_t side_x = std::min(kSide, fs.width), side_y = std::min(kSide, fs.height);
    const int64_t k = std::max<int64_t>(1, int64_t(std::sqrt(double(max_samples) / double(side_x * side_y))));
    for (int64_t j = 0; j < k; ++j)
      for (int64_t i = 0; i < k; ++i)
        rects.push_back(Rect{(fs.width - side_x) * (2 * i + 1) / (2 * k),
                             (fs.height - side_y) * (2 * j + 1) / (2 * k), side_x, side_y});
  }
  std::vector<std::vector<float>> truth(rects.size());
  std::vector<TruthWindow> windows;
  for (size_t w = 0; w < rects.size(); ++w) {
    truth[w].resize(size_t(rects[w].width * rects[w].height));
    source.fill(finest, rects[w], truth[w].data(), rects[w].width);
    windows.push_back(TruthWindow{rects[w], truth[w].data(), nullptr});
  }
  return level_screen_errors(source, windows, first_level, s_px);
}

void add_finest_error_bound(std::vector<LevelScreenError>& errors, double finest_rms_m, double finest_max_m,
                            double s_px) {
  assert(finest_rms_m >= 0 && finest_max_m >= 0 && s_px > 0);
  for (LevelScreenError& e : errors) {
    const double px_per_m = s_px / e.spacing_m;
    e.rms_m += finest_rms_m;
    e.max_m += finest_max_m;
    e.rms_px += finest_rms_m * px_per_m;
    e.p999_px += finest_max_m * px_per_m;
    e.max_px += finest_max_m * px_per_m;
  }
}

ClipmapSizeChoice clipmap_size_for_screen_error(const std::vector<LevelScreenError>& errors, double s_px,
                                                int width, int height, double fov_y_deg,
                                                double tolerance_px) {
  double worst = 0;  // p99.9 pixels per pixel of triangle size, the worst level
  for (const LevelScreenError& e : errors) worst = std::max(worst, e.p999_px / s_px);
  ClipmapSizeChoice c;
  for (int n = 15; n <= 1023; n = 2 * n + 1) {
    c.n = n;
    c.p999_px = worst * triangle_size_px(width, height, fov_y_deg, n);
    c.met = c.p999_px <= tolerance_px;
    if (c.met) break;
  }
  return c;
}

}  // namespace terrain::runtime
