#include "ros2_inputs.h"

#include <cstdio>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "frame_conversions.h"
#include "sample_views.h"

namespace cloudcast::ros2_bridge {
namespace {

std::string StampText(const Stamp& s) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%d.%09u", s.first, s.second);
  return buf;
}

}  // namespace

TakenSample::TakenSample(const MessageType& type)
    : type_(type), ptr_(dds_alloc(type.descriptor->m_size)) {}

TakenSample::~TakenSample() { dds_sample_free(ptr_, type_.descriptor, DDS_FREE_ALL); }

ExactTimeSync::ExactTimeSync(std::vector<std::string> topics, int queue_size,
                             std::function<void(Set&)> on_set,
                             std::function<void(const absl::Status&)> on_error)
    : topics_(std::move(topics)),
      queue_size_(static_cast<std::size_t>(queue_size)),
      on_set_(std::move(on_set)),
      on_error_(std::move(on_error)) {}

void ExactTimeSync::Drop(std::map<Stamp, Set>::iterator it, const char* why) {
  std::vector<std::string> have, missing;
  for (std::size_t i = 0; i < topics_.size(); ++i) {
    (it->second[i] ? have : missing).push_back(topics_[i]);
  }
  on_error_(absl::InvalidArgumentError(absl::StrCat(
      absl::StrJoin(have, ", "), ".header.stamp ", StampText(it->first), ": no ",
      absl::StrJoin(missing, ", "), " with the same stamp (", why,
      "); exact-time sync pairs only equal stamps")));
  waiting_.erase(it);
}

void ExactTimeSync::Add(std::size_t index, std::shared_ptr<TakenSample> sample) {
  const Stamp stamp{sample->header().stamp.sec, sample->header().stamp.nanosec};
  auto [it, inserted] = waiting_.try_emplace(stamp, Set(topics_.size()));
  it->second[index] = std::move(sample);
  bool complete = true;
  for (const auto& s : it->second) complete = complete && s != nullptr;
  if (complete) {
    Set set = std::move(it->second);
    // Older stamps can no longer complete (the inputs publish in stamp order).
    while (waiting_.begin() != it) Drop(waiting_.begin(), "a later stamp was complete");
    waiting_.erase(it);
    on_set_(set);
    return;
  }
  while (waiting_.size() > queue_size_) Drop(waiting_.begin(), "the queue was full");
}

Ros2Input::Ros2Input(ros_bridge::InputKind kind, std::optional<double> depth_scale, Sink sink,
                     ErrorSink error_sink)
    : kind_(kind),
      depth_scale_(depth_scale),
      sink_(std::move(sink)),
      error_sink_(std::move(error_sink)) {}

absl::StatusOr<std::unique_ptr<Ros2Input>> Ros2Input::Create(
    DdsNode* node, const NodeNames& names, ros_bridge::InputKind kind,
    const ros_bridge::SyncOptions& sync, std::optional<double> depth_scale, const QosProfile& qos,
    Sink sink, ErrorSink error_sink) {
  std::unique_ptr<Ros2Input> in(
      new Ros2Input(kind, depth_scale, std::move(sink), std::move(error_sink)));
  in->qos_ = qos;
  std::vector<std::pair<const char*, const MessageType*>> topics;
  switch (kind) {
    case ros_bridge::InputKind::kDisparity:
      topics = {{ros_bridge::kDisparityTopic, &kDisparityImageType},
                {ros_bridge::kDisparityColourTopic, &kImageType},
                {ros_bridge::kDisparityInfoTopic, &kCameraInfoType}};
      break;
    case ros_bridge::InputKind::kDepth:
      topics = {{ros_bridge::kDepthTopic, &kImageType},
                {ros_bridge::kDepthColourTopic, &kImageType},
                {ros_bridge::kDepthInfoTopic, &kCameraInfoType}};
      break;
    case ros_bridge::InputKind::kStereo:
      topics = {{ros_bridge::kLeftTopic, &kImageType},
                {ros_bridge::kRightTopic, &kImageType},
                {ros_bridge::kLeftInfoTopic, &kCameraInfoType},
                {ros_bridge::kRightInfoTopic, &kCameraInfoType}};
      break;
  }
  for (const auto& [topic, type] : topics) {
    auto resolved = ResolveTopicName(topic, names);
    if (!resolved.ok()) return resolved.status();
    auto reader = node->CreateReader(*type, *resolved, qos);
    if (!reader.ok()) return reader.status();
    in->types_.push_back(type);
    in->topics_.push_back(*resolved);
    in->readers_.push_back(*reader);
  }
  Ros2Input* self = in.get();
  in->sync_ = std::make_unique<ExactTimeSync>(
      in->topics_, sync.queue_size, [self](ExactTimeSync::Set& set) { self->OnSet(set); },
      [self](const absl::Status& s) { self->error_sink_(s); });
  return in;
}

