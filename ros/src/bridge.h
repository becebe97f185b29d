// The node: an input (its subscribers and synchronizer), the link to the server, and the
// PointCloud2, DisparityImage (stereo pairs, on request) and diagnostics publishers.
#pragma once

#include <ros/ros.h>

#include <memory>
#include <mutex>

#include "absl/status/statusor.h"
#include "bridge_options.h"
#include "cloud_link.h"
#include "cloudcast/core/frame_codec.h"
#include "diagnostics.h"
#include "disparity_output.h"
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
  std::unique_ptr<InputSource> MakeInput();
  void OnFrame(const OutgoingFrame& frame);
  void OnCloud(client::Result&& result, const SentFrame& frame);
  void PublishDisparity(const client::Result& result, const SentFrame& frame);
  void OnTimer(const ros::TimerEvent& event);

  ros::NodeHandle nh_;
  const BridgeOptions options_;
  ros::Publisher points_;
  ros::Publisher disparity_;  // ~stereo/publish_disparity only
  ros::Publisher diagnostics_;
  BridgeStats stats_;
  std::string status_name_;
  // The matcher's range as the server resolves it (the parameters over its defaults), for the
  // DisparityImage's min_disparity and max_disparity.
  DisparityRange disparity_range_;
  std::mutex decompressor_mu_;  // replies of a stream that reconnected may overlap
  PlaneDecompressor decompressor_;
  // Destroyed in reverse: the input first (no more frames), then the link (its last replies are
  // still published).
  std::unique_ptr<CloudLink> link_;
  std::unique_ptr<InputSource> input_;
  ros::Timer timer_;
};

}  // namespace cloudcast::ros_bridge
