// Line plots drawn by the project's rasteriser (raster.h): terrain-report's error per level (log
// axis) and clipmap-view's update and render time per frame (linear axis).
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "raster.h"

namespace cli {

struct PlotSeries {
  std::string name;  // in the legend, right of the plot
  Rgba colour;
  std::vector<double> x, y;  // equal lengths
  bool markers = true;       // a 7 x 7 square at every point
  int thickness = 2;
};

struct PlotAxes {
  std::string title, x_label, y_label;
  bool log_y = false;  // decades labelled, 2 and 5 as lighter lines; values <= 0 on the floor
  // Ticks of the x axis (value, label); empty: about 8 round values over the range.
  std::vector<std::pair<double, std::string>> x_ticks;
};

// A 760 x 480 plot of the series over the range of their points (linear y from 0). Throws
// std::invalid_argument for series whose x and y differ in length.
Canvas line_plot(const std::vector<PlotSeries>& series, const PlotAxes& axes);

}  // namespace cli
