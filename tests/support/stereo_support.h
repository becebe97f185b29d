// Helpers of the stereo tests: textured synthetic pairs with known disparities, grey images from
// cv::Mat, the data sets' pairs.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "cloudcast/datasets/middlebury.h"
#include "cloudcast/datasets/tsukuba.h"
#include "cloudcast/io/image_io.h"
#include "cloudcast/stereo/grey.h"
#include "cloudcast/stereo/matcher.h"

namespace cloudcast::testing {

inline stereo::GreyImage GreyOf(const cv::Mat& m) {
  stereo::GreyImage g;
  g.width = static_cast<std::uint32_t>(m.cols);
  g.height = static_cast<std::uint32_t>(m.rows);
  g.encoding = ColorEncoding::kMono8;
  g.pixels.resize(m.total());
  for (int y = 0; y < m.rows; ++y) std::memcpy(g.pixels.data() + y * m.cols, m.ptr(y), m.cols);
  return g;
}

inline cv::Mat MatOf(const stereo::GreyImage& g) {
  return cv::Mat(static_cast<int>(g.height), static_cast<int>(g.width), CV_8UC1,
                 const_cast<std::uint8_t*>(g.pixels.data()))
      .clone();
}

// Random blobs, blurred: texture a census can lock onto at every pixel (and some flat-ish parts).
inline cv::Mat Texture(int width, int height, std::uint32_t seed) {
  std::mt19937 rng(seed);
  cv::Mat noise(height, width, CV_8UC1);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) noise.at<std::uint8_t>(y, x) = static_cast<std::uint8_t>(rng());
  }
  cv::Mat out;
  cv::GaussianBlur(noise, out, cv::Size(0, 0), 1.2);
  cv::normalize(out, out, 0, 255, cv::NORM_MINMAX);
  return out;
}

// A pair whose left pixel (x, y) shows the right pixel (x - d(y), y): the right image is the left
// texture shifted by the row's disparity, sampled with sub-pixel accuracy (bilinear). The scene
// is wider than the images by a margin on each side (the right image reads from x + d to
// x + d + 1, and d may be negative) so no column of either lacks texture; disparities must lie
// in [-margin, margin - 1).
struct SyntheticPair {
  stereo::GreyImage left, right;
  std::vector<double> row_disparity;
};
inline SyntheticPair ShiftedPair(int width, int height, const std::vector<double>& bands,
                                 std::uint32_t seed) {
  const int margin = 300;
  const cv::Mat scene = Texture(width + 2 * margin, height, seed);
  cv::Mat left(height, width, CV_8UC1), right(height, width, CV_8UC1);
  SyntheticPair p;
  for (int y = 0; y < height; ++y) {
    const double d = bands[static_cast<std::size_t>(y) * bands.size() / height];
    if (d < -margin || d >= margin - 1) {
      throw std::invalid_argument("ShiftedPair: disparity out of range");
    }
    p.row_disparity.push_back(d);
    for (int x = 0; x < width; ++x) {
      left.at<std::uint8_t>(y, x) = scene.at<std::uint8_t>(y, x + margin);
      // right(xr) = left(xr + d) = scene(xr + d + margin)
      const double sx = x + d + margin;
      const int x0 = static_cast<int>(std::floor(sx));
      const double f = sx - x0;
      const double v =
          (1 - f) * scene.at<std::uint8_t>(y, x0) + f * scene.at<std::uint8_t>(y, x0 + 1);
      right.at<std::uint8_t>(y, x) = cv::saturate_cast<std::uint8_t>(v);
    }
  }
  p.left = GreyOf(left);
  p.right = GreyOf(right);
  return p;
}

// A grey New Tsukuba pair with its truth; false when the data is absent.
struct GreyPair {
  stereo::GreyImage left, right;
  OwnedDisparity truth;
};
inline bool LoadTsukubaGrey(const std::string& id, GreyPair* out) {
  auto f = tsukuba::LoadStereo(tsukuba::DefaultDir(), id);
  if (!f.ok()) return false;
  out->left = *stereo::ToGrey(f->left.view());
  out->right = *stereo::ToGrey(f->right.view());
  out->truth = std::move(f->truth);
  return true;
}

// Middlebury's Aloe at half size (middlebury.h); false when opencv-doc is not installed.
inline bool LoadAloeHalf(GreyPair* out) {
  auto f = middlebury::LoadAloe(middlebury::AloeDir(), /*half=*/true);
  if (!f.ok()) return false;
  out->left = *stereo::ToGrey(f->left.view());
  out->right = *stereo::ToGrey(f->right.view());
  out->truth = std::move(f->truth);
  return true;
}

}  // namespace cloudcast::testing
