#include "line_plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace cloudcast::bench {
namespace {

// A tick step of 1, 2 or 5 x 10^k giving about `count` ticks over `span`.
double NiceStep(double span, int count) {
  const double raw = span / count;
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    if (raw <= m * p) return m * p;
  }
  return 10 * p;
}

const cv::Scalar kColours[] = {{180, 119, 31},  {14, 127, 255}, {44, 160, 44},   {40, 39, 214},
                               {189, 103, 148}, {75, 86, 140},  {194, 119, 227}, {127, 127, 127},
                               {34, 189, 188},  {207, 190, 23}, {0, 0, 0},       {100, 200, 100}};

void Dashed(cv::Mat& img, cv::Point a, cv::Point b, const cv::Scalar& c, int thickness) {
  const double len = std::hypot(b.x - a.x, b.y - a.y);
  const int dashes = std::max(1, static_cast<int>(len / 8));
  for (int i = 0; i < dashes; i += 2) {
    const double t0 = double(i) / dashes, t1 = std::min(1.0, double(i + 1) / dashes);
    cv::line(img, a + (b - a) * t0, a + (b - a) * t1, c, thickness, cv::LINE_AA);
  }
}

}  // namespace

bool LinePlot::Write(const std::string& path) const {
  const int W = 1040, H = 640, left = 110, right = 300, top = 50, bottom = 60;
  cv::Mat img(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  double x0 = std::numeric_limits<double>::max(), x1 = -x0, y0 = x0, y1 = -x0;
  for (const PlotSeries& s : series) {
    for (double v : s.x) x0 = std::min(x0, v), x1 = std::max(x1, v);
    for (double v : s.y) y0 = std::min(y0, v), y1 = std::max(y1, v);
  }
  for (double v : x_marks) x0 = std::min(x0, v), x1 = std::max(x1, v);
  for (double v : y_marks) y0 = std::min(y0, v), y1 = std::max(y1, v);
  if (x0 > x1) return false;
  x0 = std::min(x0, 0.0);
  const double ypad = std::max(1e-6, (y1 - y0) * 0.05);
  y0 -= ypad;
  y1 += ypad;
  if (x1 <= x0) x1 = x0 + 1;
  const int pw = W - left - right, ph = H - top - bottom;
  auto px = [&](double x, double y) {
    return cv::Point(left + static_cast<int>((x - x0) / (x1 - x0) * pw),
                     top + static_cast<int>((y1 - y) / (y1 - y0) * ph));
  };
  const cv::Scalar grid(225, 225, 225), ink(40, 40, 40);
  const auto font = cv::FONT_HERSHEY_SIMPLEX;
  char buf[64];
  const double xs = NiceStep(x1 - x0, 8), ys = NiceStep(y1 - y0, 8);
  for (double x = std::ceil(x0 / xs) * xs; x <= x1 + 1e-9; x += xs) {
    cv::line(img, px(x, y0), px(x, y1), grid, 1);
    std::snprintf(buf, sizeof(buf), "%g", x);
    cv::putText(img, buf, px(x, y0) + cv::Point(-10, 20), font, 0.45, ink, 1, cv::LINE_AA);
  }
  for (double y = std::ceil(y0 / ys) * ys; y <= y1 + 1e-9; y += ys) {
    cv::line(img, px(x0, y), px(x1, y), grid, 1);
    std::snprintf(buf, sizeof(buf), "%g", y);
    cv::putText(img, buf, px(x0, y) + cv::Point(-62, 5), font, 0.45, ink, 1, cv::LINE_AA);
  }
  cv::rectangle(img, px(x0, y1), px(x1, y0), ink, 1);
  for (double x : x_marks) Dashed(img, px(x, y0), px(x, y1), cv::Scalar(0, 0, 200), 2);
  for (double y : y_marks) Dashed(img, px(x0, y), px(x1, y), cv::Scalar(0, 0, 200), 2);
  for (std::size_t i = 0; i < series.size(); ++i) {
    const PlotSeries& s = series[i];
    const cv::Scalar c = kColours[i % (sizeof(kColours) / sizeof(kColours[0]))];
    std::vector<std::pair<double, double>> pts;
    for (std::size_t k = 0; k < s.x.size() && k < s.y.size(); ++k) pts.push_back({s.x[k], s.y[k]});
    std::sort(pts.begin(), pts.end());
    for (std::size_t k = 0; k + 1 < pts.size(); ++k) {
      const cv::Point a = px(pts[k].first, pts[k].second),
                      b = px(pts[k + 1].first, pts[k + 1].second);
      if (s.dashed) {
        Dashed(img, a, b, c, 2);
      } else {
        cv::line(img, a, b, c, 2, cv::LINE_AA);
      }
    }
    for (const auto& p : pts) cv::circle(img, px(p.first, p.second), 4, c, cv::FILLED, cv::LINE_AA);
    const int ly = top + 10 + static_cast<int>(i) * 22;
    cv::line(img, {W - right + 15, ly}, {W - right + 45, ly}, c, 3, cv::LINE_AA);
    cv::putText(img, s.label, {W - right + 52, ly + 5}, font, 0.45, ink, 1, cv::LINE_AA);
  }
  cv::putText(img, title, {left, 30}, font, 0.6, ink, 1, cv::LINE_AA);
  cv::putText(img, x_label, {left + pw / 2 - 60, H - 15}, font, 0.5, ink, 1, cv::LINE_AA);
  cv::Mat ylab(30, ph, CV_8UC3, cv::Scalar(255, 255, 255));
  cv::putText(ylab, y_label, {ph / 2 - 80, 20}, font, 0.5, ink, 1, cv::LINE_AA);
  cv::rotate(ylab, ylab, cv::ROTATE_90_COUNTERCLOCKWISE);
  ylab.copyTo(img(cv::Rect(5, top, 30, ph)));
  return cv::imwrite(path, img);
}

}  // namespace cloudcast::bench
