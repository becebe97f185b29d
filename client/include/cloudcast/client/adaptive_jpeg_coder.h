// A frame coder for StreamOptions::rate_control over a thin link: the colour as JPEG at a quality
// that follows the rate controller's target frame by frame (QualityFollower), the disparity or
// depth lossless (row deltas + zstd), and below the lowest quality at the camera's resolution a
// floor at half resolution (half_resolution.h): when even quality `min_quality` at full
// resolution came out over the target's bytes per frame (or the lossless disparity or depth
// alone did, which no quality can help), frames go at half their width and height, their own
// camera halved to match (FrameCoder::last_resolution), until the target carries a
// full-resolution frame again. What cloudcast-client --rate-control --encoding jpeg
// runs; cloudcast-load's ladder (FrameStore) halves its frames the same way.
//
// Takes raw frames (Stream::Send with StreamOptions::coder set): disparity or depth frames whose
// images are raw views (DisparityView or DepthView, or their Compressed views; ColorView), or
// stereo pairs of ColorViews (both JPEG, no half floor: a pair's calibration is the server's).
// Needs OpenCV's JPEG encoder: part of cloudcast_client_opencv.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "cloudcast/client/frame_coder.h"
#include "cloudcast/client/half_resolution.h"
#include "cloudcast/client/rate_controller.h"
#include "cloudcast/proto/convert.h"

namespace cloudcast::client {

struct AdaptiveJpegOptions {
  // The camera's frame rate: the target bitrate over it is a frame's budget in bytes.
  double fps = 30;
  int start_quality = 90;
  int min_quality = 10;
  int max_quality = 95;
  // Below min_quality at full resolution, go to half (disparity and depth frames).
  bool half_resolution_floor = true;
  // Back to full resolution once the target's bytes per frame are this multiple of what the
  // last full-resolution frame at min_quality took (room to spare, so it does not flap).
  double full_resolution_margin = 1.15;
  // The stream's camera as its StreamConfig sends it (StreamConfig::camera): halved
  // (HalfResolutionCamera) as each half-resolution frame's own camera, which replaces any
  // FrameMeta::camera of that frame.
  v1::CameraModel stream_camera;
  // The lossless compression of disparity and depth.
  convert::Compression compression;
};

class AdaptiveJpegCoder : public FrameCoder {
 public:
  explicit AdaptiveJpegCoder(AdaptiveJpegOptions options);

  absl::StatusOr<FrameInput> Encode(const FrameInput& raw, std::uint64_t sequence) override;
  void OnResult(const Result& result) override {}
  void SetStreamBitrate(std::int64_t stream_bps, std::size_t other_bytes_per_frame) override;
  Resolution last_resolution() const override;

  // A camera that changes mid-stream (a ROS CameraInfo may; any thread): frames numbered
  // `from_sequence` and later are halved from `camera` instead of stream_camera, so that a
  // half-resolution frame always carries its own camera halved. Never called: stream_camera.
  void SetCamera(std::uint64_t from_sequence, v1::CameraModel camera);

  // The last frame made (any thread): its JPEG quality, whether it was at half resolution, and
  // its image bytes (all of them: the coder makes every image).
  int last_quality() const { return last_quality_.load(); }
  bool last_half() const { return last_half_.load(); }
  std::size_t last_bytes() const { return last_bytes_.load(); }
  // Of them, the lossless disparity or depth (0 for a stereo pair).
  std::size_t last_geometry_bytes() const { return last_geometry_bytes_.load(); }

 private:
  // Adjusts quality and resolution to how the last frame fared against the budget now.
  void Follow(bool halvable);
  absl::Status EncodeColour(const ColorInput& colour, const char* field, std::string* out);

  AdaptiveJpegOptions options_;
  std::int64_t stream_bps_ = 0;  // 0: no target yet (the first frames)
  QualityFollower full_, half_;
  bool at_half_ = false;
  bool disparity_frame_ = true;       // the last frame's kind (its half camera halves disparity)
  bool made_ = false;                 // a frame was made (last_* are set)
  std::size_t full_floor_bytes_ = 0;  // the last full-resolution frame at min_quality
  HalfResolutionFrame halved_;
  v1::CameraModel camera_;  // the camera of the frame being made (stream_camera until SetCamera)
  std::mutex cameras_mu_;
  std::vector<std::pair<std::uint64_t, v1::CameraModel>> cameras_;  // SetCamera's, not yet due
  std::string colour_jpeg_, right_jpeg_;
  v1::CompressedDisparity disparity_;
  v1::CompressedDepth depth_;
  std::atomic<int> last_quality_{0};
  std::atomic<bool> last_half_{false};
  std::atomic<std::size_t> last_bytes_{0};
  std::atomic<std::size_t> last_geometry_bytes_{0};
};

}  // namespace cloudcast::client
