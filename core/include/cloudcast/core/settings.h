// Everything that turns frames into compressed clouds, as a service or a tool holds it between
// frames of any size: the pipeline's options, the Draco options, and the two values that follow
// each frame unless they are set (the principal point and the Draco error bound). The defaults
// are the core structs' own, so there is one place for each default.
#pragma once

#include <cstdint>
#include <optional>
#include <string_view>

#include "absl/status/status.h"
#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/core/stereo.h"

namespace cloudcast {

struct FrameSettings {
  // camera.cx and camera.cy are ignored: see cx and cy below.
  PipelineOptions pipeline;
  // draco.max_position_error is ignored: see max_position_error below.
  DracoOptions draco;
  // Frames that are stereo pairs: how they are matched (and rectified).
  StereoParams stereo;
  // Unset: (width / 2, height / 2) of each frame in integer division, where PCL puts it.
  std::optional<double> cx;
  std::optional<double> cy;
  // Unset: a quarter of the smallest voxel leaf while the voxel grid is on (each decoded point
  // stays within a quarter of its voxel), and no bound while it is off. 0: no bound.
  std::optional<float> max_position_error;

  // The pipeline options for a width x height frame.
  PipelineOptions PipelineFor(std::uint32_t width, std::uint32_t height) const;
  // The Draco options with the error bound resolved.
  DracoOptions Draco() const;

  // Everything in range, for any frame size; errors name the member under `field`.
  absl::Status Validate(std::string_view field = "") const;
};

}  // namespace cloudcast
