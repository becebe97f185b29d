// cloudcast-ros2-bridge: a ROS 2 node without rclcpp (Debian ships none) that speaks DDS with
// ROS 2's conventions on CycloneDDS: it turns a camera's disparity, depth image or stereo pair
// into point clouds on a cloudcast server and publishes them as sensor_msgs/PointCloud2.
// --help prints its topics and parameters; docs/ros2.md has the same with examples.
#include <csignal>
#include <cstdio>
#include <string>
#include <vector>

#include "bridge_options.h"
#include "dds_node.h"
#include "help.h"
#include "ros2_bridge.h"
#include "ros_args.h"

namespace {

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop.store(true); }

constexpr const char* kProgram = "cloudcast-ros2-bridge";

int Fail(const std::string& message) {
  std::fprintf(stderr, "%s: %s\n", kProgram, message.c_str());
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace cloudcast;
  std::vector<std::string> args(argv + 1, argv + argc);
  auto parsed = ros2_bridge::ParseRosArgs(args, "cloudcast_bridge");
  if (!parsed.ok()) return Fail(std::string(parsed.status().message()));
  if (parsed->help) {
    std::fputs(ros2_bridge::HelpText().c_str(), stdout);
    return 0;
  }
  ros2_bridge::Ros2ParamReader params(parsed->params, ros2_bridge::Ros2BridgeParameters());
  auto options = ros_bridge::ReadBridgeOptions(params, kProgram);
  if (!options.ok()) return Fail(std::string(options.status().message()));
  if (options->sync.approximate_sync) {
    return Fail("approximate_sync is true; the ROS 2 bridge pairs exact stamps only (the "
                "ROS 1 bridge has ApproximateTime)");
  }
  if (options->publish_disparity) {
    return Fail("stereo.publish_disparity is true; the ROS 2 bridge does not publish the "
                "server's disparity map yet (the ROS 1 bridge does)");
  }
  ros2_bridge::Ros2Options ros2;
  ros2.node = parsed->node;
  auto domain = ros2_bridge::DomainIdFromEnv();
  if (!domain.ok()) return Fail(std::string(domain.status().message()));
  ros2.domain = *domain;
  auto qos_name = params.String("input_qos");
  if (!qos_name.ok()) return Fail(std::string(qos_name.status().message()));
  if (*qos_name) {
    auto qos = ros2_bridge::ParseQosProfile(**qos_name, "input_qos");
    if (!qos.ok()) return Fail(std::string(qos.status().message()));
    ros2.input_qos = *qos;
  }
  auto discovery = params.String("ros_discovery_info");
  if (!discovery.ok()) return Fail(std::string(discovery.status().message()));
  if (*discovery) {
    auto layout = ros2_bridge::ParseDiscoveryInfo(**discovery, "ros_discovery_info");
    if (!layout.ok()) return Fail(std::string(layout.status().message()));
    ros2.discovery_info = *layout;
  }
  if (auto sim = params.Bool("use_sim_time"); !sim.ok()) {
    return Fail(std::string(sim.status().message()));
  }
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  auto bridge = ros2_bridge::Ros2Bridge::Create(*std::move(options), std::move(ros2));
  if (!bridge.ok()) return Fail(std::string(bridge.status().message()));
  (*bridge)->Run(g_stop);
  return 0;
}
