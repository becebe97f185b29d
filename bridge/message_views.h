// The camera messages the bridges read, as views that either transport fills without copying
// pixels: ROS 1's sensor_msgs (ros/src/ros_messages.h) and ROS 2's DDS samples
// (ros2/src/ros2_messages.h). The members keep the messages' field names (ROS 1's spelling: P, K,
// T; ROS 2 spells them p, k, t), so that the conversions read as the message definitions.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace cloudcast::ros_bridge {

// A view of bytes in a message (uint8[] data).
struct ByteSpan {
  const std::uint8_t* ptr = nullptr;
  std::size_t length = 0;
  const std::uint8_t* data() const { return ptr; }
  std::size_t size() const { return length; }
};

// A message's stamp, as the 64 bits on the wire: ROS 1's time is (uint32 sec, uint32 nsec), ROS
// 2's builtin_interfaces/Time (int32 sec, uint32 nanosec); `sec` keeps either bit for bit, so
// that a cloud carries its input's stamp exactly (a negative ROS 2 time included).
struct MessageStamp {
  std::uint32_t sec = 0;
  std::uint32_t nsec = 0;
};

// The frame header, free of either transport (ROS 1's std_msgs::Header lives in ros/, ROS 2's in
// the DDS samples): what the cloud link keeps for each frame's reply (cloud_link.h). `seq` is ROS
// 1's (ROS 2 has none; 0 there).
struct MessageHeader {
  std::uint32_t seq = 0;
  MessageStamp stamp;
  std::string frame_id;
};

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
