// The stereo input (~input stereo) on ROS 1: its four subscribers, synchronized, and the shared
// conversion (frame_conversions.h: ToStereoFrame, with the camera model it applies).
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
