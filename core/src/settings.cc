#include "cloudcast/core/settings.h"

#include <algorithm>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"

namespace cloudcast {

PipelineOptions FrameSettings::PipelineFor(std::uint32_t width, std::uint32_t height) const {
  PipelineOptions o = pipeline;
  // Integer division on purpose: PCL puts the centre at static_cast<int>(width / 2).
  o.camera.cx = cx.value_or(static_cast<double>(width / 2));   // NOLINT(bugprone-integer-division)
  o.camera.cy = cy.value_or(static_cast<double>(height / 2));  // NOLINT(bugprone-integer-division)
  return o;
}

DracoOptions FrameSettings::Draco() const {
  DracoOptions d = draco;
  const VoxelGridParams& v = pipeline.voxel;
  d.max_position_error = max_position_error.value_or(
      v.enabled ? std::min({v.leaf_x, v.leaf_y, v.leaf_z}) / 4.0f : 0.0f);
  return d;
}

absl::Status FrameSettings::Validate(std::string_view field) const {
  const std::string prefix = field.empty() ? "" : std::string(field) + ".";
  // The principal point is checked as given; an unset one is the centre of a valid frame.
  if (auto s = PipelineFor(2, 2).Validate(field); !s.ok()) return s;
  if (auto s = Draco().Validate(prefix + "draco"); !s.ok()) return s;
  if (auto s =
          ValidateCapMinPoints(cap_min_points_per_voxel, prefix + "draco.cap_min_points_per_voxel");
      !s.ok()) {
    return s;
  }
  return stereo.Validate(prefix + "stereo");
}

absl::Status FrameSettings::ValidateCapMinPoints(std::uint32_t value, std::string_view field) {
  if (value <= kMaxCapMinPoints) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(std::string(field), " is ", value,
                                                 "; it must be in [0, ", kMaxCapMinPoints,
                                                 "] (0: the cap never drops voxels)"));
}

const std::vector<std::string>& PresetNames() {
  static const std::vector<std::string> names = {"new_tsukuba"};
  return names;
}

absl::Status ApplyPreset(std::string_view name, FrameSettings* settings, std::string_view field,
                         bool with_passthrough) {
  if (name != "new_tsukuba") {
    return absl::InvalidArgumentError(absl::StrCat(std::string(field), " is \"", std::string(name),
                                                   "\"; it must be one of ",
                                                   absl::StrJoin(PresetNames(), ", ")));
  }
  CameraModel& camera = settings->pipeline.camera;
  const CameraModel pcl = CameraModel::PclCompatible(640, 480, 615.0);
  camera.fx = pcl.fx;
  camera.fy = pcl.fy;
  camera.baseline = pcl.baseline;
  camera.disparity_scale = pcl.disparity_scale;
  camera.disparity_offset = pcl.disparity_offset;
  camera.invalid_disparities = pcl.invalid_disparities;
  settings->cx.reset();  // the centre of each frame, as PCL
  settings->cy.reset();
  settings->focal_given = true;
  settings->baseline_given = true;
  if (with_passthrough) {
    PassThroughParams& pt = settings->pipeline.passthrough;
    pt.enabled = true;
    pt.axis = Axis::kZ;
    pt.min = 3.0f;
    pt.max = 12.0f;
    pt.negative = false;
  }
  return absl::OkStatus();
}

}  // namespace cloudcast
