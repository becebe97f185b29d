// What a stream asks of the server's stereo matcher, and a stereo camera's calibration: plain
// settings with their defaults and checks, in one place for the proto boundary, the server and
// the clients. The matchers themselves (OpenCV's and ours) and the rectification live in stereo/,
// which needs OpenCV; the client library needs only these structs.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"

namespace cloudcast {

enum class StereoMatcher : std::uint8_t {
  kSgm,             // cloudcast's own semi-global matcher (census cost, SIMD): the fast one
  kOpenCvSgbm,      // cv::StereoSGBM, MODE_SGBM
  kOpenCvSgbm3Way,  // cv::StereoSGBM, MODE_SGBM_3WAY
  kOpenCvHH,        // cv::StereoSGBM, MODE_HH (all 8 paths)
  kOpenCvBm,        // cv::StereoBM: block matching, the cheapest and least dense
};
std::string_view Name(StereoMatcher matcher);  // "sgm", "sgbm", "sgbm-3way", "hh", "bm"
bool ParseStereoMatcher(std::string_view name, StereoMatcher* out);
// Every matcher, in the enum's order (for --help texts and GetInfo).
const std::vector<StereoMatcher>& AllStereoMatchers();

// A stereo camera's calibration, as OpenCV's stereoCalibrate gives it (row-major matrices).
struct StereoCalibration {
  std::uint32_t width = 0;  // the image size it was made for
  std::uint32_t height = 0;
  std::array<double, 9> left_k{};  // 3x3 intrinsics
  std::vector<double> left_d;      // distortion: 0, 4, 5, 8, 12 or 14 coefficients
  std::array<double, 9> right_k{};
  std::vector<double> right_d;
  std::array<double, 9> r{};  // rotation from the left camera to the right one
  std::array<double, 3> t{};  // translation, in the unit the cloud is wanted in

  // A size of at least 1x1, finite values, positive focal lengths, a distortion count OpenCV
  // accepts, a rotation matrix (orthonormal, determinant 1, within 1e-6) and a non-zero
  // translation. Errors name the member under `field`.
  absl::Status Validate(std::string_view field = "calibration") const;
  bool operator==(const StereoCalibration& o) const;
};

// How a stereo pair is matched. Names and meanings are OpenCV StereoSGBM's, so that a robot
// engineer who tuned OpenCV finds the same knobs. The defaults suit 640x480.
struct StereoParams {
  StereoMatcher matcher = StereoMatcher::kSgm;
  int min_disparity = 0;
  int num_disparities = 128;  // > 0, a multiple of 16
  int block_size = 5;         // odd; StereoBM needs 5..255
  int p1 = 0;                 // smoothness penalties; 0: the matcher's own default
  int p2 = 0;
  int uniqueness_ratio = 10;      // percent
  int speckle_window_size = 100;  // 0: no speckle filter
  int speckle_range = 2;
  int disp12_max_diff = 1;        // left-right check tolerance in pixels; < 0: no check
  int paths = 8;                  // kSgm: 4 or 8
  bool return_disparity = false;  // send the disparity map back with the cloud
  // Unrectified pairs: rectify with this first.
  bool has_calibration = false;
  StereoCalibration calibration;

  // Every member in range; errors name it under `field` (e.g. "stereo.num_disparities is 100;
  // it must be a positive multiple of 16").
  absl::Status Validate(std::string_view field = "stereo") const;
};

}  // namespace cloudcast
