// ROS 2's DDS samples (the idlc structs of ros2/idl/ros2_messages.idl) as the shared core's views
// (bridge/message_views.h), and the bridge's outputs (PointCloud2, DiagnosticArray) as samples.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "cloudcast/core/point.h"
#include "diagnostics.h"
#include "message_types.h"
#include "message_views.h"

namespace cloudcast::ros2_bridge {

// The header of a ROS 2 message as the core's (ROS 1's) header: sec is kept bit for bit (a
// negative ROS 2 time survives the round trip through FromHeader).
ros_bridge::MessageHeader ToHeader(const std_msgs_msg_dds__Header_& header);
ros_bridge::ImageMsg View(const sensor_msgs_msg_dds__Image_& image);
ros_bridge::CameraInfoMsg View(const sensor_msgs_msg_dds__CameraInfo_& info);
ros_bridge::DisparityImageMsg View(const stereo_msgs_msg_dds__DisparityImage_& disparity);

// A sensor_msgs/PointCloud2 sample of a cloud (bridge/point_cloud_layout.h), owning its storage.
class PointCloud2Sample {
 public:
  PointCloud2Sample(const PointCloud& cloud, const ros_bridge::MessageHeader& header);
  PointCloud2Sample(const PointCloud2Sample&) = delete;
  PointCloud2Sample& operator=(const PointCloud2Sample&) = delete;
  const sensor_msgs_msg_dds__PointCloud2_* sample() const { return &msg_; }

 private:
  std::string frame_id_;
  std::vector<sensor_msgs_msg_dds__PointField_> fields_;
  std::vector<std::uint8_t> data_;
  sensor_msgs_msg_dds__PointCloud2_ msg_{};
};

// A diagnostic_msgs/DiagnosticArray sample of one report, stamped `sec`.`nanosec`.
class DiagnosticArraySample {
 public:
  DiagnosticArraySample(const ros_bridge::DiagnosticReport& report, std::int32_t sec,
                        std::uint32_t nanosec);
  DiagnosticArraySample(const DiagnosticArraySample&) = delete;
  DiagnosticArraySample& operator=(const DiagnosticArraySample&) = delete;
  const diagnostic_msgs_msg_dds__DiagnosticArray_* sample() const { return &msg_; }

 private:
  ros_bridge::DiagnosticReport report_;  // the strings the sample points to
  std::vector<diagnostic_msgs_msg_dds__KeyValue_> values_;
  diagnostic_msgs_msg_dds__DiagnosticStatus_ status_{};
  diagnostic_msgs_msg_dds__DiagnosticArray_ msg_{};
};

}  // namespace cloudcast::ros2_bridge
