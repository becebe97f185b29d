// New Tsukuba frames as the ROS 2 messages a calibrated stereo camera publishes, as the ROS 1
// tests' publisher makes them (ros/testing/tsukuba_publisher.py): 640x480, f = 615, T = 0.1 m,
// the ground-truth disparity as a 32FC1 DisparityImage (0, no disparity, as min_disparity - 1),
// the left colour as bgr8, the left CameraInfo (P = [f 0 cx 0; 0 f cy 0; 0 0 1 0]); with AddRight
// the stereo input's other half, the right image in grey (mono8) and the right CameraInfo (the
// right P's Tx = -f B).
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "cloudcast/datasets/tsukuba.h"
#include "cloudcast/io/image_io.h"
#include "message_types.h"

namespace cloudcast::ros2_bridge::testing {

inline constexpr double kF = 615.0, kBaseline = 0.1, kCx = 320.0, kCy = 240.0;
inline constexpr float kMinDisparity = 4.0f;
inline constexpr const char* kFrameId = "tsukuba_left_optical";

// One frame's three messages, owning what they point to (not copyable: the samples point into
// the members).
class TsukubaSamples {
 public:
  explicit TsukubaSamples(const tsukuba::Frame& frame) {
    const std::size_t n = std::size_t{frame.disparity.width} * frame.disparity.height;
    disparity_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint8_t d = frame.disparity.pixels[i];
      disparity_[i] = d == 0 ? kMinDisparity - 1.0f : static_cast<float>(d);
    }
    colour_ = frame.colour.pixels;
    disparity.image = Image(frame.disparity.width, frame.disparity.height, "32FC1", 4,
                            reinterpret_cast<std::uint8_t*>(disparity_.data()), n * 4);
    disparity.f = static_cast<float>(kF);
    disparity.t = static_cast<float>(kBaseline);
    disparity.valid_window.width = frame.disparity.width;
    disparity.valid_window.height = frame.disparity.height;
    disparity.min_disparity = kMinDisparity;
    disparity.max_disparity = 255.0f;
    disparity.delta_d = 1.0f;
    colour = Image(frame.colour.width, frame.colour.height, "bgr8", 3, colour_.data(),
                   colour_.size());
    depth_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint8_t d = frame.disparity.pixels[i];
      depth_[i] = d == 0 ? 0 : static_cast<std::uint16_t>(std::lround(kF * kBaseline / d * 1000.0));
    }
    depth = Image(frame.disparity.width, frame.disparity.height, "16UC1", 2,
                  reinterpret_cast<std::uint8_t*>(depth_.data()), n * 2);
    info.height = frame.colour.height;
    info.width = frame.colour.width;
    info.distortion_model = const_cast<char*>("plumb_bob");
    d_.assign(5, 0.0);
    info.d._buffer = d_.data();
    info.d._length = info.d._maximum = 5;
    const double k[9] = {kF, 0, kCx, 0, kF, kCy, 0, 0, 1};
    const double r[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    const double p[12] = {kF, 0, kCx, 0, 0, kF, kCy, 0, 0, 0, 1, 0};
    std::copy(k, k + 9, info.k);
    std::copy(r, r + 9, info.r);
    std::copy(p, p + 12, info.p);
    Stamp(0, 0);
  }

  // The right image of the pair (BGR8, rectified with the left one), published in grey as a
  // stereo camera's right/image_rect is (ITU-R BT.601 weights, rounded: cv::COLOR_BGR2GRAY's to
  // within one level), and the right CameraInfo.
  void AddRight(const OwnedColor& bgr) {
    const std::size_t n = std::size_t{bgr.width} * bgr.height;
    right_grey_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint8_t* px = &bgr.pixels[3 * i];
      right_grey_[i] =
          static_cast<std::uint8_t>((114 * px[0] + 587 * px[1] + 299 * px[2] + 500) / 1000);
    }
    right = Image(bgr.width, bgr.height, "mono8", 1, right_grey_.data(), n);
    right_info = info;
    right_info.p[3] = -kF * kBaseline;
    Stamp(info.header.stamp.sec, info.header.stamp.nanosec);
  }
  TsukubaSamples(const TsukubaSamples&) = delete;
  TsukubaSamples& operator=(const TsukubaSamples&) = delete;

  // Every message of the frame gets the same stamp (exact-time sync pairs them).
  void Stamp(std::int32_t sec, std::uint32_t nanosec) {
    for (std_msgs_msg_dds__Header_* h :
         {&disparity.header, &disparity.image.header, &colour.header, &info.header,
          &depth.header, &right.header, &right_info.header}) {
      h->stamp.sec = sec;
      h->stamp.nanosec = nanosec;
      h->frame_id = const_cast<char*>(kFrameId);
    }
  }

  stereo_msgs_msg_dds__DisparityImage_ disparity{};
  sensor_msgs_msg_dds__Image_ colour{};
  sensor_msgs_msg_dds__CameraInfo_ info{};
  // The ground truth as a depth camera's 16UC1 image registered to the colour camera (the ROS 1
  // publisher's depth16): z = f B / d in millimetres, rounded; d = 0 gives 0 (no measurement).
  sensor_msgs_msg_dds__Image_ depth{};
  // After AddRight: the right image (mono8) and CameraInfo of the pair.
  sensor_msgs_msg_dds__Image_ right{};
  sensor_msgs_msg_dds__CameraInfo_ right_info{};

 private:
  static sensor_msgs_msg_dds__Image_ Image(std::uint32_t w, std::uint32_t h, const char* encoding,
                                           std::uint32_t bytes_per_pixel, std::uint8_t* data,
                                           std::size_t size) {
    sensor_msgs_msg_dds__Image_ image{};
    image.width = w;
    image.height = h;
    image.encoding = const_cast<char*>(encoding);
    image.is_bigendian = 0;
    image.step = w * bytes_per_pixel;
    image.data._buffer = data;
    image.data._length = image.data._maximum = static_cast<std::uint32_t>(size);
    return image;
  }
  std::vector<float> disparity_;
  std::vector<std::uint16_t> depth_;
  std::vector<std::uint8_t> colour_;
  std::vector<std::uint8_t> right_grey_;
  std::vector<double> d_;
};

}  // namespace cloudcast::ros2_bridge::testing
