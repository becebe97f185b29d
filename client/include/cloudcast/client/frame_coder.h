// A stream's frame coder: what turns a raw frame into the frame that is sent, at the moment the
// stream can send it (StreamOptions::coder). For coders whose output must never be dropped once
// made: a video encoder, whose every picture is a reference for the next (cloudcast/video/
// frame_encoder.h implements it; the client library itself links no codec). With one set and
// DELIVERY_LATEST, Send keeps the newest raw frame while the stream has no room for it (the write
// slot busy, or the rate controller's window full) and encodes it once there is: a newer raw
// frame replaces the kept one (reported as kReplaced), never an encoded one.
#pragma once

#include <cstdint>
#include <optional>

#include "absl/status/statusor.h"
#include "cloudcast/client/frame.h"
#include "cloudcast/client/result.h"

namespace cloudcast::client {

class FrameCoder {
 public:
  virtual ~FrameCoder() = default;
  // The frame to send for `raw`, numbered `sequence`; it may view memory the coder owns until
  // the next Encode. Called one at a time, in sequence order, on the sending thread or on one of
  // gRPC's callback threads (a kept frame encoded when the stream has room).
  virtual absl::StatusOr<FrameInput> Encode(const FrameInput& raw, std::uint64_t sequence) = 0;
  // The fate of each frame this coder encoded (a reply, or dropped, lost, unsent), on gRPC's
  // callback threads: a video encoder learns here that the server needs a keyframe. Raw frames
  // replaced before they were encoded never reach it.
  virtual void OnResult(const Result& result) = 0;
  // With StreamOptions::rate_control, before each Encode: the controller's target for the whole
  // stream, and the bytes the last frame carried beside what this coder made (a lossless
  // disparity or depth map, a raw image): the coder's own share is what is left.
  virtual void SetStreamBitrate(std::int64_t stream_bps, std::size_t other_bytes_per_frame) = 0;

  // The resolution the last Encode made its frame at. A coder whose floor is a lower resolution
  // than the camera's (AdaptiveJpegCoder: half) gives that frame its own camera, which the stream
  // sends as Frame.camera in place of FrameMeta::camera, and the frame's Result says so
  // (Result::resolution_divisor). Default: the camera's resolution, the caller's camera.
  struct Resolution {
    int divisor = 1;                        // 1: the camera's; 2: half its width and height
    std::optional<v1::CameraModel> camera;  // set with divisor > 1
  };
  virtual Resolution last_resolution() const { return {}; }
};

}  // namespace cloudcast::client
