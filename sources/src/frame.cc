#include "cloudcast/sources/frame.h"

#include <algorithm>

namespace cloudcast::sources {

const char* Name(ImageRole role) {
  switch (role) {
    case ImageRole::kDisparity:
      return "disparity";
    case ImageRole::kColour:
      return "colour";
  }
  return "?";
}

const char* Name(FrameKind kind) {
  switch (kind) {
    case FrameKind::kDisparity:
      return "disparity";
  }
  return "?";
}

const std::vector<ImageRole>& RolesOf(FrameKind kind) {
  static const std::vector<ImageRole> kDisparityColour = {ImageRole::kDisparity,
                                                          ImageRole::kColour};
  switch (kind) {
    case FrameKind::kDisparity:
      return kDisparityColour;
  }
  return kDisparityColour;
}

const cv::Mat& SourceFrame::image(ImageRole role) const {
  static const cv::Mat kNone;
  const std::vector<ImageRole>& roles = RolesOf(kind);
  const auto it = std::find(roles.begin(), roles.end(), role);
  const auto i = static_cast<std::size_t>(it - roles.begin());
  return it == roles.end() || i >= images.size() ? kNone : images[i];
}

}  // namespace cloudcast::sources
