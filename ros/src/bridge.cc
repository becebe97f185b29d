#include "bridge.h"

#include <diagnostic_msgs/DiagnosticArray.h>
#include <sensor_msgs/PointCloud2.h>

#include "absl/strings/str_cat.h"
#include "disparity_input.h"
#include "point_cloud2.h"

namespace cloudcast::ros_bridge {

absl::StatusOr<std::unique_ptr<Bridge>> Bridge::Create(ros::NodeHandle nh,
                                                       ros::NodeHandle private_nh) {
  auto options = ReadBridgeOptions(private_nh);
  if (!options.ok()) return options.status();
  if (options->input != InputKind::kDisparity) {
    return absl::UnimplementedError(absl::StrCat(
        "~input is '", options->input == InputKind::kDepth ? "depth" : "stereo",
        "': this bridge takes disparity only so far (the depth and stereo-pair inputs come "
        "with the protocol's own, issue 19)"));
  }
  std::unique_ptr<Bridge> bridge(new Bridge(nh, *std::move(options)));
  auto info = bridge->link_->Probe();
  if (info.ok()) {
    ROS_INFO("cloudcast: server %s at %s (instance %s, %u workers)", info->version().c_str(),
             bridge->options_.server.c_str(), info->instance().c_str(), info->worker_threads());
  } else if (info.status().code() == absl::StatusCode::kInvalidArgument) {
    return info.status();  // a target or TLS setting that can never work
  } else if (info.status().code() == absl::StatusCode::kUnauthenticated ||
             info.status().code() == absl::StatusCode::kPermissionDenied) {
    // The server may be given the token later (it re-reads its tokens on SIGHUP): keep trying.
    ROS_ERROR("cloudcast: the server refuses this bridge (%s); check ~token_file",
              info.status().ToString().c_str());
  } else {
    ROS_WARN("cloudcast: %s; frames are dropped until it answers",
             std::string(info.status().message()).c_str());
  }
  bridge->input_ = std::make_unique<DisparityInput>(
      bridge->nh_, bridge->options_.sync,
      [b = bridge.get()](const OutgoingFrame& f) { b->OnFrame(f); },
      [b = bridge.get()](const absl::Status& s) {
        b->stats_.InputError(s);
        ROS_ERROR_THROTTLE(5, "cloudcast: input frame refused: %s",
                           std::string(s.message()).c_str());
      });
  ROS_INFO("cloudcast: subscribed to %s; publishing %s", bridge->input_->Describe().c_str(),
           bridge->points_.getTopic().c_str());
  return bridge;
}

Bridge::Bridge(ros::NodeHandle nh, BridgeOptions options) : nh_(nh), options_(std::move(options)) {
  points_ = nh_.advertise<sensor_msgs::PointCloud2>("points2", 5);
  diagnostics_ = nh_.advertise<diagnostic_msgs::DiagnosticArray>("/diagnostics", 5);
  status_name_ = absl::StrCat(ros::this_node::getName(), ": cloudcast stream");
  link_ = std::make_unique<CloudLink>(
      options_, &stats_,
      [this](client::Result&& r, const std_msgs::Header& h) { OnCloud(std::move(r), h); });
  timer_ = nh_.createTimer(ros::Duration(options_.diagnostics_period_s), &Bridge::OnTimer, this);
}

void Bridge::OnFrame(const OutgoingFrame& frame) {
  stats_.FrameIn();
  link_->Send(frame);
}

// On the stream's receiver thread (roscpp's publish is thread-safe).
void Bridge::OnCloud(client::Result&& result, const std_msgs::Header& header) {
  sensor_msgs::PointCloud2Ptr msg = boost::make_shared<sensor_msgs::PointCloud2>();
  ToPointCloud2(result.cloud, header, msg.get());
  points_.publish(msg);
  stats_.Published();
}

void Bridge::OnTimer(const ros::TimerEvent&) {
  diagnostics_.publish(stats_.Report(ros::Time::now(), status_name_, options_.server));
}

}  // namespace cloudcast::ros_bridge
