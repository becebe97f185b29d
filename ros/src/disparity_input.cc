#include "disparity_input.h"

#include <utility>

namespace cloudcast::ros_bridge {

DisparityInput::DisparityInput(ros::NodeHandle& nh, const SyncOptions& sync, Sink sink,
                               ErrorSink error_sink)
    : sink_(std::move(sink)),
      error_sink_(std::move(error_sink)),
      sync_(nh, {kDisparityTopic, kDisparityColourTopic, kDisparityInfoTopic}, sync,
            [this](const auto& d, const auto& c, const auto& i) { OnMessages(d, c, i); }) {}

void DisparityInput::OnMessages(const stereo_msgs::DisparityImage::ConstPtr& disparity,
                                const sensor_msgs::Image::ConstPtr& colour,
                                const sensor_msgs::CameraInfo::ConstPtr& info) {
  OutgoingFrame frame;
  if (absl::Status s = ToFrame(*disparity, *colour, *info, &masked_, &frame); !s.ok()) {
    error_sink_(s);
    return;
  }
  sink_(frame);
}

}  // namespace cloudcast::ros_bridge
