// The ROS 2 bridge's inputs: the DDS readers of one input kind's topics (the same names as the
// ROS 1 bridge's, resolved in the node's namespace and remapped), their exact-time
// synchronization on header.stamp, and the shared conversion of each matched set into a frame
// (bridge/frame_conversions.h).
#pragma once

#include <dds/dds.h>

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "bridge_options.h"
#include "dds_node.h"
#include "input_source.h"
#include "message_types.h"
#include "qos.h"
#include "ros_names.h"

namespace cloudcast::ros2_bridge {

// A sample taken from a reader into storage of its own (Cyclone allocates its strings and
// sequences), freed with it.
class TakenSample {
 public:
  explicit TakenSample(const MessageType& type);
  ~TakenSample();
  TakenSample(const TakenSample&) = delete;
  TakenSample& operator=(const TakenSample&) = delete;
  void* get() { return ptr_; }
  template <typename T>
  const T& as() const {
    return *static_cast<const T*>(ptr_);
  }
  // Every input type starts with its std_msgs/Header.
  const std_msgs_msg_dds__Header_& header() const { return as<std_msgs_msg_dds__Header_>(); }

 private:
  const MessageType& type_;
  void* ptr_;
};

using Stamp = std::pair<std::int32_t, std::uint32_t>;  // sec, nanosec

// Pairs the samples of N topics whose header.stamp is equal (message_filters' ExactTime). A set
// that stays incomplete is dropped, with an error naming the topics that had no sample of its
// stamp, when a later stamp completes or when more than `queue_size` stamps wait.
class ExactTimeSync {
 public:
  using Set = std::vector<std::shared_ptr<TakenSample>>;
  ExactTimeSync(std::vector<std::string> topics, int queue_size, std::function<void(Set&)> on_set,
                std::function<void(const absl::Status&)> on_error);
  void Add(std::size_t index, std::shared_ptr<TakenSample> sample);
  std::size_t waiting() const { return waiting_.size(); }

 private:
  void Drop(std::map<Stamp, Set>::iterator it, const char* why);
  std::vector<std::string> topics_;
  std::size_t queue_size_;
  std::function<void(Set&)> on_set_;
  std::function<void(const absl::Status&)> on_error_;
  std::map<Stamp, Set> waiting_;
};

class Ros2Input : public ros_bridge::InputSource {
 public:
  static absl::StatusOr<std::unique_ptr<Ros2Input>> Create(
      DdsNode* node, const NodeNames& names, ros_bridge::InputKind kind,
      const ros_bridge::SyncOptions& sync, std::optional<double> depth_scale,
      const QosProfile& qos, Sink sink, ErrorSink error_sink);
  std::string Describe() const override;
  const std::vector<dds_entity_t>& readers() const { return readers_; }
  // Takes everything the readers hold, feeding the synchronizer (and the sink per matched set);
  // reports readers that met a writer of incompatible QoS since the last call.
  void TakeAll();

 private:
  Ros2Input(ros_bridge::InputKind kind, std::optional<double> depth_scale, Sink sink,
            ErrorSink error_sink);
  void OnSet(ExactTimeSync::Set& set);

  const ros_bridge::InputKind kind_;
  const std::optional<double> depth_scale_;
  Sink sink_;
  ErrorSink error_sink_;
  std::vector<const MessageType*> types_;
  std::vector<std::string> topics_;  // resolved, as the readers' order
  std::vector<dds_entity_t> readers_;
  std::unique_ptr<ExactTimeSync> sync_;
  std::vector<float> masked_;  // the masked disparities of the frame being sent
  QosProfile qos_;
};

}  // namespace cloudcast::ros2_bridge