std::string Ros2Input::Describe() const { return absl::StrJoin(topics_, ", "); }

void Ros2Input::TakeAll() {
  for (std::size_t i = 0; i < readers_.size(); ++i) {
    dds_requested_incompatible_qos_status_t qos_status;
    if (dds_get_requested_incompatible_qos_status(readers_[i], &qos_status) == DDS_RETCODE_OK &&
        qos_status.total_count_change > 0) {
      const bool reliability = qos_status.last_policy_id == DDS_RELIABILITY_QOS_POLICY_ID;
      const bool representation =
          qos_status.last_policy_id == DDS_DATA_REPRESENTATION_QOS_POLICY_ID;
      error_sink_(absl::FailedPreconditionError(absl::StrCat(
          topics_[i], ": a writer's QoS is incompatible with this reader's (",
          reliability      ? "it is best effort and input_qos is default (reliable): set "
                             "input_qos:=sensor_data"
          : representation ? "its data representation is not XCDR1, as every ROS 2 reader's"
                           : absl::StrCat("DDS policy id ", qos_status.last_policy_id),
          ")")));
    }
    for (;;) {
      auto sample = std::make_shared<TakenSample>(*types_[i]);
      void* buf[1] = {sample->get()};
      dds_sample_info_t info;
      const dds_return_t n = dds_take(readers_[i], buf, &info, 1, 1);
      if (n <= 0) break;
      if (!info.valid_data) continue;
      sync_->Add(i, std::move(sample));
    }
  }
}

void Ros2Input::OnSet(ExactTimeSync::Set& set) {
  ros_bridge::OutgoingFrame frame;
  absl::Status s;
  switch (kind_) {
    case ros_bridge::InputKind::kDisparity:
      s = ros_bridge::ToFrame(View(set[0]->as<stereo_msgs_msg_dds__DisparityImage_>()),
                              View(set[1]->as<sensor_msgs_msg_dds__Image_>()),
                              View(set[2]->as<sensor_msgs_msg_dds__CameraInfo_>()), &masked_,
                              &frame);
      break;
    case ros_bridge::InputKind::kDepth:
      s = ros_bridge::ToDepthFrame(View(set[0]->as<sensor_msgs_msg_dds__Image_>()),
                                   View(set[1]->as<sensor_msgs_msg_dds__Image_>()),
                                   View(set[2]->as<sensor_msgs_msg_dds__CameraInfo_>()),
                                   depth_scale_, &frame);
      break;
    case ros_bridge::InputKind::kStereo:
      s = ros_bridge::ToStereoFrame(View(set[0]->as<sensor_msgs_msg_dds__Image_>()),
                                    View(set[1]->as<sensor_msgs_msg_dds__Image_>()),
                                    View(set[2]->as<sensor_msgs_msg_dds__CameraInfo_>()),
                                    View(set[3]->as<sensor_msgs_msg_dds__CameraInfo_>()), &frame);
      break;
  }
  if (!s.ok()) {
    error_sink_(s);
    return;
  }
  sink_(frame);
}

}  // namespace cloudcast::ros2_bridge
