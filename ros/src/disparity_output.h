// The server's disparity map of a stereo pair (CloudReply.disparity: DISPARITY_U16 in 1/16 pixel,
// 0 where nothing matched, zstd-compressed) as the stereo_msgs/DisparityImage that
// stereo_image_proc's disparity nodelet would publish (~stereo/publish_disparity).
#pragma once

#include <std_msgs/Header.h>
#include <stereo_msgs/DisparityImage.h>

#include "absl/status/status.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/core/frame_codec.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::ros_bridge {

// The matcher's search range, for the message's min_disparity and max_disparity.
struct DisparityRange {
  int min_disparity = 0;
  int num_disparities = 128;
};

// Decompresses `compressed` (with `decompressor`, reused from frame to frame) into `out`:
//   image          32FC1, the values / 16; where nothing matched, min_disparity - 1 (the message's
//                  "any disparity less than min_disparity is invalid", as stereo_image_proc
//                  writes it)
//   f, T           the camera's fx and baseline (Z = f T / d)
//   min/max        the matcher's range, [min_disparity, min_disparity + num_disparities - 1]
//   delta_d        1/16, the step of the server's fixed-point disparities
//   valid_window   the whole image (the server does not report the matcher's border)
// `header` is the left image's. Errors (a payload that is not a 16-bit disparity map or does not
// decompress) name "reply.disparity".
absl::Status ToDisparityImage(const v1::CompressedDisparity& compressed,
                              const std_msgs::Header& header, const CameraModel& camera,
                              const DisparityRange& range, PlaneDecompressor* decompressor,
                              stereo_msgs::DisparityImage* out);

}  // namespace cloudcast::ros_bridge
