#include "stereo_input.h"

#include <utility>

namespace cloudcast::ros_bridge {

StereoInput::StereoInput(ros::NodeHandle& nh, const SyncOptions& sync, Sink sink,
                         ErrorSink error_sink)
    : sink_(std::move(sink)),
      error_sink_(std::move(error_sink)),
      sync_(nh, {kLeftTopic, kRightTopic, kLeftInfoTopic, kRightInfoTopic}, sync,
            [this](const auto& l, const auto& r, const auto& li, const auto& ri) {
              OnMessages(l, r, li, ri);
            }) {}

void StereoInput::OnMessages(const sensor_msgs::Image::ConstPtr& left,
                             const sensor_msgs::Image::ConstPtr& right,
                             const sensor_msgs::CameraInfo::ConstPtr& left_info,
                             const sensor_msgs::CameraInfo::ConstPtr& right_info) {
  OutgoingFrame frame;
  if (absl::Status s = ToStereoFrame(*left, *right, *left_info, *right_info, &frame); !s.ok()) {
    error_sink_(s);
    return;
  }
  sink_(frame);
}

}  // namespace cloudcast::ros_bridge
