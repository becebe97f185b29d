#include "ros2_bridge.h"

#include <chrono>
#include <cstdio>

#include "absl/strings/str_cat.h"
#include "log.h"
#include "sample_views.h"

namespace cloudcast::ros2_bridge {

Ros2Bridge::Ros2Bridge(ros_bridge::BridgeOptions options, Ros2Options ros2)
    : options_(std::move(options)), ros2_(std::move(ros2)) {}

Ros2Bridge::~Ros2Bridge() {
  input_.reset();
  link_.reset();
  node_.reset();
}

absl::StatusOr<std::unique_ptr<Ros2Bridge>> Ros2Bridge::Create(ros_bridge::BridgeOptions options,
                                                               Ros2Options ros2) {
  std::unique_ptr<Ros2Bridge> b(new Ros2Bridge(std::move(options), std::move(ros2)));
  auto node = DdsNode::Create(b->ros2_.domain);
  if (!node.ok()) return node.status();
  b->node_ = *std::move(node);
  const NodeNames& names = b->ros2_.node;
  const std::string ns = names.node_namespace == "/" ? "" : names.node_namespace;
  b->status_name_ = absl::StrCat(ns, "/", names.node_name, ": cloudcast stream");
  auto points = ResolveTopicName("points2", names);
  if (!points.ok()) return points.status();
  b->points_topic_ = *points;
  auto diagnostics = ResolveTopicName("/diagnostics", names);
  if (!diagnostics.ok()) return diagnostics.status();
  auto pw = b->node_->CreateWriter(kPointCloud2Type, *points, b->ros2_.output_qos);
  if (!pw.ok()) return pw.status();
  b->points_ = *pw;
  auto dw = b->node_->CreateWriter(kDiagnosticArrayType, *diagnostics, b->ros2_.output_qos);
  if (!dw.ok()) return dw.status();
  b->diagnostics_ = *dw;

  Ros2Bridge* self = b.get();
  b->link_ = std::make_unique<ros_bridge::CloudLink>(
      b->options_, &b->stats_,
      [self](client::Result&& r, const ros_bridge::SentFrame& f) { self->OnCloud(std::move(r), f); },
      [self](ros_bridge::LogLevel level, const std::string& message) {
        switch (level) {
          case ros_bridge::LogLevel::kInfo: LogInfo(self->ros2_.node, message); break;
          case ros_bridge::LogLevel::kWarn: LogWarn(self->ros2_.node, message); break;
          case ros_bridge::LogLevel::kError: LogError(self->ros2_.node, message); break;
        }
      });
  auto info = b->link_->Probe();
  if (info.ok()) {
    LogInfo(names, absl::StrCat("server ", info->version(), " at ", b->options_.server,
                                " (instance ", info->instance(), ", ", info->worker_threads(),
                                " workers)"));
  } else if (info.status().code() == absl::StatusCode::kInvalidArgument) {
    return info.status();  // a target or TLS setting that can never work
  } else {
    b->stats_.LinkDown(info.status());  // /diagnostics says why from its first report
    LogWarn(names, absl::StrCat(info.status().message(), "; frames are dropped until it answers"));
  }
  auto input = Ros2Input::Create(
      b->node_.get(), names, b->options_.input, b->options_.sync, b->options_.depth_scale,
      b->ros2_.input_qos,
      [self](const ros_bridge::OutgoingFrame& f) {
        self->stats_.FrameIn();
        self->link_->Send(f);
      },
      [self](const absl::Status& s) {
        self->stats_.InputError(s);
        LogError(self->ros2_.node, absl::StrCat("input refused: ", s.message()));
      });
  if (!input.ok()) return input.status();
  b->input_ = *std::move(input);

  b->waitset_ = dds_create_waitset(b->node_->participant());
  if (b->waitset_ < 0) {
    return absl::InternalError(absl::StrCat("dds_create_waitset: ", dds_strretcode(b->waitset_)));
  }
  for (dds_entity_t r : b->input_->readers()) dds_waitset_attach(b->waitset_, r, r);
  if (b->ros2_.discovery_info) {
    // After every reader and writer of the node exists: the entry lists their GIDs.
    auto entry = PublishDiscoveryInfo(b->node_->participant(), *b->ros2_.discovery_info, names,
                                      b->input_->readers(), {b->points_, b->diagnostics_});
    if (!entry.ok()) return entry.status();
  }
  LogInfo(names, absl::StrCat("input ", std::string(ros_bridge::Name(b->options_.input)), ": subscribed to ",
                              b->input_->Describe(), "; publishing ", *points, " and ",
                              *diagnostics, " (DDS domain ", b->ros2_.domain,
                              "; ros_discovery_info ",
                              b->ros2_.discovery_info
                                  ? std::string(Name(*b->ros2_.discovery_info))
                                  : std::string("off"),
                              ")"));
  return b;
}

// On the stream's receiver thread (dds_write is thread-safe).
void Ros2Bridge::OnCloud(client::Result&& result, const ros_bridge::SentFrame& frame) {
  PointCloud2Sample msg(result.cloud, frame.header);
  const dds_return_t rc = dds_write(points_, msg.sample());
  if (rc != DDS_RETCODE_OK) {
    stats_.PublishError(absl::UnavailableError(
        absl::StrCat("writing ", points_topic_, ": ", dds_strretcode(rc))));
    return;
  }
  stats_.Published();
}

void Ros2Bridge::PublishDiagnostics() {
  const auto now = std::chrono::system_clock::now().time_since_epoch();
  const auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(now).count();
  const auto report = stats_.Report(ns / 1e9, status_name_, options_.server);
  DiagnosticArraySample msg(report, static_cast<std::int32_t>(ns / 1000000000),
                            static_cast<std::uint32_t>(ns % 1000000000));
  dds_write(diagnostics_, msg.sample());
}

void Ros2Bridge::Run(const std::atomic<bool>& stop) {
  using Clock = std::chrono::steady_clock;
  const auto period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(options_.diagnostics_period_s));
  auto next_report = Clock::now() + period;
  while (!stop.load()) {
    // At most 100 ms between looks at `stop` (set by a signal handler).
    const auto until = std::min(next_report, Clock::now() + std::chrono::milliseconds(100));
    const auto wait_ns =
        std::chrono::duration_cast<std::chrono::nanoseconds>(until - Clock::now()).count();
    dds_waitset_wait(waitset_, nullptr, 0, wait_ns > 0 ? wait_ns : 0);
    input_->TakeAll();
    if (Clock::now() >= next_report) {
      PublishDiagnostics();
      next_report += period;
      if (next_report < Clock::now()) next_report = Clock::now() + period;
    }
  }
}

}  // namespace cloudcast::ros2_bridge
