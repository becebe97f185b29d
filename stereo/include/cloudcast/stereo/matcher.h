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
#include "cloudcast/core/stereo.h"

namespace cloudcast::stereo {

// The matchers and their parameters are core's StereoMatcher and StereoParams
// (cloudcast/core/stereo.h): the protocol, the server and the clients share them.

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

// The largest disparity the output can hold (core's kMaxStereoDisparity).
inline constexpr int kMaxDisparity = kMaxStereoDisparity;
// Our matcher keeps one byte per pixel and disparity for a frame; OpenCV's MODE_HH two. Frames
// whose volume would exceed this are refused (RESOURCE_EXHAUSTED) instead of allocated.
inline constexpr std::uint64_t kMaxCostVolumeBytes = std::uint64_t{1} << 30;

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
  virtual const StereoParams& params() const = 0;
};

// The threads OpenCV's matchers (and the rest of OpenCV) may use inside one call: cv::setNumThreads
// for the whole process. A server that runs one frame per core sets 1, so that OpenCV's pool does
// not oversubscribe the cores the other workers use.
void SetOpenCvThreads(int threads);

// Validates `params` and makes the matcher it names; `simd` picks our matcher's code
// (FAILED_PRECONDITION for a level this CPU lacks).
absl::StatusOr<std::unique_ptr<Matcher>> MakeMatcher(const StereoParams& params,
                                                     SimdLevel simd = SimdLevel::kAuto);

}  // namespace cloudcast::stereo
