// Filling protocol Frames from client inputs (internal to the client library).
#pragma once

#include <grpcpp/support/byte_buffer.h>

#include <cstdint>
#include <deque>
#include <memory>
#include <string>

#include "absl/status/status.h"
#include "cloudcast/client/frame.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::client::internal {

// Writes the frame's images into `frame`, each pixel byte copied once (or compressed once). Raw
// rows are packed tightly (row_stride 0): padding and ROI surroundings are never sent. Reusing
// `frame` across calls reuses its pixel buffers, so same-sized frames allocate nothing. Checks only
// what memory safety needs (the server judges sizes and limits); on error `frame` is unspecified.
absl::Status FillImages(const FrameInput& input, v1::Frame* frame);
// One image each, as FillImages fills them; `field` names it in errors.
absl::Status FillDisparity(const DisparityInput& disparity, v1::DisparityImage* image);
absl::Status FillDepth(const DepthInput& depth, v1::DepthImage* image);
absl::Status FillColour(const ColorInput& colour, v1::ColorImage* image,
                        const char* field = "colour");

// The image bytes `frame` carries: raw pixels, compressed payloads or encoded files.
std::uint64_t ImageBytes(const v1::Frame& frame);

// Sets sequence, capture time (now when meta's is 0) and frame_id.
void FillMeta(const FrameMeta& meta, std::uint64_t sequence, v1::Frame* frame);

// A frame kept past Send (a raw frame waiting for room to be encoded: StreamOptions::coder): every
// image copied, raw rows packed tightly, messages and files copied; input() views the copies.
// Checks what memory safety needs, as FillImages does.
class HeldFrame {
 public:
  absl::Status Hold(const FrameInput& input);
  const FrameInput& input() const { return input_; }

 private:
  template <typename View>
  absl::Status Keep(const View& view, const char* field, View* out);
  template <typename Input>
  absl::Status KeepImage(const Input& in, const char* field, Input* out);

  FrameInput input_;
  std::deque<std::string> bytes_;  // pixels and files (a deque: the views stay where they are)
  std::deque<std::shared_ptr<const google::protobuf::Message>> messages_;
};

// A StreamRequest holding one frame, as the bytes gRPC writes, with each raw image's pixels copied
// once: from the caller's rows straight into a slice of their own. Protobuf's serializer would
// copy them twice (into the message, then into gRPC's slices), which is 40% of a robot's CPU per
// raw frame. Those pixels go as a second occurrence of the frame field that holds only them;
// protobuf merges repeated occurrences of a message field, so every reader parses the one message
// ToProto would have made. Everything else is serialized as usual. Reused from frame to frame;
// not thread-safe.
class RequestWriter {
 public:
  // Fills `out` (see FillImages for the checks; on error `out` is unspecified).
  absl::Status Write(const FrameInput& input, const FrameMeta& meta, std::uint64_t sequence,
                     grpc::ByteBuffer* out);
  // The last frame written, but for the raw pixels, which are only in the bytes.
  const v1::Frame& frame() const { return request_.frame(); }
  // The image bytes of the last frame written (as ImageBytes, raw pixels included).
  std::uint64_t image_bytes() const { return image_bytes_; }

 private:
  v1::StreamRequest request_;
  std::string head_;  // the serialized request, then the pixels' headers
  std::uint64_t image_bytes_ = 0;
};

}  // namespace cloudcast::client::internal
