// Near-lossless disparity and depth for Stream::Send and Client::Process (docs/client.md,
// "Near-lossless disparity and depth"): the frame's disparity or depth quantized so that no point
// the server makes moves by more than `max_point_error` (core/near_lossless.h), then sent as
// usual, e.g. compressed: stream.Send(NearLossless(CompressRaw(frame), camera, 0.0075, &q)).
#pragma once

#include "absl/status/statusor.h"
#include "cloudcast/client/frame.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/core/near_lossless.h"

namespace cloudcast::client {

// `input` with its disparity or depth, a raw view or a Compressed view, replaced by the same kind
// viewing `quantizer`'s buffer (valid until its next use: keep it until Send returns), quantized
// for `max_point_error` (metres per point, in the camera's REP 103 optical frame; 0: unchanged)
// with `camera`, the one the server converts with (the stream's, principal point resolved for the
// frame's size: FrameSettings::PipelineFor). Colour and stereo pairs pass as they are. An encoded
// file or a precompressed message cannot be quantized: INVALID_ARGUMENT naming "disparity" or
// "depth"; bad views, cameras or bounds as PointErrorQuantizer::Quantize says.
absl::StatusOr<FrameInput> NearLossless(const FrameInput& input, const CameraModel& camera,
                                        double max_point_error, PointErrorQuantizer* quantizer);

}  // namespace cloudcast::client
