#include "frame_processor.h"

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <exception>
#include <functional>
#include <limits>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/draco_codec.h"

namespace cloudcast::server {
namespace {

using Clock = std::chrono::steady_clock;

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

std::uint32_t Micros(double seconds) {
  return static_cast<std::uint32_t>(std::clamp(seconds * 1e6, 0.0, 4.0e9));
}

// "z in [3, 12]", "x outside [-1, 1]", with the server's "no limit" floats shown as such.
std::string RangeText(const PassThroughParams& pt) {
  auto limit = [](float v) {
    if (v <= std::numeric_limits<float>::lowest()) return std::string("-inf");
    if (v >= std::numeric_limits<float>::max()) return std::string("+inf");
    return absl::StrCat(v);
  };
  return absl::StrCat(std::string(Name(pt.axis)), pt.negative ? " outside [" : " in [",
                      limit(pt.min), ", ", limit(pt.max), "]");
}

// A cloud over config.draco.max_cloud_bytes at the floors of both bit depths: which bounds set
// those floors, for a client to loosen one (contract revision 4).
void ExplainOverCap(const DracoOptions& draco, const DracoEncodeInfo& info,
                    std::uint32_t min_points, bool points_exhausted, v1::OverCap* out) {
  constexpr char kCap[] = "config.draco.max_cloud_bytes";
  out->set_field(kCap);
  out->set_max_cloud_bytes(draco.max_cloud_bytes);
  out->set_cloud_bytes(info.bytes);
  const bool bounded = draco.max_position_error > 0.0f;
  const std::string position_bound =
      bounded ? "config.draco.max_position_error" : "config.draco.position_bits";
  const std::string color_bound = draco.min_color_bits < draco.color_bits
                                      ? "config.draco.min_color_bits"
                                      : "config.draco.color_bits";
  constexpr char kPointsBound[] = "config.draco.cap_min_points_per_voxel";
  out->add_limited_by(position_bound);
  out->add_limited_by(color_bound);
  if (points_exhausted) out->add_limited_by(kPointsBound);
  out->set_message(absl::StrCat(
      "the cloud takes ", info.bytes, " bytes at ", info.position_bits, " position bits (",
      bounded ? absl::StrCat("the fewest that keep ", position_bound, " ", draco.max_position_error)
              : absl::StrCat(position_bound, "; no error bound"),
      ") and ", info.color_bits, " colour bits (", color_bound, ")",
      points_exhausted
          ? absl::StrCat(", voxels of at least ", min_points, " points (", kPointsBound, ")")
          : "",
      ", over ", kCap, " ", draco.max_cloud_bytes));
}

}  // namespace

void FrameProcessor::ExplainEmpty(
    const StageCounts& counts, const PipelineOptions& options,
    const std::function<absl::Status(const PipelineOptions&, PointCloud*)>& rerun,
    v1::CloudReply* reply) {
  if (counts.pixels == 0 || counts.after_voxel > 0) return;
  v1::EmptyCloud* empty = reply->mutable_empty();
  if (counts.valid_points == 0) {
    empty->set_stage(v1::STAGE_CONVERSION);
    empty->set_reason("NO_VALID_PIXELS");
    empty->set_message(absl::StrCat(
        "conversion: none of the ", counts.pixels,
        " pixels had a valid disparity or depth (0, NaN, infinite, an invalid disparity value, "
        "or a point behind the camera): check the image's encoding and config.camera"));
    return;
  }
  if (counts.after_passthrough == 0) {
    const PassThroughParams& pt = options.passthrough;
    empty->set_stage(v1::STAGE_PASSTHROUGH);
    empty->set_reason("OUTSIDE_RANGE");
    std::string seen;
    // The points the passthrough saw, once more without it, for the range they span: only for a
    // frame that came out empty, so the common case pays nothing, and only for one such frame in
    // kRangeEvery on this worker. The rerun costs as much as the frame did, and a camera set up
    // for the wrong range (New Tsukuba's far frames under the paper's passthrough, a robot's
    // wrong unit) sends such frames 30 times a second: measured every time, it doubled their
    // cost (11 % of a loopback benchmark's server CPU).
    PipelineOptions unfiltered = options;
    unfiltered.passthrough.enabled = false;
    unfiltered.voxel.enabled = false;
    const bool measure = empty_by_passthrough_++ % kRangeEvery == 0;
    if (!measure) {
      seen = absl::StrCat(" (the range the points spanned is measured on one such frame in ",
                          kRangeEvery, ")");
    } else if (rerun(unfiltered, &unfiltered_).ok() && !unfiltered_.empty()) {
      const int axis = pt.axis == Axis::kX ? 0 : pt.axis == Axis::kY ? 1 : 2;
      float lo = std::numeric_limits<float>::max();
      float hi = std::numeric_limits<float>::lowest();
      for (const Point& p : unfiltered_.points) {
        const float v = axis == 0 ? p.x : axis == 1 ? p.y : p.z;
        if (!std::isfinite(v)) continue;
        lo = std::min(lo, v);
        hi = std::max(hi, v);
      }
      if (lo <= hi) {
        empty->set_observed_min(lo);
        empty->set_observed_max(hi);
        seen = absl::StrCat(", and the points' ", std::string(Name(pt.axis)), " lies in [", lo,
                            ", ", hi, "]");
      }
      unfiltered_.ResizeUnorganized(0);
    }
    empty->set_message(absl::StrCat("passthrough removed all ", counts.valid_points,
                                    " valid points: it keeps ", RangeText(pt),
                                    " (config.passthrough)", seen,
                                    "; x, y and z are in the unit of the depth or the baseline"));
    return;
  }
  empty->set_stage(v1::STAGE_VOXEL_GRID);
  empty->set_reason("VOXELS_UNDER_MIN_POINTS");
  empty->set_message(absl::StrCat(
      "voxel grid: none of its voxels held ", options.voxel.min_points_per_voxel, " of the ",
      counts.after_passthrough, " points (config.voxel_grid.min_points_per_voxel)"));
}

double ThreadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + static_cast<double>(ts.tv_nsec) * 1e-9;
}

