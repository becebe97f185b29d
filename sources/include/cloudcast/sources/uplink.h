// How a source's frames travel to the server: the --encoding of cloudcast-client and
// cloudcast-load, and the one place that turns a SourceFrame into what the uplink carries.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "cloudcast/client/frame.h"
#include "cloudcast/client/opencv.h"
#include "cloudcast/core/near_lossless.h"
#include "cloudcast/core/settings.h"
#include "cloudcast/sources/frame.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::sources {

enum class Uplink {
  kRaw,   // pixels as they are: the fastest on loopback and fast links
  kZstd,  // both images compressed losslessly (row deltas + zstd): about a third of raw, and
          // cheap on both sides
  kPng,   // both images as files, losslessly: PNG, and TIFF for a float disparity or depth (PNG
          // has no float samples)
  kJpeg,  // colour (and a stereo pair's right image) as JPEG (lossy), disparity and depth as
          // with kPng: the thinnest uplink
};
// "raw", "zstd", "png", "jpeg" (what the --encoding flags accept).
bool ParseUplink(std::string_view name, Uplink* out);
const char* Name(Uplink uplink);
const std::vector<std::string>& UplinkNames();

struct UplinkOptions {
  Uplink encoding = Uplink::kRaw;
  int jpeg_quality = client::kDefaultJpegQuality;  // 1..100, kJpeg
  int png_compression = 1;                         // 0..9, kPng and kJpeg's disparity
  // Near-lossless disparity and depth (core/near_lossless.h): the most any point may move, in
  // the cloud's units (metres), per point, in the camera's REP 103 optical frame. 0 (the
  // default): lossless. Applies before every encoding (it pays with zstd and png).
  double max_point_error = 0;
  // With max_point_error: the camera the stream sends (principal point unset: each frame's
  // centre, as the server resolves it).
  FrameSettings camera{};
};

// One frame's images as the uplink carries them, of any kind (disparity + colour, depth +
// colour, a stereo pair). Raw and zstd frames view the source's Mats (held here, so they stay
// alive); zstd is compressed by whoever consumes the images (Send, or ToProto), so nothing is
// compressed twice; png and jpeg frames are encoded by Encode.
class UplinkFrame {
 public:
  // Prepares `frame` for `options`. Errors name the image ("disparity Mat has type ...").
  absl::Status Encode(const SourceFrame& frame, const UplinkOptions& options);

  FrameKind kind() const { return kind_; }
  // As client inputs, for Stream::Send. They view this object: keep it until Send returns.
  // input() is the whole frame (the kind's client::FrameInput alternative).
  client::FrameInput input() const;
  // Its images, each as a view of its Mat (kRaw, kZstd) or as a file; those the kind has
  // (colour() is a stereo pair's left image).
  client::DisparityInput disparity() const;
  client::DepthInput depth() const;
  client::ColorInput colour() const;
  client::ColorInput right() const;
  // Writes the images into `frame`'s image fields (cloudcast-load's prepared requests).
  absl::Status ToProto(v1::Frame* frame) const;

  // A float disparity or depth went as TIFF (kPng and kJpeg), worth a note to the user once.
  bool float_disparity_as_tiff() const { return float_as_tiff_; }
  // What the near-lossless quantizer did to the disparity or depth of the last Encode whose
  // options had max_point_error > 0 (cloudcast-load's report of what the bound changed).
  const QuantizeStats& quantize_stats() const { return quantizer_.stats(); }

 private:
  FrameKind kind_ = FrameKind::kDisparity;
  Uplink encoding_ = Uplink::kRaw;
  cv::Mat geometry_mat_, colour_mat_, right_mat_;  // kRaw, kZstd
  client::DisparityInput disparity_view_;
  client::DepthInput depth_view_;
  client::ColorInput colour_view_, right_view_;
  std::string geometry_file_, colour_file_, right_file_;  // kPng, kJpeg
  bool float_as_tiff_ = false;
  PointErrorQuantizer quantizer_;  // owns the quantized disparity or depth the views point into
};

}  // namespace cloudcast::sources
