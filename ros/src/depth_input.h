// The depth input (~input depth) on ROS 1: its three subscribers, synchronized, and the shared
// conversion (frame_conversions.h: ToDepthFrame, with the camera model it applies).
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