absl::Status FrameProcessor::Process(const v1::Frame& frame, const InPlacePixels* in_place,
                                     const FrameSettings& settings, v1::CloudReply* reply,
                                     FrameCosts* costs, const DecodedVideo* video) {
  *costs = FrameCosts{};
  reply->set_sequence(frame.sequence());
  reply->set_frame_id(frame.frame_id());
  reply->set_capture_time_unix_ns(frame.capture_time_unix_ns());

  // The frame's own camera, field by field over the stream's; then the camera this frame needs.
  const FrameSettings* effective = &settings;
  FrameSettings with_frame_camera;
  if (frame.has_camera()) {
    with_frame_camera = settings;
    if (absl::Status s = convert::ApplyCamera(frame.camera(), "frame.camera", &with_frame_camera);
        !s.ok()) {
      return s;
    }
    effective = &with_frame_camera;
  }
  if (frame.geometry_case() != v1::Frame::GEOMETRY_NOT_SET) {
    if (absl::Status s = convert::RequireCamera(*effective, frame.geometry_case()); !s.ok()) {
      return s;
    }
  }
  return ProcessWith(frame, in_place, *effective, reply, costs, video);
}

absl::Status FrameProcessor::ProcessWith(const v1::Frame& frame, const InPlacePixels* in_place,
                                         const FrameSettings& settings, v1::CloudReply* reply,
                                         FrameCosts* costs, const DecodedVideo* video) {
  const Clock::time_point t0 = Clock::now();
  FrameImages images;
  if (absl::Status s =
          PrepareFrameImages(frame, settings.pipeline.limits, &decode_, &images, in_place, video);
      !s.ok()) {
    return s;
  }
  const Clock::time_point t1 = Clock::now();
  costs->decoded = images.decoded;
  costs->decode_seconds = images.decoded ? Seconds(t1 - t0) : 0.0;
  // Video pictures were decoded when the frame was read (video_input.h): their time counts here.
  if (video != nullptr) costs->decode_seconds += video->decode_seconds;

  const PipelineOptions options = settings.PipelineFor(images.colour.width, images.colour.height);
  StageCounts counts;
  const double cpu0 = ThreadCpuSeconds();
  absl::Status status;
  PipelineOptions ran = options;
  MatchedPair pair;
  switch (images.kind) {
    case FrameKind::kDisparity:
      status = pipeline_.Run(options, images.disparity, images.colour, &cloud_, &counts);
      break;
    case FrameKind::kDepth:
      status = pipeline_.Run(options, images.depth, images.colour, &cloud_, &counts);
      break;
    case FrameKind::kStereo: {
      // The stream's camera for this size; a calibration gives the rectified one instead.
      status = stereo_.Match(images.colour, images.right, settings, options.camera,
                             settings.pipeline.limits.max_stereo_volume, &pair);
      costs->rectify_seconds = pair.rectify_seconds;
      costs->match_seconds = pair.match_seconds;
      if (!status.ok()) break;
      ran.camera = pair.camera;
      status = pipeline_.Run(ran, pair.disparity, pair.colour, &cloud_, &counts);
      if (status.ok() && settings.stereo.return_disparity) {
        status = convert::ToProto(pair.disparity, convert::Compression{}, "disparity",
                                  reply->mutable_disparity(), &disparity_compressor_);
      }
      break;
    }
  }
  const Clock::time_point t2 = Clock::now();
  DracoEncodeInfo info;
  const DracoOptions draco = settings.Draco();
  if (status.ok()) {
    // Straight into the reply's own buffer: no copy of the compressed cloud afterwards. With a
    // cap (config.draco.max_cloud_bytes) the encoder chooses the bits itself, in 1 to 3 encodes.
    status = EncodeDraco(cloud_, draco, reply->mutable_draco(), &info);
  }
  std::uint32_t min_points = ran.voxel.enabled ? ran.voxel.min_points_per_voxel : 0;
  bool points_exhausted = false;
  if (status.ok() && info.over_cap && ran.voxel.enabled) {
    const std::uint32_t configured = min_points;
    status = DropSparseVoxels(settings, draco, &min_points, &points_exhausted, reply, &info);
    counts.after_voxel = cloud_.size();
    costs->voxels_dropped = min_points != configured;
  }
  const double cpu1 = ThreadCpuSeconds();
  const Clock::time_point t3 = Clock::now();
  // The pipeline's time without the matching, which has a stage time of its own.
  costs->pipeline_seconds =
      std::max(0.0, Seconds(t2 - t1) - costs->rectify_seconds - costs->match_seconds);
  costs->encode_seconds = Seconds(t3 - t2);
  costs->core_cpu_seconds = cpu1 - cpu0;
  // The settings were checked when the StreamConfig was resolved, so what fails here is the
  // frame (e.g. a cloud too wide for 30 position bits under the error bound).
  if (!status.ok()) return status;

  ExplainEmpty(
      counts, ran,
      [&](const PipelineOptions& o, PointCloud* out) {
        switch (images.kind) {
          case FrameKind::kDisparity:
            return pipeline_.Run(o, images.disparity, images.colour, out);
          case FrameKind::kDepth:
            return pipeline_.Run(o, images.depth, images.colour, out);
          case FrameKind::kStereo:
            return pipeline_.Run(o, pair.disparity, pair.colour, out);
        }
        return absl::OkStatus();
      },
      reply);
  reply->set_point_count(static_cast<std::uint32_t>(counts.after_voxel));
  reply->set_position_error_bound(info.position_error_bound);
  reply->set_position_bits(info.position_bits);
  reply->set_color_bits(info.color_bits);
  reply->set_min_points_per_voxel(min_points);
  if (info.over_cap) {
    ExplainOverCap(draco, info, min_points, points_exhausted, reply->mutable_over_cap());
  }
  v1::StageCounts* c = reply->mutable_counts();
  c->set_pixels(counts.pixels);
  c->set_valid_points(counts.valid_points);
  c->set_after_passthrough(counts.after_passthrough);
  c->set_after_voxel_grid(counts.after_voxel);
  v1::StageTimes* t = reply->mutable_times();
  t->set_decode_us(Micros(costs->decode_seconds));
  t->set_pipeline_us(Micros(costs->pipeline_seconds));
  t->set_encode_us(Micros(costs->encode_seconds));
  t->set_rectify_us(Micros(costs->rectify_seconds));
  t->set_match_us(Micros(costs->match_seconds));
  return absl::OkStatus();
}

