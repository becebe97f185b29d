// The depth input (~input depth): a depth image registered to the colour camera + the colour
// image + its CameraInfo, the three topics of depth_image_proc's point_cloud_xyzrgb nodelet,
// turned into cloudcast frames.
//
// The image (REP 118): 16UC1 in millimetres or 32FC1 in metres (or whatever unit ~depth_scale
// says); 0, NaN and infinities are no measurement. The server computes the points by
// depth_image_proc's own formula, in its order of float operations:
//   z = D * float(s),  x = ((u - cx) * D) * float(s / fx),  y = ((v - cy) * D) * float(s / fy)
// with fx, fy, cx, cy from the CameraInfo's P (image_geometry's), or K when P is all zero.
// One difference: for a 32FC1 depth of exactly 0.0 depth_image_proc publishes a point at the
// camera's origin; REP 118 calls it no reading, and cloudcast gives no point.
#pragma once

#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "cloudcast/client/frame.h"
#include "cloudcast/core/camera.h"
#include "image_messages.h"
#include "input_source.h"

namespace cloudcast::ros_bridge {

// The topics, relative to the node's namespace (remap them to the camera's).
inline constexpr const char* kDepthTopic = "depth_registered/image_rect";
inline constexpr const char* kDepthColourTopic = "rgb/image_rect_color";
inline constexpr const char* kDepthInfoTopic = "rgb/camera_info";

// The camera model of a depth image and the CameraInfo of its pixels (the colour camera's, for a
// registered depth image): the intrinsics, and `depth_scale` (unset: REP 118's unit for the
// encoding). Errors name the topic's field.
absl::StatusOr<CameraModel> CameraFromDepth(const sensor_msgs::Image& depth,
                                            const sensor_msgs::CameraInfo& info,
                                            std::optional<double> depth_scale);

// A view of the depth pixels in the message (16UC1 or 32FC1, little endian), no copy: the
// server reads 0, NaN and infinities as no measurement, so nothing needs masking.
absl::StatusOr<DepthView> DepthFromImage(const sensor_msgs::Image& depth);

// One synchronized set of messages as a frame: the camera, the depth and colour views and the
// depth image's header. The depth and colour images must be of the same size and frame_id (as
// depth_image_proc requires). Errors name the topic and field.
absl::Status ToDepthFrame(const sensor_msgs::Image& depth, const sensor_msgs::Image& colour,
                          const sensor_msgs::CameraInfo& info, std::optional<double> depth_scale,
                          OutgoingFrame* frame);

// The three subscribers, synchronized, and ToDepthFrame.
class DepthInput : public InputSource {
 public:
  DepthInput(ros::NodeHandle& nh, const SyncOptions& sync, std::optional<double> depth_scale,
             Sink sink, ErrorSink error_sink);
  std::string Describe() const override { return sync_.Describe(); }

 private:
  void OnMessages(const sensor_msgs::Image::ConstPtr& depth,
                  const sensor_msgs::Image::ConstPtr& colour,
                  const sensor_msgs::CameraInfo::ConstPtr& info);

  const std::optional<double> depth_scale_;
  Sink sink_;
  ErrorSink error_sink_;
  TopicSync<sensor_msgs::Image, sensor_msgs::Image, sensor_msgs::CameraInfo> sync_;
};

}  // namespace cloudcast::ros_bridge
