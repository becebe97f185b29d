// A stereo pair with its ground truth, as the data sets (tsukuba.h, middlebury.h) load it.
#pragma once

#include <string>

#include "cloudcast/io/image_io.h"

namespace cloudcast {

struct StereoFrame {
  std::string id;
  OwnedColor left;       // BGR8
  OwnedColor right;      // BGR8, rectified with the left one
  OwnedDisparity truth;  // the left image's disparity: 8-bit, px, 0 = unknown
};

}  // namespace cloudcast
