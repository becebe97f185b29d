// What a stream asks of the server's stereo matcher, and a stereo camera's calibration: plain
// settings with their defaults and checks, in one place for the proto boundary, the server, the
// matchers and the clients. The matchers themselves (OpenCV's and ours) and the rectification live
// in stereo/ (cloudcast_stereo), which needs OpenCV; the client library needs only these structs.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"

namespace cloudcast {

enum class StereoMatcher : std::uint8_t {
  kSgm,             // ours, the default: a semi-global matcher (census cost, 4 or 8 paths, SIMD)
  kOpenCvSgbm,      // cv::StereoSGBM::MODE_SGBM (5 directions, one pass)
  kOpenCvSgbm3Way,  // cv::StereoSGBM::MODE_SGBM_3WAY
  kOpenCvHH,        // cv::StereoSGBM::MODE_HH (8 directions, full cost volume)
  kOpenCvBm,        // cv::StereoBM (block matching with its prefilter): cheap, least dense
};
std::string_view Name(StereoMatcher matcher);  // "sgm", "sgbm", "sgbm-3way", "hh", "bm"
bool ParseStereoMatcher(std::string_view name, StereoMatcher* out);
// Every matcher, in the enum's order (for --help texts and GetInfo).
const std::vector<StereoMatcher>& AllStereoMatchers();

// The largest disparity the matchers' output holds: 16 * (min_disparity + num_disparities) must
// fit in 15 bits (OpenCV's int16 output and cv::filterSpeckles need it too).
inline constexpr int kMaxStereoDisparity = 2048;
// Our matcher sums its path costs in bytes, exactly as long as a path's cost stays within this
// (stereo/src/sgm_kernels.h holds the kernels to it).
inline constexpr int kSgmMaxPathCost = 31;
// Our matcher's largest matching cost for a census window of `block_size` (3, 5 or 7): its census
// bits (4, 12), the 24 bits of a 7x7 window halved, rounding up.
int SgmMaxCensusCost(int block_size);

// A stereo camera's calibration, as OpenCV's cv::stereoCalibrate gives it: a point X in
// left-camera coordinates is R * X + T in the right camera's. Matrices are row-major.
struct StereoCalibration {
  std::uint32_t width = 0;  // the image size both cameras were calibrated at
  std::uint32_t height = 0;
  std::array<double, 9> left_k{};  // camera matrix: fx 0 cx / 0 fy cy / 0 0 1 (skew allowed)
  std::vector<double> left_d;      // distortion: 0, 4, 5, 8, 12 or 14 coefficients
  std::array<double, 9> right_k{};
  std::vector<double> right_d;
  std::array<double, 9> r{};  // rotation (orthonormal, determinant +1)
  std::array<double, 3> t{};  // translation; its unit is the baseline's, and so z's

  // A size of at least 1x1 within Limits{}; finite values; camera matrices with positive focal
  // lengths and 0 0 1 as their last row (and 0 below the diagonal); a distortion count OpenCV
  // takes; R a rotation (R^T R = I within 1e-6, det +1); T not zero. Errors name the member
  // under `field` (e.g. "calibration.left_k[0] (fx)").
  absl::Status Validate(std::string_view field = "calibration") const;
  bool operator==(const StereoCalibration& o) const;
};

// How a stereo pair is matched. Names and meanings are OpenCV StereoSGBM's, so that a robot
// engineer who tuned OpenCV finds the same knobs. The defaults suit 640x480 (docs/stereo.md has
// the measurements on New Tsukuba and Middlebury's Aloe they were chosen by).
struct StereoParams {
  StereoMatcher matcher = StereoMatcher::kSgm;
  // Disparities searched: [min_disparity, min_disparity + num_disparities). The output holds the
  // disparity itself (not its offset from min_disparity), so the pipeline's scale stays 1/16 with
  // no offset whatever min_disparity is; a disparity <= 0 (possible only with min_disparity <= 0)
  // has no depth in front of the camera and is output as 0, "no match".
  int min_disparity = 0;
  int num_disparities = 128;  // > 0, a multiple of 16
  // OpenCV: its blockSize (SGBM: >= 1, BM: >= 5, odd). Ours: the side of the square window of the
  // centre-symmetric census transform whose Hamming distance is its matching cost: 3, 5 or 7.
  int block_size = 5;
  // Smoothness penalties for a disparity change of 1 (p1) and of more (p2). 0 picks the default:
  // OpenCV's usual 8 * block^2 and 32 * block^2; ours, for its costs of 0 to 12 (4 for block 3):
  // 5 and 19 for block 5, 4 and 19 for 7, 3 and 16 for 3. Ours takes p2 in
  // [p1 + 1, kSgmMaxPathCost - its largest cost] (19 for blocks 5 and 7, 27 for 3).
  int p1 = 0;
  int p2 = 0;
  // A match is rejected when another disparity (not a neighbour of the best) costs less than the
  // best's / (1 - ratio / 100), as OpenCV does. Percent, in [0, 99].
  int uniqueness_ratio = 10;
  // Speckle filter after matching: regions of at most this many pixels whose disparities differ
  // from their neighbours' by more than speckle_range px are removed (cv::filterSpeckles). 0: off.
  int speckle_window_size = 100;
  int speckle_range = 2;
  // Left-right consistency: a match is dropped when the right image's best match of its right
  // pixel differs from it by more than this many px (OpenCV's disp12MaxDiff). < 0: off.
  int disp12_max_diff = 1;
  // Ours: 4 (left, right, up, down) or 8 (and the diagonals) aggregation paths. 4 by default: as
  // accurate on New Tsukuba and Aloe, in two thirds of the time.
  int paths = 4;
  // Send the disparity map back with the cloud (CloudReply.disparity).
  bool return_disparity = false;
  // Unrectified pairs: rectify with this first.
  bool has_calibration = false;
  StereoCalibration calibration;

  // Each member in its range, and the combination valid for `matcher`. Errors name the member
  // under `field` (e.g. "stereo.num_disparities is 100; it must be a positive multiple of 16").
  absl::Status Validate(std::string_view field = "stereo") const;
  // p1 and p2 as the matcher uses them (the defaults above resolved).
  int EffectiveP1() const;
  int EffectiveP2() const;
};

}  // namespace cloudcast
