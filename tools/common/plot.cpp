// Line plots: axes with round ticks (linear) or decades (log), series, legend.
#include "plot.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>

namespace cli {

namespace {

// A round step (1, 2 or 5 times a power of ten) giving about `count` ticks over `span`.
double round_step(double span, int count) {
  const double raw = span / count, p = std::pow(10, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0})
    if (m * p >= raw) return m * p;
  return 10 * p;
}

// Integral values as integers ("1200", not "1.2e+03"), others as tick_label does.
std::string axis_label(double v) {
  if (v == std::round(v) && std::abs(v) < 1e7) return std::to_string(int64_t(v));
  return tick_label(v);
}

}  // namespace

Canvas line_plot(const std::vector<PlotSeries>& series, const PlotAxes& axes) {
  const int W = 760, H = 480, left = 78, right = 110, top = 36, bottom = 58;
  Canvas c(W, H);
  const Rgba ink{0, 0, 0, 255}, grid{215, 215, 215, 255};
  double x0 = std::numeric_limits<double>::infinity(), x1 = -x0, lo = x0, hi = 0;
  for (const PlotSeries& s : series) {
    if (s.x.size() != s.y.size()) throw std::invalid_argument("line_plot: x and y differ in length");
    for (size_t i = 0; i < s.x.size(); ++i) {
      x0 = std::min(x0, s.x[i]), x1 = std::max(x1, s.x[i]);
      if (!axes.log_y || s.y[i] > 0) lo = std::min(lo, s.y[i]), hi = std::max(hi, s.y[i]);
    }
  }
  if (!(x1 > x0)) x0 = std::isfinite(x0) ? x0 - 0.5 : 0, x1 = x0 + 1;
  double d0 = 0, d1 = 1, ystep = 1;
  if (axes.log_y) {
    if (!(hi > 0)) lo = 0.01, hi = 1;  // every figure 0: drawn on the floor of the axis
    d0 = std::floor(std::log10(lo)), d1 = std::max(std::ceil(std::log10(hi)), d0 + 1);
  } else {
    ystep = round_step(hi > 0 ? hi : 1, 6);
    d1 = std::ceil((hi > 0 ? hi : 1) / ystep) * ystep;
  }
  const double pw = W - left - right, ph = H - top - bottom;
  auto px = [&](double x) { return left + (x - x0) / (x1 - x0) * pw; };
  auto py = [&](double v) {
    if (!axes.log_y) return top + ph * (1 - std::clamp(v, 0.0, d1) / d1);
    const double lv = v > 0 ? std::log10(v) : d0;
    return top + ph * (1 - (std::clamp(lv, d0, d1) - d0) / (d1 - d0));
  };
  auto y_tick = [&](double v) {
    c.line(left, py(v), W - right, py(v), grid);
    const std::string label = axes.log_y ? tick_label(v) : axis_label(v);
    c.text(left - 6 - Canvas::text_width(label, 2), int(py(v)) - 7, label, ink, 2);
  };
  if (axes.log_y) {
    for (double d = d0; d <= d1; ++d) {  // decades: grid line and label; 2 and 5 as lighter lines
      y_tick(std::pow(10, d));
      if (d < d1)
        for (double m : {2.0, 5.0})
          c.line(left, py(m * std::pow(10, d)), W - right, py(m * std::pow(10, d)), {235, 235, 235, 255});
    }
  } else {
    for (double v = 0; v <= d1 + 0.5 * ystep; v += ystep) y_tick(v);
  }
  std::vector<std::pair<double, std::string>> ticks = axes.x_ticks;
  if (ticks.empty()) {
    const double step = round_step(x1 - x0, 8);
    for (double v = std::ceil(x0 / step) * step; v <= x1 + 1e-9 * step; v += step)
      ticks.emplace_back(v, axis_label(v));
  }
  for (const auto& [v, label] : ticks) {
    c.line(px(v), top + ph, px(v), top + ph + 5, ink);
    c.text(int(px(v)) - Canvas::text_width(label, 2) / 2, top + int(ph) + 9, label, ink, 2);
  }
  c.line(left, top, left, top + ph, ink);
  c.line(left, top + ph, W - right, top + ph, ink);
  c.text(left + int(pw) / 2 - Canvas::text_width(axes.x_label, 2) / 2, H - 22, axes.x_label, ink, 2);
  c.text(10, top + int(ph) / 2 + Canvas::text_width(axes.y_label, 2) / 2, axes.y_label, ink, 2, true);
  c.text(left, 10, axes.title, ink, 2);
  int legend_y = top + 8;
  for (const PlotSeries& s : series) {
    for (size_t i = 0; i < s.x.size(); ++i) {
      if (i > 0) c.line(px(s.x[i - 1]), py(s.y[i - 1]), px(s.x[i]), py(s.y[i]), s.colour, s.thickness);
      if (s.markers) c.fill_rect(int(px(s.x[i])) - 3, int(py(s.y[i])) - 3, 7, 7, s.colour);
    }
    c.fill_rect(W - right + 12, legend_y + 5, 20, 3, s.colour);  // the legend, right of the plot
    c.text(W - right + 38, legend_y, s.name, ink, 2);
    legend_y += 20;
  }
  return c;
}

}  // namespace cli
