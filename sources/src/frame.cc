#include "cloudcast/sources/frame.h"

#include <algorithm>

namespace cloudcast::sources {
namespace {

struct KindRow {
  FrameKind kind;
  const char* name;
  std::vector<ImageRole> roles;
};

// One row per kind: its name and its images. The first role names the frames of globs.
const std::vector<KindRow>& Kinds() {
  static const std::vector<KindRow> kinds = {
      {FrameKind::kDisparity, "disparity", {ImageRole::kDisparity, ImageRole::kColour}},
      {FrameKind::kDepth, "depth", {ImageRole::kDepth, ImageRole::kColour}},
      {FrameKind::kStereo, "stereo", {ImageRole::kColour, ImageRole::kRight}},
  };
  return kinds;
}

const KindRow& RowOf(FrameKind kind) {
  for (const KindRow& row : Kinds()) {
    if (row.kind == kind) return row;
  }
  return Kinds().front();
}

}  // namespace

const char* Name(ImageRole role) {
  switch (role) {
    case ImageRole::kDisparity:
      return "disparity";
    case ImageRole::kColour:
      return "colour";
    case ImageRole::kDepth:
      return "depth";
    case ImageRole::kRight:
      return "right";
  }
  return "?";
}

std::string RoleFlag(ImageRole role, const std::string& suffix) {
  return std::string("--") + Name(role) + suffix;
}

const char* Name(FrameKind kind) { return RowOf(kind).name; }

bool ParseFrameKind(std::string_view name, FrameKind* out) {
  for (const KindRow& row : Kinds()) {
    if (name == row.name) {
      *out = row.kind;
      return true;
    }
  }
  return false;
}

const std::vector<std::string>& FrameKindNames() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> v;
    for (const KindRow& row : Kinds()) v.emplace_back(row.name);
    return v;
  }();
  return names;
}

const std::vector<ImageRole>& RolesOf(FrameKind kind) { return RowOf(kind).roles; }

const cv::Mat& SourceFrame::image(ImageRole role) const {
  static const cv::Mat kNone;
  const std::vector<ImageRole>& roles = RolesOf(kind);
  const auto it = std::find(roles.begin(), roles.end(), role);
  const auto i = static_cast<std::size_t>(it - roles.begin());
  return it == roles.end() || i >= images.size() ? kNone : images[i];
}

}  // namespace cloudcast::sources
