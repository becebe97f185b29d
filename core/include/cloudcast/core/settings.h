// Everything that turns frames into compressed clouds, as a service or a tool holds it between
// frames of any size: the pipeline's options, the Draco options, and the two values that follow
// each frame unless they are set (the principal point and the Draco error bound). The defaults
// are the core structs' own, so there is one place for each default.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

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
  // Whether the camera's focal length and baseline were given (by a client, an operator or a
  // preset) rather than left at CameraModel's values. The contract assumes no data set's camera
  // (convert::ContractDefaults clears both); the core's own programs start from a given camera.
  bool focal_given = true;
  bool baseline_given = true;
  // The downlink cap's last resort (contract revision 5): a cloud still over
  // draco.max_cloud_bytes at the floors of both bit depths loses the voxels of fewest points,
  // the voxel grid's minimum raised one point at a time up to this many (never to an empty
  // cloud). 0: never; every voxel pipeline.voxel keeps comes back. At most kMaxCapMinPoints.
  std::uint32_t cap_min_points_per_voxel = 0;
  static constexpr std::uint32_t kMaxCapMinPoints = 64;
  // The range rule of cap_min_points_per_voxel, for every place that reads it (programs' flags,
  // the contract's DracoConfig); the error names `field`.
  static absl::Status ValidateCapMinPoints(std::uint32_t value, std::string_view field);

  // The pipeline options for a width x height frame.
  PipelineOptions PipelineFor(std::uint32_t width, std::uint32_t height) const;
  // The Draco options with the error bound resolved.
  DracoOptions Draco() const;

  // Everything in range, for any frame size; errors name the member under `field`.
  absl::Status Validate(std::string_view field = "") const;
};

// Named settings for a known camera, for programs and clients that stream one. Each sets the
// camera (focal length, baseline, invalid values; the principal point stays the image centre)
// and the depth range it was published with:
//   new_tsukuba  the paper's: New Tsukuba's ground-truth disparities through PCL's conversion,
//                fx = fy = 615, baseline 1 (z = 615 / d), 0 and 2047 invalid, passthrough z in
//                [3, 12].
// The names, for --help and errors.
const std::vector<std::string>& PresetNames();
// Applies preset `name` to `settings`; INVALID_ARGUMENT naming `field` for an unknown name.
// `with_passthrough` false keeps `settings`' passthrough (a caller that was given one).
absl::Status ApplyPreset(std::string_view name, FrameSettings* settings,
                         std::string_view field = "preset", bool with_passthrough = true);

}  // namespace cloudcast
