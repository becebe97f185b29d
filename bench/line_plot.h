// Line charts as PNG files for docs/, drawn with OpenCV (already a dependency of every benchmark):
// axes with ticks, one polyline per series, a legend, optional target lines.
#pragma once

#include <string>
#include <vector>

namespace cloudcast::bench {

struct PlotSeries {
  std::string label;
  std::vector<double> x, y;
  bool dashed = false;
};

struct LinePlot {
  std::string title, x_label, y_label;
  std::vector<PlotSeries> series;
  std::vector<double> x_marks;  // vertical target lines (e.g. a bitrate budget)
  std::vector<double> y_marks;  // horizontal ones (e.g. a PSNR floor, a lossless score)
  // Writes `path` (PNG, 1000 x 640). False when OpenCV cannot write it.
  bool Write(const std::string& path) const;
};

}  // namespace cloudcast::bench
