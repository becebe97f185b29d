// Middlebury's "Aloe" stereo pair (2006 data set), as Debian's opencv-doc package installs it: a
// second data set that a fresh machine can always have (apt-get install opencv-doc).
#pragma once

#include <string>

#include "absl/status/statusor.h"
#include "cloudcast/datasets/stereo_frame.h"

namespace cloudcast::middlebury {

// /usr/share/doc/opencv-doc/examples/data, where opencv-doc puts aloeL.jpg, aloeR.jpg, aloeGT.png.
std::string AloeDir();
bool AloePresent(const std::string& dir = AloeDir());

// Aloe: 1282x1110, truth in px (0 = unknown, disparities 32 to 211). `half`: 641x555, as
// Middlebury makes its half-size versions: 2x2 means of the colours (rounded), the truth halved
// (rounded up; 0 stays 0) at the top-left pixel of each 2x2 block; disparities 16 to 106.
absl::StatusOr<StereoFrame> LoadAloe(const std::string& dir = AloeDir(), bool half = true);

}  // namespace cloudcast::middlebury
