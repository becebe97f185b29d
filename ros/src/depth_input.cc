#include "depth_input.h"

#include <utility>

namespace cloudcast::ros_bridge {

DepthInput::DepthInput(ros::NodeHandle& nh, const SyncOptions& sync,
                       std::optional<double> depth_scale, Sink sink, ErrorSink error_sink)
    : depth_scale_(depth_scale),
      sink_(std::move(sink)),
      error_sink_(std::move(error_sink)),
      sync_(nh, {kDepthTopic, kDepthColourTopic, kDepthInfoTopic}, sync,
            [this](const auto& d, const auto& c, const auto& i) { OnMessages(d, c, i); }) {}

void DepthInput::OnMessages(const sensor_msgs::Image::ConstPtr& depth,
                            const sensor_msgs::Image::ConstPtr& colour,
                            const sensor_msgs::CameraInfo::ConstPtr& info) {
  OutgoingFrame frame;
  if (absl::Status s = ToDepthFrame(*depth, *colour, *info, depth_scale_, &frame); !s.ok()) {
    error_sink_(s);
    return;
  }
  sink_(frame);
}

}  // namespace cloudcast::ros_bridge
