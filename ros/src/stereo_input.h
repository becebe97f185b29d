// The stereo input (~input stereo): the rectified left and right images of a stereo camera and
// both CameraInfos (the four topics stereo_image_proc's disparity nodelet takes, the left one in
// colour so that the points have it), sent as stereo pairs that the server matches
// (StreamConfig.stereo, ~stereo/... parameters).
//
// The camera model, from the rectified cameras' projection matrices (REP 104, CameraInfo.msg):
//   fx, fy, cx, cy   the left P (P[0], P[5], P[2], P[6])
//   baseline         -P_right[3] / P_right[0] (the right P's Tx = -fx' * B), so that
//                    z = fx * baseline / d is image_geometry's f T / d
// The server's matcher gives d = u_left - u_right, which is the disparity only when both
// rectified cameras have the same intrinsics: a right P with another fx, fy, cx or cy is refused
// (stereo_image_proc would shift its disparities by cx - cx'; OpenCV's stereoRectify with
// CALIB_ZERO_DISPARITY, as ROS's camera_calibration runs it, makes them equal).
#pragma once

#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <string>

#include "absl/status/statusor.h"
#include "cloudcast/client/frame.h"
#include "cloudcast/core/camera.h"
#include "image_messages.h"
#include "input_source.h"

namespace cloudcast::ros_bridge {

// The topics, relative to the node's namespace (the camera's; remap e.g. right/image_rect to
// right/image_rect_color for a colour right image, or left/image_rect_color to left/image_rect).
inline constexpr const char* kLeftTopic = "left/image_rect_color";
inline constexpr const char* kRightTopic = "right/image_rect";
inline constexpr const char* kLeftInfoTopic = "left/camera_info";
inline constexpr const char* kRightInfoTopic = "right/camera_info";

// The camera model of a rectified pair of `width` x `height` images from its two CameraInfos.
// Errors name the topic's field.
absl::StatusOr<CameraModel> CameraFromStereo(const sensor_msgs::CameraInfo& left_info,
                                             const sensor_msgs::CameraInfo& right_info,
                                             std::uint32_t width, std::uint32_t height);

// One synchronized set of messages as a frame: the camera, the two image views (rgb8, bgr8,
// rgba8, bgra8 or mono8 each; the server matches their grey, the points take the left one's
// colour) and the left image's header. Errors name the topic and field.
absl::Status ToStereoFrame(const sensor_msgs::Image& left, const sensor_msgs::Image& right,
                           const sensor_msgs::CameraInfo& left_info,
                           const sensor_msgs::CameraInfo& right_info, OutgoingFrame* frame);

// The four subscribers, synchronized, and ToStereoFrame.
class StereoInput : public InputSource {
 public:
  StereoInput(ros::NodeHandle& nh, const SyncOptions& sync, Sink sink, ErrorSink error_sink);
  std::string Describe() const override { return sync_.Describe(); }

 private:
  void OnMessages(const sensor_msgs::Image::ConstPtr& left,
                  const sensor_msgs::Image::ConstPtr& right,
                  const sensor_msgs::CameraInfo::ConstPtr& left_info,
                  const sensor_msgs::CameraInfo::ConstPtr& right_info);

  Sink sink_;
  ErrorSink error_sink_;
  TopicSync<sensor_msgs::Image, sensor_msgs::Image, sensor_msgs::CameraInfo,
            sensor_msgs::CameraInfo>
      sync_;
};

}  // namespace cloudcast::ros_bridge