absl::Status FrameProcessor::DropSparseVoxels(const FrameSettings& settings,
                                              const DracoOptions& draco, std::uint32_t* min_points,
                                              bool* exhausted, v1::CloudReply* reply,
                                              DracoEncodeInfo* info) {
  const std::uint32_t most = settings.cap_min_points_per_voxel;
  *exhausted = most > 0;
  // 0 and 1 both keep every voxel (PCL): the first step that drops any is 2.
  for (std::uint32_t k = std::max<std::uint32_t>(*min_points, 1) + 1; k <= most; ++k) {
    if (absl::Status s = pipeline_.RefilterVoxels(k, &sparser_); !s.ok()) return s;
    // The cloud is what the robot drives by: an over-cap cloud beats none.
    if (sparser_.size() == 0) return absl::OkStatus();
    std::swap(cloud_, sparser_);
    *min_points = k;
    if (absl::Status s = EncodeDraco(cloud_, draco, reply->mutable_draco(), info); !s.ok()) {
      return s;
    }
    if (!info->over_cap) {
      *exhausted = false;
      return absl::OkStatus();
    }
  }
  return absl::OkStatus();
}

FrameRunner::FrameRunner(int workers, Metrics* metrics, std::string instance,
                         std::uint64_t keep_scratch_pixels)
    : keep_scratch_pixels_(keep_scratch_pixels),
      scratch_mu_(new std::mutex[static_cast<std::size_t>(std::max(workers, 1))]),
      metrics_(metrics),
      instance_(std::move(instance)) {
  // One frame per worker, one worker per core: OpenCV's matchers must not fan out over the cores
  // the other workers use.
  stereo::SetOpenCvThreads(1);
  for (int i = 0; i < workers; ++i) {
    processors_.push_back(std::make_unique<FrameProcessor>(&rectifiers_));
  }
}

