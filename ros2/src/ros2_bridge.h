// The ROS 2 node: an input (DDS readers, exact-time sync), the shared link to the server
// (bridge/cloud_link.h), and the PointCloud2 and /diagnostics writers, run by one thread that
// waits on the readers; the clouds are written from the stream's receiver thread.
#pragma once

#include <dds/dds.h>

#include <atomic>
#include <memory>
#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "bridge_options.h"
#include "cloud_link.h"
#include "dds_node.h"
#include "diagnostics.h"
#include "discovery_info.h"
#include "qos.h"
#include "ros2_inputs.h"
#include "ros_names.h"

namespace cloudcast::ros2_bridge {

// What the ROS 2 bridge takes beyond the shared parameters.
struct Ros2Options {
  NodeNames node;
  dds_domainid_t domain = 0;
  QosProfile input_qos = SensorDataQos();  // input_qos: a best-effort reader matches every writer
  QosProfile output_qos = DefaultQos();    // reliable: default subscribers see it
  // ros_discovery_info: the node's entry in the ROS 2 graph, in this distribution's Gid layout
  // (discovery_info.h); nullopt: none.
  std::optional<GidLayout> discovery_info = GidLayout::kIronAndLater;
};

class Ros2Bridge {
 public:
  static absl::StatusOr<std::unique_ptr<Ros2Bridge>> Create(ros_bridge::BridgeOptions options,
                                                            Ros2Options ros2);
  ~Ros2Bridge();
  Ros2Bridge(const Ros2Bridge&) = delete;
  Ros2Bridge& operator=(const Ros2Bridge&) = delete;

  // Until `stop` is set: takes the inputs' samples as they come, reports /diagnostics every
  // diagnostics period.
  void Run(const std::atomic<bool>& stop);

 private:
  Ros2Bridge(ros_bridge::BridgeOptions options, Ros2Options ros2);
  void OnCloud(client::Result&& result, const ros_bridge::SentFrame& frame);
  void PublishDiagnostics();

  const ros_bridge::BridgeOptions options_;
  const Ros2Options ros2_;
  std::unique_ptr<DdsNode> node_;
  dds_entity_t points_ = 0, diagnostics_ = 0, waitset_ = 0;
  std::string points_topic_, status_name_;
  ros_bridge::BridgeStats stats_;
  // Destroyed in reverse: the input first (no more frames), then the link (its last replies are
  // still written), then the DDS node.
  std::unique_ptr<ros_bridge::CloudLink> link_;
  std::unique_ptr<Ros2Input> input_;
};

}  // namespace cloudcast::ros2_bridge
