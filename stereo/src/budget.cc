#include "cloudcast/stereo/budget.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <string>

#include "absl/strings/str_cat.h"

namespace cloudcast::stereo {
namespace {

using U64 = std::uint64_t;

U64 RoundUp(U64 v, U64 to) { return (v + to - 1) / to * to; }

// What every OpenCV SGBM mode adds to its own buffers: the int16 output, medianBlur's copy of it,
// and filterSpeckles' buffer (9 bytes a pixel), all for the whole image (stereosgbm.cpp:2214,
// 2226, 2349).
U64 SgbmCommonBytes(U64 w, U64 h) { return 13 * w * h + 10 * w + 4096; }

// OpenCV's StereoBM (stereobm.cpp:356-384, 1235-1237, 1291): all stripes' buffers at once,
// whatever the thread count; preFilterCap stays at its default (31).
U64 BmBytes(U64 w, U64 h, U64 d, U64 bs) {
  const bool small = bs <= 21;
  const double n0 = small ? 8e6 : 2e6;
  const U64 s = small ? 2 : 4;
  const double rows = std::min(std::max(n0 / static_cast<double>(w * d), 10.0 * (bs - 1)),
                               static_cast<double>(h));
  const U64 stripes = static_cast<U64>(std::ceil(static_cast<double>(h) / std::max(rows, 1.0)));
  return stripes * ((h + bs + 2) * (d * (bs + 2 + s) + 4) + s * (d + 2) + 260) + 23 * w * h +
         16 * w + 2048;
}

// Ours (sgm_matcher.cc, Prepare and Compute): one byte per cost of the whole frame (s1), the
// padded images, the census planes (at most 6 bytes a pixel, for a 7x7 window), three path rows
// of 4 paths, the minima, and the output.
U64 SgmBytes(U64 w, U64 h, U64 d, U64 span) {
  const U64 dp = RoundUp(d, 64);
  const U64 padded = 2 * ((w + 134) * (h + 6) + 128);
  const U64 planes = 6 * h * ((w + 64) + (span + w + dp + 192));
  const U64 rows = 3 * (128 + (w + 2) * 4 * dp);
  const U64 minima = 12 * (w + 130) + 3 * (w + 64) * 64;
  return w * h * dp + w * dp + padded + planes + rows + minima + 2 * w * h + 40 * (w + 1) +
         65536;
}

}  // namespace

absl::Status CheckMatchable(const StereoParams& params, std::uint32_t width, std::uint32_t height,
                            std::string_view field) {
  // Ours matches narrow pairs as it does wide ones (each pixel over the disparities its row
  // has; stereo_test holds its SIMD code to its scalar code there, the fuzzers run it).
  if (params.matcher == StereoMatcher::kSgm) return absl::OkStatus();
  const std::string f(field);
  const U64 span = static_cast<U64>(params.num_disparities) +
                   static_cast<U64>(std::abs(params.min_disparity)) +
                   static_cast<U64>(params.block_size);
  if (width <= span) {
    return absl::InvalidArgumentError(absl::StrCat(
        f, ".num_disparities is ", params.num_disparities, " (with min_disparity ",
        params.min_disparity, " and block_size ", params.block_size, "): a pair ", width,
        " pixels wide must be wider than num_disparities + |min_disparity| + block_size = ", span,
        ", so that some left pixel has its whole disparity range and block in the right image; "
        "send fewer disparities or wider images"));
  }
  if (params.matcher == StereoMatcher::kOpenCvBm && static_cast<U64>(params.block_size) >= height) {
    return absl::InvalidArgumentError(
        absl::StrCat(f, ".block_size is ", params.block_size, "; OpenCV's StereoBM needs it below "
                     "the image height (", height, ")"));
  }
  return absl::OkStatus();
}

std::uint64_t MatchWorkBytes(const StereoParams& params, std::uint32_t width,
                             std::uint32_t height) {
  const U64 w = width, h = height;
  const U64 d = static_cast<U64>(std::max(params.num_disparities, 0));
  const U64 bs = static_cast<U64>(std::max(params.block_size, 1));
  const U64 span = static_cast<U64>(std::abs(params.min_disparity));
  // OpenCV's columns with a whole disparity range (width1 <= w - D), and its cost vectors'
  // length rounded up to the SIMD lanes (stereosgbm.cpp: Da, at most 16 lanes of int16).
  const U64 w1 = w > d ? w - d : 0;
  const U64 da = d + 15;
  const U64 lr = 16 * (w + 4) * (d + 16);  // the path buffers Lr and minLr, two rows of 8 paths
  switch (params.matcher) {
    case StereoMatcher::kSgm:
      return SgmBytes(w, h, d, span);
    case StereoMatcher::kOpenCvSgbm:  // C and S for one row, the block's rows of sums
      return 2 * w1 * da * (bs + 5) + lr + SgbmCommonBytes(w, h);
    case StereoMatcher::kOpenCvHH:  // C and S for every row (the full dynamic programming)
      return 2 * w1 * da * (2 * h + bs + 3) + lr + SgbmCommonBytes(w, h);
    case StereoMatcher::kOpenCvSgbm3Way:  // one stripe's sums at a time, four output strips
      return 2 * da * (w1 + 1) * (bs + 7) + 4 * w * bs + 16 * w * h + 40 * w + 4096 +
             SgbmCommonBytes(w, h);
    case StereoMatcher::kOpenCvBm:
      return BmBytes(w, h, d, bs);
  }
  return 0;
}

std::uint64_t MatchVolume(const StereoParams& params, std::uint32_t width, std::uint32_t height) {
  const U64 d = static_cast<U64>(std::max(params.num_disparities, 0));
  const U64 bs = static_cast<U64>(std::max(params.block_size, 1));
  return U64{width} * (U64{height} + 8 * bs) * d;
}

}  // namespace cloudcast::stereo