int FrameRunner::ReleaseIdleScratch() {
  int released = 0;
  for (std::size_t i = 0; i < processors_.size(); ++i) {
    std::unique_lock<std::mutex> lock(scratch_mu_[i], std::try_to_lock);
    if (!lock.owns_lock()) continue;
    processors_[i] = std::make_unique<FrameProcessor>(&rectifiers_);
    ++released;
  }
  return released;
}

absl::Status FrameRunner::Run(std::size_t worker, const v1::Frame& frame,
                              const InPlacePixels* in_place, const FrameSettings& settings,
                              const Arrival& arrival, v1::CloudReply* reply,
                              const DecodedVideo* video) {
  const Clock::time_point start = Clock::now();
  Metrics& m = *metrics_;
  m.queue_seconds.Observe(Seconds(start - arrival.time));
  const double cpu0 = ThreadCpuSeconds();
  FrameCosts costs;
  std::unique_lock<std::mutex> scratch(scratch_mu_[worker]);
  absl::Status status;
  // No exception may leave a worker (it would end the process): each is this frame's error.
  // The inputs of every library call are bounded before it (OpenCV's matchers: budget.h), so
  // this is the last line, not the first.
  try {
    status = processors_[worker]->Process(frame, in_place, settings, reply, &costs, video);
  } catch (const std::exception& e) {
    status = absl::InternalError(
        absl::StrCat("frame ", frame.sequence(), ": the server failed processing it: ", e.what()));
  } catch (...) {
    status = absl::InternalError(
        absl::StrCat("frame ", frame.sequence(), ": the server failed processing it"));
  }
  if (!status.ok() && status.code() == absl::StatusCode::kInternal) {
    // Its scratch may be half-built: start the next frame on a fresh one.
    processors_[worker] = std::make_unique<FrameProcessor>(&rectifiers_);
  }
  // Scratch sized for a huge frame would stay resident for the frames after it.
  if (EstimateFrameMemory(frame).pixels > keep_scratch_pixels_) {
    processors_[worker] = std::make_unique<FrameProcessor>(&rectifiers_);
  }
  scratch.unlock();
  m.core_cpu_seconds.Increment(costs.core_cpu_seconds);
  if (status.ok()) {
    reply->mutable_times()->set_queue_us(Micros(Seconds(start - arrival.time)));
    reply->set_receive_time_unix_ns(arrival.unix_ns);
    reply->set_stream_bytes_received(arrival.stream_bytes);
    reply->set_server_instance(instance_);
    m.frames_processed.Increment();
    if (reply->has_over_cap()) m.replies_over_cap.Increment();
    if (costs.voxels_dropped) m.replies_voxels_dropped.Increment();
    m.pipeline_seconds.Observe(costs.pipeline_seconds);
    m.encode_seconds.Observe(costs.encode_seconds);
    if (costs.decoded) m.decode_seconds.Observe(costs.decode_seconds);
    if (costs.match_seconds > 0) {
      m.match_seconds.Observe(costs.rectify_seconds + costs.match_seconds);
    }
  } else {
    m.FrameErrors(status.code()).Increment();
  }
  m.worker_cpu_seconds.Increment(ThreadCpuSeconds() - cpu0);
  return status;
}

}  // namespace cloudcast::server
