// Reading one image of a frame, by its role: the checks each role's files and videos get.
// A new role gets its rules here (internal to cloudcast_sources).
#pragma once

#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/sources/frame.h"

namespace cloudcast::sources::internal {

// The paths of `paths` for each role of `kind`, in RolesOf order; InvalidArgument naming the flag
// of a role that has none, or of a role the kind does not have (`suffix` makes the flags:
// "-glob" gives --disparity-glob).
absl::StatusOr<std::vector<std::string>> PathsPerRole(FrameKind kind, const RolePaths& paths,
                                                      const std::string& suffix);

// Reads the file `path` as `role` needs it: a disparity unchanged (one channel, 8U, 16U or 32F;
// any conversion would scale its values), colour as 8-bit BGR. Errors start with `flag` and
// name the file: NotFound for a missing one, InvalidArgument for one that does not decode or
// does not fit the role.
absl::StatusOr<cv::Mat> ReadImage(ImageRole role, const std::string& path, const std::string& flag);

// The depth (CV_32FC1, z = fx * baseline / d in the baseline's unit, 0 where there is no
// disparity) that `disparity` gives through `camera` (its scale and offset applied): the same z
// the server computes from the disparity, so both kinds of one frame give one cloud.
cv::Mat DepthFromDisparity(const cv::Mat& disparity, const CameraModel& camera);

// Whether a video of `role` must keep its values exactly (a lossy codec is warned about).
bool NeedsLosslessVideo(ImageRole role);

// A decoded video frame as `role` needs it: a disparity back to one channel (decoders give grey
// videos back as BGR; on the `first` frame, unequal channels add a warning), colour to 8 bits.
absl::StatusOr<cv::Mat> FromVideo(ImageRole role, cv::Mat frame, const std::string& flag,
                                  const std::string& path, bool first,
                                  std::vector<std::string>* warnings);

// A frame's images (of `kind`, read from `paths`) all have one size; the error names two that
// differ.
absl::Status CheckSameSize(FrameKind kind, const std::vector<cv::Mat>& images,
                           const std::vector<std::string>& paths);

}  // namespace cloudcast::sources::internal
