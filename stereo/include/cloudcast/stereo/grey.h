// Grey images for the matchers: what a robot sends (BGR8, RGB8, RGBA8 or mono8) to the 8-bit grey
// the matchers read. The points keep the left image's own colour; only matching uses grey.
#pragma once

#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/core/image.h"
#include "cloudcast/io/image_io.h"

namespace cloudcast::stereo {

// A grey image that owns its pixels (OwnedColor with kMono8, tightly packed rows).
using GreyImage = OwnedColor;

// `colour` to grey into `out` (resized; its buffer is reused between calls), with OpenCV's
// cv::cvtColor weights (0.299 R + 0.587 G + 0.114 B, rounded); mono8 is copied. The view is
// checked against Limits{} first; errors name `field`.
absl::Status ToGrey(const ColorView& colour, GreyImage* out, std::string_view field = "colour");
absl::StatusOr<GreyImage> ToGrey(const ColorView& colour, std::string_view field = "colour");

}  // namespace cloudcast::stereo
