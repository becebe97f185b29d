// What a client sends: a colour image and what gives it depth, all of the same size:
//   DisparityFrame  a disparity map from the robot's own matcher, and the colour image;
//   DepthFrame      a depth image (a depth camera's 16-bit millimetres or float metres), and the
//                   colour image;
//   StereoFrame     a rectified stereo pair (left and right, mono or colour), which the server
//                   matches (StreamConfig.stereo); the points take the left image's colour.
// Each image is raw pixels in memory (core views, not copied until Send), raw pixels to compress
// losslessly, or an encoded image file; plus the frame's metadata. OpenCV users: see opencv.h for
// cv::Mat adapters.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <variant>

#include "cloudcast/core/image.h"
#include "cloudcast/proto/convert.h"

namespace cloudcast::client {

// An image file in memory (PNG, JPEG, TIFF, ...), decoded by the server with OpenCV. Disparity
// must stay lossless (PNG 8/16-bit, TIFF); JPEG suits colour on a thin uplink. The bytes are
// viewed, not owned: keep them alive until Send / Process returns.
struct EncodedImage {
  std::string_view bytes;
};

// Colour pixels in OpenCV's four-channel order (B, G, R, A), e.g. a CV_8UC4 Mat. The protocol has
// no BGRA encoding, so Send drops the alpha while it copies the rows into the request (sent as
// BGR8, a quarter fewer bytes than RGBA, and alpha is ignored by the server anyway).
struct BgraView {
  const void* data = nullptr;
  std::size_t size_bytes = 0;  // how much memory `data` points to
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  std::size_t stride_bytes = 0;  // distance between row starts, >= width x 4
};

// Raw pixels that Send compresses losslessly on the way out (the protocol's CompressedDisparity /
// CompressedColor: a row predictor, then zstd). On camera images it sends about a third of the
// raw bytes for a few milliseconds of client CPU, and the server decodes it in about a millisecond,
// several times cheaper than PNG on both sides (README, cloudcast-uplink-bench). The view is
// read during Send only. `compression` picks the predictor and zstd level; the default is the
// one the uplink table chose. BGRA has no protocol encoding: compress BGR (or RGBA) pixels.
struct CompressedDisparityView {
  DisparityView view;
  convert::Compression compression;
};
struct CompressedDepthView {
  DepthView view;
  convert::Compression compression;
};
struct CompressedColorView {
  ColorView view;
  convert::Compression compression;
};
inline CompressedDisparityView Compressed(const DisparityView& view,
                                          const convert::Compression& compression = {}) {
  return {view, compression};
}
inline CompressedDepthView Compressed(const DepthView& view,
                                      const convert::Compression& compression = {}) {
  return {view, compression};
}
inline CompressedColorView Compressed(const ColorView& view,
                                      const convert::Compression& compression = {}) {
  return {view, compression};
}

// Pixels compressed earlier (convert::ToProto into the protocol message, e.g. on the camera's
// own thread, or once for a recorded sequence): sent as they are, the payload copied into the
// request. Viewed, not owned: keep the message alive until Send / Process returns.
struct PrecompressedDisparity {
  const v1::CompressedDisparity* message = nullptr;
};
struct PrecompressedDepth {
  const v1::CompressedDepth* message = nullptr;
};
struct PrecompressedColor {
  const v1::CompressedColor* message = nullptr;
};
// A picture of a video bitstream, encoded already (the message must outlive Send): what
// cloudcast::video::FrameEncoder (cloudcast/video/frame_encoder.h) makes of raw colour and stereo
// images. The server decodes its bitstreams in the order the pictures were sent (docs/video.md).
struct PrecodedVideo {
  const v1::VideoPicture* message = nullptr;
};

using DisparityInput =
    std::variant<DisparityView, EncodedImage, CompressedDisparityView, PrecompressedDisparity>;
// Depth files: PNG 16-bit (millimetres, as depth cameras record them), TIFF, PFM.
using DepthInput = std::variant<DepthView, EncodedImage, CompressedDepthView, PrecompressedDepth>;
using ColorInput = std::variant<ColorView, BgraView, EncodedImage, CompressedColorView,
                                PrecompressedColor, PrecodedVideo>;

// The images of one frame, by what gives its points their depth.
struct DisparityFrame {
  DisparityInput disparity;
  ColorInput colour;
};
struct DepthFrame {
  DepthInput depth;
  ColorInput colour;
};
// A rectified stereo pair (or one the server rectifies: StreamConfig.stereo.calibration).
struct StereoFrame {
  ColorInput left;  // also the colour of the points
  ColorInput right;
};
using FrameInput = std::variant<DisparityFrame, DepthFrame, StereoFrame>;

// `input` with its raw view, if it holds one, to be compressed; other kinds as they are (a
// BgraView stays raw: the protocol has no BGRA encoding to compress it as).
DisparityInput CompressRaw(const DisparityInput& input,
                           const convert::Compression& compression = {});
DepthInput CompressRaw(const DepthInput& input, const convert::Compression& compression = {});
ColorInput CompressRaw(const ColorInput& input, const convert::Compression& compression = {});
// Every raw view of the frame compressed.
FrameInput CompressRaw(const FrameInput& input, const convert::Compression& compression = {});
// Only the disparity or depth map compressed (losslessly), the colour images as they are: what a
// video coder (StreamOptions::coder, e.g. video::FrameEncoder) is given, since it codes the colour
// images and passes the map through. A stereo pair is returned as it is.
FrameInput CompressGeometry(const FrameInput& input, const convert::Compression& compression = {});

// A frame's metadata, echoed by the server in its reply.
struct FrameMeta {
  // The client's frame counter. Unset: one more than the stream's previous frame (the first
  // frame of a stream, and every Process call, gets 0).
  std::optional<std::uint64_t> sequence;
  // When the images were captured, nanoseconds since the Unix epoch, in this machine's clock.
  // 0: the moment Send is called (latency then excludes capture and the caller's own work).
  std::int64_t capture_time_unix_ns = 0;
  // The camera's coordinate frame, like a ROS frame_id.
  std::string frame_id;
  // This frame's own camera (Frame.camera): each field set overrides the stream's for this frame
  // only (a zoom, an auto-calibration, a CameraInfo per message). Unset: the stream's.
  std::optional<v1::CameraModel> camera;
};

// Nanoseconds since the Unix epoch, now (std::chrono::system_clock).
std::int64_t UnixNanosNow();

}  // namespace cloudcast::client
