// Running one frame on a worker: proto Frame -> images -> fused pipeline -> Draco -> CloudReply,
// with the metrics. Stream and Process both run their frames through FrameRunner::Run.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/core/frame_codec.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/core/point.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/v1/cloudcast.pb.h"
#include "frame_input.h"
#include "metrics.h"
#include "stereo_stage.h"

namespace cloudcast::server {

// What one frame cost, for the metrics.
struct FrameCosts {
  double decode_seconds = 0;    // wall time decoding PNG / JPEG (0 for raw images)
  double rectify_seconds = 0;   // stereo pairs with a calibration: remapping both images
  double match_seconds = 0;     // stereo pairs: grey + the matcher
  double pipeline_seconds = 0;  // wall time in Pipeline::Run
  double encode_seconds = 0;    // wall time in EncodeDraco
  double core_cpu_seconds = 0;  // this thread's CPU time in Pipeline::Run + EncodeDraco
  bool decoded = false;
  bool voxels_dropped = false;  // the downlink cap raised the voxel minimum
};

// Holds the scratch a frame needs (pipeline tables and voxel accumulator, the cloud, decoded
// images) so that steady-state frames allocate little. Not thread-safe: one per worker thread.
class FrameProcessor {
 public:
  // `rectifiers`: the rectification maps every worker shares (must outlive the processor).
  explicit FrameProcessor(RectifierCache* rectifiers) : stereo_(rectifiers) {}

  // Fills `reply`'s cloud fields: the echoed sequence / frame_id / capture time, `draco` (written
  // in place), point_count, position_error_bound, position_bits, counts and the decode, pipeline
  // and encode times. Errors: see PrepareFrameImages; pipeline and Draco errors keep the core's
  // code.
  // `in_place`: the frame's pixels RequestReader left in gRPC's slices (see PrepareFrameImages).
  // `video`: the frame's video pictures, decoded when it was read (see PrepareFrameImages).
  absl::Status Process(const v1::Frame& frame, const InPlacePixels* in_place,
                       const FrameSettings& settings, v1::CloudReply* reply, FrameCosts* costs,
                       const DecodedVideo* video = nullptr);

 private:
  // Process with the frame's camera applied and checked.
  absl::Status ProcessWith(const v1::Frame& frame, const InPlacePixels* in_place,
                           const FrameSettings& settings, v1::CloudReply* reply, FrameCosts* costs,
                           const DecodedVideo* video);
  // A frame with pixels whose cloud came out empty: reply.empty says which stage took the last
  // points and why; for the passthrough, `rerun` runs the pipeline again without it to measure
  // the range the points spanned.
  void ExplainEmpty(const StageCounts& counts, const PipelineOptions& options,
                    const std::function<absl::Status(const PipelineOptions&, PointCloud*)>& rerun,
                    v1::CloudReply* reply);

  // The cap's last resort (FrameSettings::cap_min_points_per_voxel): while cloud_ is over the
  // cap at the floors, the voxel minimum `*min_points` goes up a point and the cloud is encoded
  // again into the reply, never to an empty cloud. `*exhausted`: still over the cap with the
  // minimum as high as the settings (or a non-empty cloud) allow.
  absl::Status DropSparseVoxels(const FrameSettings& settings, const DracoOptions& draco,
                                std::uint32_t* min_points, bool* exhausted, v1::CloudReply* reply,
                                DracoEncodeInfo* info);

  Pipeline pipeline_;
  PointCloud cloud_;
  PointCloud sparser_;     // DropSparseVoxels'
  PointCloud unfiltered_;  // ExplainEmpty's
  // ExplainEmpty measures the range the points spanned on one frame in kRangeEvery emptied by
  // the passthrough (on this worker).
  static constexpr std::uint64_t kRangeEvery = 32;
  std::uint64_t empty_by_passthrough_ = 0;
  DecodeScratch decode_;
  StereoStage stereo_;
  PlaneCompressor disparity_compressor_;  // the disparity map sent back on request
};

// When a frame had arrived whole.
struct Arrival {
  std::chrono::steady_clock::time_point time;
  std::int64_t unix_ns = 0;
  std::uint64_t stream_bytes = 0;  // the call's request bytes read by then (Stream calls)
};

// One FrameProcessor per worker, and the bookkeeping every frame gets.
class FrameRunner {
 public:
  // A worker that ran a frame of more than `keep_scratch_pixels` pixels gives its scratch back
  // afterwards (a fresh FrameProcessor), so that one huge frame does not stay resident.
  FrameRunner(int workers, Metrics* metrics, std::string instance,
              std::uint64_t keep_scratch_pixels = ~std::uint64_t{0});

  // On worker `worker`: processes `frame` into `reply`, which gets everything but its send time
  // and frames_dropped (the writer's). Counts the frame, its stage times and CPU, or its error.
  // `in_place`: as for FrameProcessor::Process (nullptr: the pixels are in `frame`).
  absl::Status Run(std::size_t worker, const v1::Frame& frame, const InPlacePixels* in_place,
                   const FrameSettings& settings, const Arrival& arrival, v1::CloudReply* reply,
                   const DecodedVideo* video = nullptr);

  const std::string& instance() const { return instance_; }

  // Gives every idle worker's scratch back (a worker in the middle of a frame keeps its own):
  // for a server that has gone idle. Thread-safe. The workers that did.
  int ReleaseIdleScratch();

 private:
  const std::uint64_t keep_scratch_pixels_;
  // processors_[i] is used by worker i under scratch_mu_[i], which ReleaseIdleScratch tries.
  std::unique_ptr<std::mutex[]> scratch_mu_;
  RectifierCache rectifiers_;  // before processors_, which point at it
  std::vector<std::unique_ptr<FrameProcessor>> processors_;
  Metrics* const metrics_;
  const std::string instance_;
};

// This thread's CPU time in seconds (CLOCK_THREAD_CPUTIME_ID).
double ThreadCpuSeconds();

}  // namespace cloudcast::server
