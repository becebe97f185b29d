// The camera messages the bridges read, as views that either transport fills without copying
// pixels: ROS 1's sensor_msgs (ros/src/ros_messages.h) and ROS 2's DDS samples
// (ros2/src/ros2_messages.h). The members keep the messages' field names (ROS 1's spelling: P, K,
// T; ROS 2 spells them p, k, t), so that the conversions read as the message definitions.
#pragma once

#include <std_msgs/Header.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <string_view>

namespace cloudcast::ros_bridge {

// A view of bytes in a message (uint8[] data).
struct ByteSpan {
  const std::uint8_t* ptr = nullptr;
  std::size_t length = 0;
  const std::uint8_t* data() const { return ptr; }
  std::size_t size() const { return length; }
};

// The frame header: ROS 1's std_msgs/Header, which the cloud link keeps for each frame's reply
// (cloud_link.h); a ROS 2 header (int32 sec, uint32 nanosec, frame_id) fits it bit for bit.
using MessageHeader = std_msgs::Header;

// sensor_msgs/Image.
struct ImageMsg {
  MessageHeader header;
  std::uint32_t height = 0, width = 0;
  std::string_view encoding;
  std::uint8_t is_bigendian = 0;
  std::uint32_t step = 0;
  ByteSpan data;
};

// sensor_msgs/RegionOfInterest (the members the conversions read).
struct RoiMsg {
  std::uint32_t width = 0, height = 0;
};

// sensor_msgs/CameraInfo (the members the conversions read).
struct CameraInfoMsg {
  std::uint32_t height = 0, width = 0;
  std::array<double, 9> K{};
  std::array<double, 12> P{};
  std::uint32_t binning_x = 0, binning_y = 0;
  RoiMsg roi;
};

// stereo_msgs/DisparityImage (the members the conversions read).
struct DisparityImageMsg {
  MessageHeader header;
  ImageMsg image;
  float f = 0, T = 0;
  float min_disparity = 0;
};

// REP 118 and sensor_msgs/image_encodings.h's names of the encodings the bridges take.
namespace encodings {
inline constexpr std::string_view kRgb8 = "rgb8", kBgr8 = "bgr8", kRgba8 = "rgba8",
                                  kBgra8 = "bgra8", kMono8 = "mono8", k16UC1 = "16UC1",
                                  k32FC1 = "32FC1";
}  // namespace encodings

}  // namespace cloudcast::ros_bridge
