// Filling protocol Frames from client inputs (internal to the client library).
#pragma once

#include "absl/status/status.h"
#include "cloudcast/client/frame.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::client::internal {

// Writes both images into `frame`, each pixel byte copied once (or compressed once). Raw rows are
// packed tightly (row_stride 0): padding and ROI surroundings are never sent. Reusing `frame`
// across calls reuses its pixel buffers, so same-sized frames allocate nothing. Checks only what
// memory safety needs (the server judges sizes and limits); on error `frame` is unspecified.
absl::Status FillImages(const DisparityInput& disparity, const ColorInput& colour,
                        v1::Frame* frame);

// The image bytes `frame` carries: raw pixels, compressed payloads or encoded files.
std::uint64_t ImageBytes(const v1::Frame& frame);

// Sets sequence, capture time (now when meta's is 0) and frame_id.
void FillMeta(const FrameMeta& meta, std::uint64_t sequence, v1::Frame* frame);

}  // namespace cloudcast::client::internal
