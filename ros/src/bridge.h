// The node: an input (its subscribers and synchronizer), the link to the server, and the
// PointCloud2 and diagnostics publishers.
#pragma once

#include <ros/ros.h>

#include <memory>

#include "absl/status/statusor.h"
#include "bridge_options.h"
#include "cloud_link.h"
#include "diagnostics.h"
#include "input_source.h"

namespace cloudcast::ros_bridge {

class Bridge {
 public:
  // Reads the parameters of `private_nh`, subscribes and advertises under `nh`. Errors name the
  // parameter (see ReadBridgeOptions).
  static absl::StatusOr<std::unique_ptr<Bridge>> Create(ros::NodeHandle nh,
                                                        ros::NodeHandle private_nh);
  Bridge(const Bridge&) = delete;
  Bridge& operator=(const Bridge&) = delete;

 private:
  Bridge(ros::NodeHandle nh, BridgeOptions options);
  void OnFrame(const OutgoingFrame& frame);
  void OnCloud(client::Result&& result, const std_msgs::Header& header);
  void OnTimer(const ros::TimerEvent& event);

  ros::NodeHandle nh_;
  const BridgeOptions options_;
  ros::Publisher points_;
  ros::Publisher diagnostics_;
  BridgeStats stats_;
  std::string status_name_;
  // Destroyed in reverse: the input first (no more frames), then the link (its last replies are
  // still published).
  std::unique_ptr<CloudLink> link_;
  std::unique_ptr<InputSource> input_;
  ros::Timer timer_;
};

}  // namespace cloudcast::ros_bridge
