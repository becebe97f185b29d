// OpenCV images for the client-side tests: random disparity and colour Mats, exact comparison,
// and videos written with OpenCV's own writer.
#pragma once

#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>
#include <string>
#include <vector>

namespace cloudcast::testing {

// Equal type, size and every value.
inline ::testing::AssertionResult SameMat(const cv::Mat& a, const cv::Mat& b) {
  if (a.type() != b.type() || a.size() != b.size()) {
    return ::testing::AssertionFailure()
           << "type/size differ: " << cv::typeToString(a.type()) << " " << a.cols << "x" << a.rows
           << " vs " << cv::typeToString(b.type()) << " " << b.cols << "x" << b.rows;
  }
  if (a.empty()) return ::testing::AssertionSuccess();
  cv::Mat diff;
  cv::absdiff(a.reshape(1), b.reshape(1), diff);
  double max = 0;
  cv::minMaxLoc(diff, nullptr, &max);
  if (max != 0) return ::testing::AssertionFailure() << "values differ by up to " << max;
  return ::testing::AssertionSuccess();
}

// A disparity with every 8-bit value, zeros included, and a random colour image.
inline cv::Mat TestDisparity8(int w, int h, int seed) {
  cv::Mat d(h, w, CV_8UC1);
  cv::RNG rng(seed);
  rng.fill(d, cv::RNG::UNIFORM, 0, 256);
  return d;
}
inline cv::Mat TestColour(int w, int h, int seed) {
  cv::Mat c(h, w, CV_8UC3);
  cv::RNG rng(seed + 1000);
  rng.fill(c, cv::RNG::UNIFORM, 0, 256);
  return c;
}

// Writes `frames` to `path` with `fourcc` through FFmpeg; false when this OpenCV build cannot.
inline bool WriteVideo(const std::string& path, const char* fourcc,
                       const std::vector<cv::Mat>& frames) {
  const bool colour = frames.front().channels() == 3;
  cv::VideoWriter writer(path, cv::CAP_FFMPEG,
                         cv::VideoWriter::fourcc(fourcc[0], fourcc[1], fourcc[2], fourcc[3]), 30,
                         frames.front().size(), colour);
  if (!writer.isOpened()) return false;
  for (const cv::Mat& f : frames) writer.write(f);
  writer.release();
  return true;
}

}  // namespace cloudcast::testing
