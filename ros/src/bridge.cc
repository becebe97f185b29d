#include "bridge.h"

#include <diagnostic_msgs/DiagnosticArray.h>
#include <sensor_msgs/PointCloud2.h>
#include <stereo_msgs/DisparityImage.h>

#include "absl/strings/str_cat.h"
#include "cloudcast/proto/convert.h"
#include "depth_input.h"
#include "diagnostics_msg.h"
#include "disparity_input.h"
#include "point_cloud2.h"
#include "ros_messages.h"
#include "ros_params.h"
#include "stereo_input.h"

namespace cloudcast::ros_bridge {
namespace {

// The stereo settings a stream of `config` gets on a server whose defaults are `defaults` (its
// GetInfo), or on one with the core's defaults when the server did not answer.
DisparityRange ResolveRange(const client::StreamConfig& config,
                            const absl::StatusOr<v1::ServerInfo>& info) {
  convert::StreamSettings defaults;
  if (info.ok()) {
    if (auto d = convert::Resolve(info->defaults(), convert::StreamSettings{}); d.ok()) {
      defaults = *std::move(d);
    }
  }
  DisparityRange range;
  const StereoParams* st = &defaults.frame.stereo;
  auto resolved = convert::Resolve(config, defaults);
  if (resolved.ok()) st = &resolved->frame.stereo;
  range.min_disparity = st->min_disparity;
  range.num_disparities = st->num_disparities;
  return range;
}

}  // namespace

absl::StatusOr<std::unique_ptr<Bridge>> Bridge::Create(ros::NodeHandle nh,
                                                       ros::NodeHandle private_nh) {
  auto options = ReadBridgeOptions(private_nh);
  if (!options.ok()) return options.status();
  std::unique_ptr<Bridge> bridge(new Bridge(nh, *std::move(options)));
  auto info = bridge->link_->Probe();
  if (info.ok()) {
    ROS_INFO("cloudcast: server %s at %s (instance %s, %u workers)", info->version().c_str(),
             bridge->options_.server.c_str(), info->instance().c_str(), info->worker_threads());
  } else if (info.status().code() == absl::StatusCode::kInvalidArgument) {
    return info.status();  // a target or TLS setting that can never work
  } else {
    // /diagnostics says why from its first report, before any frame comes.
    bridge->stats_.LinkDown(info.status());
    if (info.status().code() == absl::StatusCode::kUnauthenticated ||
        info.status().code() == absl::StatusCode::kPermissionDenied) {
      // The server may be given the token later (it re-reads its tokens on SIGHUP): keep trying.
      ROS_ERROR("cloudcast: the server refuses this bridge (%s); check ~token_file",
                info.status().ToString().c_str());
    } else {
      ROS_WARN("cloudcast: %s; frames are dropped until it answers",
               std::string(info.status().message()).c_str());
    }
  }
  if (bridge->options_.publish_disparity) {
    bridge->disparity_range_ = ResolveRange(bridge->options_.config, info);
  }
  bridge->input_ = bridge->MakeInput();
  std::string outputs = bridge->points_.getTopic();
  if (bridge->options_.publish_disparity) {
    absl::StrAppend(&outputs, " and ", bridge->disparity_.getTopic(), " (min_disparity ",
                    bridge->disparity_range_.min_disparity, ", ",
                    bridge->disparity_range_.num_disparities, " disparities)");
  }
  ROS_INFO("cloudcast: ~input %s: subscribed to %s; publishing %s",
           std::string(Name(bridge->options_.input)).c_str(), bridge->input_->Describe().c_str(),
           outputs.c_str());
  return bridge;
}

std::unique_ptr<InputSource> Bridge::MakeInput() {
  InputSource::Sink sink = [this](const OutgoingFrame& f) { OnFrame(f); };
  InputSource::ErrorSink error_sink = [this](const absl::Status& s) {
    stats_.InputError(s);
    ROS_ERROR_THROTTLE(5, "cloudcast: input frame refused: %s", std::string(s.message()).c_str());
  };
  switch (options_.input) {
    case InputKind::kDepth:
      return std::make_unique<DepthInput>(nh_, options_.sync, options_.depth_scale, std::move(sink),
                                          std::move(error_sink));
    case InputKind::kStereo:
      return std::make_unique<StereoInput>(nh_, options_.sync, std::move(sink),
                                           std::move(error_sink));
    case InputKind::kDisparity:
      break;
  }
  return std::make_unique<DisparityInput>(nh_, options_.sync, std::move(sink),
                                          std::move(error_sink));
}

Bridge::Bridge(ros::NodeHandle nh, BridgeOptions options) : nh_(nh), options_(std::move(options)) {
  points_ = nh_.advertise<sensor_msgs::PointCloud2>("points2", 5);
  if (options_.publish_disparity) {
    disparity_ = nh_.advertise<stereo_msgs::DisparityImage>("disparity", 5);
  }
  diagnostics_ = nh_.advertise<diagnostic_msgs::DiagnosticArray>("/diagnostics", 5);
  status_name_ = absl::StrCat(ros::this_node::getName(), ": cloudcast stream");
  link_ = std::make_unique<CloudLink>(
      options_, &stats_,
      [this](client::Result&& r, const SentFrame& f) { OnCloud(std::move(r), f); },
      [](LogLevel level, const std::string& message) {
        switch (level) {
          case LogLevel::kInfo: ROS_INFO("cloudcast: %s", message.c_str()); break;
          case LogLevel::kWarn: ROS_WARN("cloudcast: %s", message.c_str()); break;
          case LogLevel::kError: ROS_ERROR("cloudcast: %s", message.c_str()); break;
        }
      });
  timer_ = nh_.createTimer(ros::Duration(options_.diagnostics_period_s), &Bridge::OnTimer, this);
}

void Bridge::OnFrame(const OutgoingFrame& frame) {
  stats_.FrameIn();
  link_->Send(frame);
}

// On a gRPC callback thread, one reply at a time (roscpp's publish is thread-safe).
void Bridge::OnCloud(client::Result&& result, const SentFrame& frame) {
  if (options_.publish_disparity) PublishDisparity(result, frame);
  sensor_msgs::PointCloud2Ptr msg = boost::make_shared<sensor_msgs::PointCloud2>();
  ToPointCloud2(result.cloud, ToRos(frame.header), msg.get());
  points_.publish(msg);
  stats_.Published();
}

void Bridge::PublishDisparity(const client::Result& result, const SentFrame& frame) {
  if (!result.reply.has_disparity()) {
    stats_.PublishError(absl::DataLossError(
        "the reply has no disparity map (a server without StereoConfig.return_disparity?)"));
    ROS_WARN_THROTTLE(5,
                      "cloudcast: a reply without the disparity map ~stereo/publish_disparity "
                      "asked for");
    return;
  }
  stereo_msgs::DisparityImagePtr msg = boost::make_shared<stereo_msgs::DisparityImage>();
  absl::Status s;
  {
    std::lock_guard<std::mutex> lock(decompressor_mu_);
    s = ToDisparityImage(result.reply.disparity(), ToRos(frame.header), frame.camera, disparity_range_,
                         &decompressor_, msg.get());
  }
  if (!s.ok()) {
    stats_.PublishError(s);
    ROS_ERROR_THROTTLE(5, "cloudcast: %s", std::string(s.message()).c_str());
    return;
  }
  disparity_.publish(msg);
}

void Bridge::OnTimer(const ros::TimerEvent&) {
  const ros::Time now = ros::Time::now();
  diagnostics_.publish(
      ToDiagnosticArray(stats_.Report(now.toSec(), status_name_, options_.server), now));
}

}  // namespace cloudcast::ros_bridge
