// ROS 1's camera messages as the shared core's views (bridge/message_views.h), and the core's
// conversions over ROS 1 messages: the views point into the messages, nothing is copied.
#pragma once

#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <stereo_msgs/DisparityImage.h>

#include <optional>
#include <vector>

#include "frame_conversions.h"
#include "message_views.h"

namespace cloudcast::ros_bridge {

// ROS 1's header as the core's (transport-free) one and back, bit for bit.
MessageHeader FromRos(const std_msgs::Header& header);
std_msgs::Header ToRos(const MessageHeader& header);

ImageMsg View(const sensor_msgs::Image& image);
CameraInfoMsg View(const sensor_msgs::CameraInfo& info);
DisparityImageMsg View(const stereo_msgs::DisparityImage& disparity);

inline absl::StatusOr<client::ColorInput> ColourFromImage(const sensor_msgs::Image& image,
                                                          const std::string& topic) {
  return ColourFromImage(View(image), topic);
}
inline absl::StatusOr<CameraModel> CameraFromDisparity(
    const stereo_msgs::DisparityImage& disparity, const sensor_msgs::CameraInfo& info) {
  return CameraFromDisparity(View(disparity), View(info));
}
inline absl::StatusOr<DisparityView> MaskedDisparity(const stereo_msgs::DisparityImage& disparity,
                                                     std::vector<float>* buffer) {
  return MaskedDisparity(View(disparity), buffer);
}
inline absl::Status ToFrame(const stereo_msgs::DisparityImage& disparity,
                            const sensor_msgs::Image& colour, const sensor_msgs::CameraInfo& info,
                            std::vector<float>* buffer, OutgoingFrame* frame) {
  return ToFrame(View(disparity), View(colour), View(info), buffer, frame);
}
inline absl::StatusOr<CameraModel> CameraFromDepth(const sensor_msgs::Image& depth,
                                                   const sensor_msgs::CameraInfo& info,
                                                   std::optional<double> depth_scale) {
  return CameraFromDepth(View(depth), View(info), depth_scale);
}
inline absl::StatusOr<DepthView> DepthFromImage(const sensor_msgs::Image& depth) {
  return DepthFromImage(View(depth));
}
inline absl::Status ToDepthFrame(const sensor_msgs::Image& depth, const sensor_msgs::Image& colour,
                                 const sensor_msgs::CameraInfo& info,
                                 std::optional<double> depth_scale, OutgoingFrame* frame) {
  return ToDepthFrame(View(depth), View(colour), View(info), depth_scale, frame);
}
inline absl::StatusOr<CameraModel> CameraFromStereo(const sensor_msgs::CameraInfo& left_info,
                                                    const sensor_msgs::CameraInfo& right_info,
                                                    std::uint32_t width, std::uint32_t height) {
  return CameraFromStereo(View(left_info), View(right_info), width, height);
}
inline absl::Status ToStereoFrame(const sensor_msgs::Image& left, const sensor_msgs::Image& right,
                                  const sensor_msgs::CameraInfo& left_info,
                                  const sensor_msgs::CameraInfo& right_info,
                                  OutgoingFrame* frame) {
  return ToStereoFrame(View(left), View(right), View(left_info), View(right_info), frame);
}

}  // namespace cloudcast::ros_bridge
