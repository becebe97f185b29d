// Stereo matching: a rectified grey pair in, a disparity map out, which the core pipeline then
// turns into points like any other disparity map (DisparityEncoding::kU16, disparity_scale 1/16,
// invalid {0}: see ForMatcherOutput).
//
// Two families of matchers share one set of parameters:
//   kSgm         ours: a semi-global matcher (census cost, 4 or 8 paths, AVX2 / AVX-512 where the
//                CPU has them, a scalar fallback that gives the same output bit for bit);
//   kOpenCv...   OpenCV 4.6's cv::StereoSGBM (its three modes) and cv::StereoBM, called as they
//                are, as the reference and the cheap mode.
// docs/stereo.md has the accuracy and speed tables on New Tsukuba and how to reproduce them.
#pragma once

#include <cstdint>
#include <memory>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/core/image.h"

namespace cloudcast::stereo {

enum class MatcherKind : std::uint8_t {
  kSgm,             // ours, the default
  kOpenCvSgbm,      // cv::StereoSGBM::MODE_SGBM (5 directions, one pass)
  kOpenCvSgbm3Way,  // cv::StereoSGBM::MODE_SGBM_3WAY
  kOpenCvHH,        // cv::StereoSGBM::MODE_HH (8 directions, full cost volume)
  kOpenCvBm,        // cv::StereoBM (block matching with its prefilter)
};
// "sgm", "sgbm", "sgbm-3way", "hh", "bm".
std::string_view Name(MatcherKind kind);
bool ParseMatcherKind(std::string_view name, MatcherKind* out);

// Which code our matcher (kSgm) runs. kAuto picks the widest the CPU has; the others exist so
// tests and benchmarks can compare them (MakeMatcher fails for one the CPU lacks). All give the
// same output bit for bit.
enum class SimdLevel : std::uint8_t { kAuto, kScalar, kAvx2, kAvx512 };
std::string_view Name(SimdLevel level);  // "auto", "scalar", "avx2", "avx512"
bool ParseSimdLevel(std::string_view name, SimdLevel* out);
// True when this CPU can run `level` (kAuto and kScalar always).
bool CpuSupports(SimdLevel level);
// What kAuto resolves to on this CPU.
SimdLevel BestSimdLevel();

// The largest disparity the output can hold: 16 * (min_disparity + num_disparities) must fit in
// 15 bits (OpenCV's int16 output and cv::filterSpeckles need it too).
inline constexpr int kMaxDisparity = 2048;
// Our matcher keeps one byte per pixel and disparity for a frame; OpenCV's MODE_HH two. Frames
// whose volume would exceed this are refused (RESOURCE_EXHAUSTED) instead of allocated.
inline constexpr std::uint64_t kMaxCostVolumeBytes = std::uint64_t{1} << 30;

// Defaults suit 640x480 (New Tsukuba: docs/stereo.md has the measurements they were chosen by).
struct MatcherParams {
  MatcherKind kind = MatcherKind::kSgm;
  // Disparities searched: [min_disparity, min_disparity + num_disparities). The output holds the
  // disparity itself (not its offset from min_disparity), so the pipeline's scale stays 1/16 with
  // no offset whatever min_disparity is; a disparity <= 0 (possible only with min_disparity <= 0)
  // has no depth in front of the camera and is output as 0, "no match".
  int min_disparity = 0;
  int num_disparities = 128;  // > 0, a multiple of 16
  // OpenCV: its blockSize (SGBM: >= 1, BM: >= 5, odd). Ours: the side of the square window of the
  // centre-symmetric census transform whose Hamming distance is its matching cost: 3, 5 or 7 (4,
  // 12 or 24 bits, each comparing one pixel of the window with its mirror image through the
  // centre; the 24-bit distance is halved, rounding up, so costs stay within 0..12).
  int block_size = 5;
  // Smoothness penalties for a disparity change of 1 (p1) and of more (p2). 0 picks the default:
  // OpenCV's usual 8 * block^2 and 32 * block^2; ours, for its costs of 0 to 12 (4 for block 3),
  // measured on New Tsukuba and Aloe: 5 and 19 for block 5, 4 and 19 for 7, 3 and 16 for 3. Ours
  // sums its paths exactly in bytes, so it takes p2 in [p1 + 1, 31 - its largest cost] (19 for
  // blocks 5 and 7, 27 for 3) and p1 below that.
  int p1 = 0;
  int p2 = 0;
  // A match is rejected when another disparity (not a neighbour of the best) costs less than the
  // best's / (1 - ratio / 100), as OpenCV does (cost * (100 - ratio) < best * 100). Percent, in
  // [0, 99].
  int uniqueness_ratio = 10;
  // cv::filterSpeckles after matching: regions of at most this many pixels whose disparities
  // differ from their neighbours' by more than speckle_range px are removed. 0: off.
  int speckle_window_size = 100;
  int speckle_range = 2;
  // Left-right consistency: a match is dropped when the right image's best match of its right
  // pixel differs from it by more than this many px (OpenCV's disp12MaxDiff). < 0: off.
  int disp12_max_diff = 1;
  // Ours: 4 (left, right, up, down) or 8 (and the diagonals) aggregation paths. 4 by default: as
  // accurate on New Tsukuba and Aloe, and two thirds of the time (docs/stereo.md).
  int paths = 4;
  // Ours: which code to run (see SimdLevel).
  SimdLevel simd = SimdLevel::kAuto;

  // Each member in its range, and the combination valid for `kind`. Errors name the member under
  // `field` (e.g. "stereo.num_disparities is 100; it must be a positive multiple of 16").
  absl::Status Validate(std::string_view field = "stereo") const;
  // p1 and p2 as the matcher uses them (the defaults above resolved).
  int EffectiveP1() const;
  int EffectiveP2() const;
};

// Grey 8-bit rectified images: core's colour view with ColorEncoding::kMono8 (any stride; rows
// in pieces, as the server receives them, are fine). ToGrey (grey.h) makes one from colour.
using GreyView = ColorView;

// A disparity map in 1/16 px (uint16 fixed point), 0 = no match, row-major with no padding.
struct DisparityMap16 {
  std::vector<std::uint16_t> values;
  std::uint32_t width = 0;
  std::uint32_t height = 0;

  std::uint16_t at(std::uint32_t x, std::uint32_t y) const {
    return values[static_cast<std::size_t>(y) * width + x];
  }
  // As the core pipeline reads it: kU16, stride width * 2.
  DisparityView view() const;
};

// Denominator scale of the matcher's output: value / 16 = disparity in px.
inline constexpr double kDisparityScale = 1.0 / 16.0;
// `camera` (focal lengths, principal point, baseline of the rectified left camera) set up to read
// a DisparityMap16: disparity_scale 1/16, offset 0, invalid {0}.
CameraModel ForMatcherOutput(CameraModel camera);

// Not thread-safe: one per worker. Keeps its scratch memory between frames (allocated for the
// largest frame so far) and gives it back when a frame needs less than a quarter of it.
class Matcher {
 public:
  virtual ~Matcher();
  // Matches `left` against `right` (same size, kMono8, checked against Limits{}) into `out`
  // (resized). Errors name "left" or "right".
  virtual absl::Status Compute(const GreyView& left, const GreyView& right,
                               DisparityMap16* out) = 0;
  virtual const MatcherParams& params() const = 0;
};

// Validates `params` and makes the matcher it names.
absl::StatusOr<std::unique_ptr<Matcher>> MakeMatcher(const MatcherParams& params);

}  // namespace cloudcast::stereo
