// One worker's frame processing: proto Frame -> images -> fused pipeline -> Draco -> CloudReply.
#pragma once

#include "absl/status/status.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/core/point.h"
#include "cloudcast/v1/cloudcast.pb.h"
#include "frame_input.h"
#include "options.h"

namespace cloudcast::server {

// What one frame cost, for the metrics.
struct FrameCosts {
  double decode_seconds = 0;    // wall time decoding PNG / JPEG (0 for raw images)
  double pipeline_seconds = 0;  // wall time in Pipeline::Run
  double encode_seconds = 0;    // wall time in EncodeDraco
  double core_cpu_seconds = 0;  // this thread's CPU time in Pipeline::Run + EncodeDraco
  bool decoded = false;
};

// Holds the scratch a frame needs (pipeline tables and voxel accumulator, the cloud, decoded
// images) so that steady-state frames allocate little. Not thread-safe: one per worker thread.
class FrameProcessor {
 public:
  // Fills `reply`'s cloud fields: the echoed sequence / frame_id / capture time, `draco` (written
  // in place), point_count, position_error_bound, position_bits, counts and the decode, pipeline
  // and encode times. Leaves queue time, receive / send times and frames_dropped to the caller.
  // Errors: see PrepareFrameImages; pipeline and Draco errors keep the core's code.
  absl::Status Process(const v1::Frame& frame, const StreamSettings& settings,
                       v1::CloudReply* reply, FrameCosts* costs);

 private:
  Pipeline pipeline_;
  PointCloud cloud_;
  DecodeScratch decode_;
};

// This thread's CPU time in seconds (CLOCK_THREAD_CPUTIME_ID).
double ThreadCpuSeconds();

}  // namespace cloudcast::server
