// The disparity input (~input disparity) on ROS 1: its three subscribers, synchronized, and the
// shared conversion (frame_conversions.h: ToFrame, with the camera model it applies).
#pragma once

#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <stereo_msgs/DisparityImage.h>

#include <optional>
#include <string>
#include <vector>

#include "input_source.h"
#include "ros_messages.h"
#include "topic_sync.h"

namespace cloudcast::ros_bridge {

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
