// The disparity input (~input disparity): stereo_msgs/DisparityImage + the left colour image +
// the left CameraInfo, as stereo_image_proc's point_cloud2 nodelet takes them, turned into
// cloudcast frames.
//
// The camera model (stereo_msgs/DisparityImage.msg: "for disparity d, the depth from the camera
// is Z = fT/d"; the disparities are pre-adjusted for the principal points' x-offset):
//   fx, fy, cx, cy   from the CameraInfo's projection matrix P (the rectified camera)
//   baseline         f * T / fx, so that cloudcast's z = fx * baseline / d is f T / d
//   x = (u - cx) z / fx, y = (v - cy) z / fy, as image_geometry's reprojection
// Invalid pixels ("any disparity less than min_disparity is invalid"; stereo_image_proc writes
// min_disparity - 1 there): values below min_disparity, NaN and infinities give no point; so does
// d <= 0 (no finite depth), as in cloudcast's model.
#pragma once

#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <stereo_msgs/DisparityImage.h>

#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "cloudcast/client/frame.h"
#include "cloudcast/core/camera.h"
#include "image_messages.h"
#include "input_source.h"

namespace cloudcast::ros_bridge {

// The camera model of a DisparityImage and the CameraInfo of its (left, rectified) camera. Errors
// name the topic's field: an uncalibrated CameraInfo (P all zero), sizes that differ, f or T not
// finite and positive.
absl::StatusOr<CameraModel> CameraFromDisparity(const stereo_msgs::DisparityImage& disparity,
                                                const sensor_msgs::CameraInfo& info);

// The disparities of `disparity` (32FC1, little endian) with every invalid value (below
// min_disparity, or not finite) replaced by NaN, in `buffer` (reused from frame to frame): the one
// copy of the pixels the bridge makes before the client library's own.
absl::StatusOr<DisparityView> MaskedDisparity(const stereo_msgs::DisparityImage& disparity,
                                              std::vector<float>* buffer);

// One synchronized set of messages as a frame: the camera, the masked disparities (in
// `buffer`), the colour view and the disparity's header. Errors name the topic and field.
absl::Status ToFrame(const stereo_msgs::DisparityImage& disparity, const sensor_msgs::Image& colour,
                     const sensor_msgs::CameraInfo& info, std::vector<float>* buffer,
                     OutgoingFrame* frame);

// The three subscribers, synchronized, and ToFrame.
class DisparityInput : public InputSource {
 public:
  // Topics relative to `nh`: "disparity", "left/image_rect_color", "left/camera_info".
  DisparityInput(ros::NodeHandle& nh, const SyncOptions& sync, Sink sink, ErrorSink error_sink);
  std::string Describe() const override { return sync_.Describe(); }

 private:
  void OnMessages(const stereo_msgs::DisparityImage::ConstPtr& disparity,
                  const sensor_msgs::Image::ConstPtr& colour,
                  const sensor_msgs::CameraInfo::ConstPtr& info);

  Sink sink_;
  ErrorSink error_sink_;
  std::vector<float> masked_;  // the masked disparities of the frame being sent
  TopicSync<stereo_msgs::DisparityImage, sensor_msgs::Image, sensor_msgs::CameraInfo> sync_;
};

}  // namespace cloudcast::ros_bridge
