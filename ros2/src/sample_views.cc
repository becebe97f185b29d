#include "sample_views.h"

#include <algorithm>

#include "point_cloud_layout.h"

namespace cloudcast::ros2_bridge {
namespace {

const char* NonNull(const char* s) { return s == nullptr ? "" : s; }
char* Mutable(const std::string& s) { return const_cast<char*>(s.c_str()); }

}  // namespace

ros_bridge::MessageHeader ToHeader(const std_msgs_msg_dds__Header_& header) {
  ros_bridge::MessageHeader out;
  out.stamp.sec = static_cast<std::uint32_t>(header.stamp.sec);
  out.stamp.nsec = header.stamp.nanosec;
  out.frame_id = NonNull(header.frame_id);
  return out;
}

ros_bridge::ImageMsg View(const sensor_msgs_msg_dds__Image_& image) {
  ros_bridge::ImageMsg v;
  v.header = ToHeader(image.header);
  v.height = image.height;
  v.width = image.width;
  v.encoding = NonNull(image.encoding);
  v.is_bigendian = image.is_bigendian;
  v.step = image.step;
  v.data = {image.data._buffer, image.data._length};
  return v;
}

ros_bridge::CameraInfoMsg View(const sensor_msgs_msg_dds__CameraInfo_& info) {
  ros_bridge::CameraInfoMsg v;
  v.height = info.height;
  v.width = info.width;
  std::copy(std::begin(info.k), std::end(info.k), v.K.begin());
  std::copy(std::begin(info.p), std::end(info.p), v.P.begin());
  v.binning_x = info.binning_x;
  v.binning_y = info.binning_y;
  v.roi.width = info.roi.width;
  v.roi.height = info.roi.height;
  return v;
}

ros_bridge::DisparityImageMsg View(const stereo_msgs_msg_dds__DisparityImage_& disparity) {
  ros_bridge::DisparityImageMsg v;
  v.header = ToHeader(disparity.header);
  v.image = View(disparity.image);
  v.f = disparity.f;
  v.T = disparity.t;
  v.min_disparity = disparity.min_disparity;
  return v;
}

PointCloud2Sample::PointCloud2Sample(const PointCloud& cloud,
                                     const ros_bridge::MessageHeader& header)
    : frame_id_(header.frame_id) {
  for (const ros_bridge::PointFieldSpec& f : ros_bridge::kPointFields) {
    fields_.push_back({const_cast<char*>(f.name), f.offset, f.datatype, f.count});
  }
  data_.resize(cloud.size() * ros_bridge::kPointStep);
  ros_bridge::WritePointData(cloud, data_.data());
  msg_.header.stamp.sec = static_cast<std::int32_t>(header.stamp.sec);
  msg_.header.stamp.nanosec = header.stamp.nsec;
  msg_.header.frame_id = Mutable(frame_id_);
  msg_.height = 1;
  msg_.width = static_cast<std::uint32_t>(cloud.size());
  msg_.fields._buffer = fields_.data();
  msg_.fields._length = msg_.fields._maximum = static_cast<std::uint32_t>(fields_.size());
  msg_.is_bigendian = false;
  msg_.point_step = ros_bridge::kPointStep;
  msg_.row_step = msg_.point_step * msg_.width;
  msg_.data._buffer = data_.data();
  msg_.data._length = msg_.data._maximum = static_cast<std::uint32_t>(data_.size());
  msg_.is_dense = true;  // the server's clouds hold finite points only
}

DiagnosticArraySample::DiagnosticArraySample(const ros_bridge::DiagnosticReport& report,
                                             std::int32_t sec, std::uint32_t nanosec)
    : report_(report) {
  for (const auto& [key, value] : report_.values) {
    values_.push_back({Mutable(key), Mutable(value)});
  }
  status_.level = report_.level;
  status_.name = Mutable(report_.name);
  status_.message = Mutable(report_.message);
  status_.hardware_id = Mutable(report_.hardware_id);
  status_.values._buffer = values_.data();
  status_.values._length = status_.values._maximum = static_cast<std::uint32_t>(values_.size());
  msg_.header.stamp.sec = sec;
  msg_.header.stamp.nanosec = nanosec;
  msg_.header.frame_id = const_cast<char*>("");
  msg_.status._buffer = &status_;
  msg_.status._length = msg_.status._maximum = 1;
}

}  // namespace cloudcast::ros2_bridge
