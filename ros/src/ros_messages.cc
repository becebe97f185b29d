#include "ros_messages.h"

#include <algorithm>

namespace cloudcast::ros_bridge {

MessageHeader FromRos(const std_msgs::Header& header) {
  MessageHeader out;
  out.seq = header.seq;
  out.stamp.sec = header.stamp.sec;
  out.stamp.nsec = header.stamp.nsec;
  out.frame_id = header.frame_id;
  return out;
}

std_msgs::Header ToRos(const MessageHeader& header) {
  std_msgs::Header out;
  out.seq = header.seq;
  out.stamp.sec = header.stamp.sec;
  out.stamp.nsec = header.stamp.nsec;
  out.frame_id = header.frame_id;
  return out;
}

ImageMsg View(const sensor_msgs::Image& image) {
  ImageMsg v;
  v.header = FromRos(image.header);
  v.height = image.height;
  v.width = image.width;
  v.encoding = image.encoding;
  v.is_bigendian = image.is_bigendian;
  v.step = image.step;
  v.data = {image.data.data(), image.data.size()};
  return v;
}

CameraInfoMsg View(const sensor_msgs::CameraInfo& info) {
  CameraInfoMsg v;
  v.height = info.height;
  v.width = info.width;
  std::copy(info.K.begin(), info.K.end(), v.K.begin());
  std::copy(info.P.begin(), info.P.end(), v.P.begin());
  v.binning_x = info.binning_x;
  v.binning_y = info.binning_y;
  v.roi.width = info.roi.width;
  v.roi.height = info.roi.height;
  return v;
}

DisparityImageMsg View(const stereo_msgs::DisparityImage& disparity) {
  DisparityImageMsg v;
  v.header = FromRos(disparity.header);
  v.image = View(disparity.image);
  v.f = disparity.f;
  v.T = disparity.T;
  v.min_disparity = disparity.min_disparity;
  return v;
}

}  // namespace cloudcast::ros_bridge
