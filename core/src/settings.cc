#include "cloudcast/core/settings.h"

#include <algorithm>
#include <string>

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
  return stereo.Validate(prefix + "stereo");
}

}  // namespace cloudcast
