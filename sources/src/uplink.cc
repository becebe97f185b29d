#include "cloudcast/sources/uplink.h"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "absl/strings/str_cat.h"
#include "cloudcast/proto/convert.h"

namespace cloudcast::sources {
namespace {

struct Named {
  Uplink uplink;
  const char* name;
};
constexpr Named kUplinks[] = {
    {Uplink::kRaw, "raw"}, {Uplink::kZstd, "zstd"}, {Uplink::kPng, "png"}, {Uplink::kJpeg, "jpeg"}};

// The input kinds below are picked out one by one (not visited), so a kind the client library
// adds later is an error here until it is handled, not a compile failure.
absl::Status DisparityToProto(const client::DisparityInput& input, v1::DisparityImage* image) {
  if (const auto* raw = std::get_if<DisparityView>(&input)) {
    return convert::ToProto(*raw, "disparity", image->mutable_raw());
  }
  if (const auto* z = std::get_if<client::CompressedDisparityView>(&input)) {
    return convert::ToProto(z->view, z->compression, "disparity", image->mutable_compressed());
  }
  if (const auto* file = std::get_if<client::EncodedImage>(&input)) {
    image->set_encoded(std::string(file->bytes));
    return absl::OkStatus();
  }
  return absl::InternalError("disparity: an input kind the uplink does not make");
}

absl::Status DepthToProto(const client::DepthInput& input, v1::DepthImage* image) {
  if (const auto* raw = std::get_if<DepthView>(&input)) {
    return convert::ToProto(*raw, "depth", image->mutable_raw());
  }
  if (const auto* z = std::get_if<client::CompressedDepthView>(&input)) {
    return convert::ToProto(z->view, z->compression, "depth", image->mutable_compressed());
  }
  if (const auto* file = std::get_if<client::EncodedImage>(&input)) {
    image->set_encoded(std::string(file->bytes));
    return absl::OkStatus();
  }
  return absl::InternalError("depth: an input kind the uplink does not make");
}

absl::Status ColourToProto(const client::ColorInput& input, const char* what,
                           v1::ColorImage* image) {
  if (const auto* raw = std::get_if<ColorView>(&input)) {
    return convert::ToProto(*raw, what, image->mutable_raw());
  }
  if (const auto* bgra = std::get_if<client::BgraView>(&input)) {
    return convert::BgraToProto(bgra->data, bgra->size_bytes, bgra->width, bgra->height,
                                bgra->stride_bytes, what, image->mutable_raw());
  }
  if (const auto* z = std::get_if<client::CompressedColorView>(&input)) {
    return convert::ToProto(z->view, z->compression, what, image->mutable_compressed());
  }
  if (const auto* file = std::get_if<client::EncodedImage>(&input)) {
    image->set_encoded(std::string(file->bytes));
    return absl::OkStatus();
  }
  if (const auto* video = std::get_if<client::PrecodedVideo>(&input)) {
    if (video->message != nullptr) *image->mutable_video() = *video->message;
    return absl::OkStatus();
  }
  return absl::InternalError(absl::StrCat(what, ": an input kind the uplink does not make"));
}

bool Encoded(Uplink u) { return u == Uplink::kPng || u == Uplink::kJpeg; }

// A colour image (or a stereo pair's right one) as kRaw / kZstd views it.
absl::Status ColourView(const cv::Mat& m, const char* what, bool zstd, client::ColorInput* out) {
  absl::StatusOr<client::ColorInput> input = client::ColorFromMat(m, what);
  if (!input.ok()) return input.status();
  *out = zstd ? client::CompressRaw(*input) : *std::move(input);  // BGRA stays raw (as BGR)
  return absl::OkStatus();
}

// A colour image as kPng / kJpeg encode it.
absl::StatusOr<std::string> ColourFile(const cv::Mat& m, const UplinkOptions& options) {
  return options.encoding == Uplink::kJpeg ? client::EncodeJpeg(m, options.jpeg_quality)
                                           : client::EncodePng(m, options.png_compression);
}

// `g` (a disparity or depth Mat) quantized for `options.max_point_error` into `quantizer`'s
// buffer, as a Mat header over it (valid until the quantizer's next use); `g` itself when the
// bound is 0.
absl::StatusOr<cv::Mat> NearLossless(const cv::Mat& g, FrameKind kind, const UplinkOptions& options,
                                     PointErrorQuantizer* quantizer) {
  if (options.max_point_error == 0 || kind == FrameKind::kStereo) return g;
  const CameraModel camera =
      options.camera.PipelineFor(static_cast<std::uint32_t>(g.cols), static_cast<std::uint32_t>(g.rows))
          .camera;
  const void* data = nullptr;
  if (kind == FrameKind::kDisparity) {
    absl::StatusOr<client::DisparityInput> in = client::DisparityFromMat(g);
    if (!in.ok()) return in.status();
    const auto* view = std::get_if<DisparityView>(&*in);
    if (view == nullptr) return absl::InternalError("disparity Mat is not a raw view");
    DisparityView out;
    if (absl::Status s = quantizer->Quantize(*view, camera,
                                             options.max_point_error, "disparity", &out);
        !s.ok()) {
      return s;
    }
    data = out.data;
  } else {
    absl::StatusOr<client::DepthInput> in = client::DepthFromMat(g);
    if (!in.ok()) return in.status();
    const auto* view = std::get_if<DepthView>(&*in);
    if (view == nullptr) return absl::InternalError("depth Mat is not a raw view");
    DepthView out;
    if (absl::Status s = quantizer->Quantize(*view, camera,
                                             options.max_point_error, "depth", &out);
        !s.ok()) {
      return s;
    }
    data = out.data;
  }
  return cv::Mat(g.rows, g.cols, g.type(), const_cast<void*>(data));
}

}  // namespace

bool ParseUplink(std::string_view name, Uplink* out) {
  for (const Named& n : kUplinks) {
    if (name == n.name) {
      *out = n.uplink;
      return true;
    }
  }
  return false;
}

const char* Name(Uplink uplink) {
  for (const Named& n : kUplinks) {
    if (n.uplink == uplink) return n.name;
  }
  return "?";
}

const std::vector<std::string>& UplinkNames() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> v;
    for (const Named& n : kUplinks) v.emplace_back(n.name);
    return v;
  }();
  return names;
}

absl::Status UplinkFrame::Encode(const SourceFrame& frame, const UplinkOptions& options) {
  kind_ = frame.kind;
  encoding_ = options.encoding;
  float_as_tiff_ = false;
  geometry_mat_ = colour_mat_ = right_mat_ = cv::Mat();
  geometry_file_.clear();
  colour_file_.clear();
  right_file_.clear();
  const cv::Mat& c = frame.colour();
  const bool stereo = kind_ == FrameKind::kStereo;
  // What gives the points depth: a disparity or depth image; a stereo pair has none.
  absl::StatusOr<cv::Mat> geometry = NearLossless(
      kind_ == FrameKind::kDepth ? frame.depth() : frame.disparity(), kind_, options, &quantizer_);
  if (!geometry.ok()) return geometry.status();
  const cv::Mat& g = *geometry;
  const char* left = stereo ? "left" : "colour";
  if (encoding_ == Uplink::kRaw || encoding_ == Uplink::kZstd) {
    const bool zstd = encoding_ == Uplink::kZstd;
    if (kind_ == FrameKind::kDisparity) {
      absl::StatusOr<client::DisparityInput> d = client::DisparityFromMat(g);
      if (!d.ok()) return d.status();
      disparity_view_ = zstd ? client::CompressRaw(*d) : *std::move(d);
    } else if (kind_ == FrameKind::kDepth) {
      absl::StatusOr<client::DepthInput> d = client::DepthFromMat(g);
      if (!d.ok()) return d.status();
      depth_view_ = zstd ? client::CompressRaw(*d) : *std::move(d);
    }
    if (absl::Status s = ColourView(c, left, zstd, &colour_view_); !s.ok()) return s;
    if (stereo) {
      if (absl::Status s = ColourView(frame.right(), "right", zstd, &right_view_); !s.ok()) {
        return s;
      }
    }
    geometry_mat_ = stereo ? cv::Mat() : g;  // the views point into these
    colour_mat_ = c;
    right_mat_ = frame.right();
    return absl::OkStatus();
  }
  if (!stereo) {
    // PNG has no float samples; TIFF keeps them exactly.
    float_as_tiff_ = g.depth() == CV_32F;
    absl::StatusOr<std::string> gf = float_as_tiff_ ? client::EncodeImage(g, ".tiff")
                                                    : client::EncodePng(g, options.png_compression);
    if (!gf.ok()) return gf.status();
    geometry_file_ = *std::move(gf);
  }
  absl::StatusOr<std::string> cf = ColourFile(c, options);
  if (!cf.ok()) return cf.status();
  colour_file_ = *std::move(cf);
  if (stereo) {
    absl::StatusOr<std::string> rf = ColourFile(frame.right(), options);
    if (!rf.ok()) return rf.status();
    right_file_ = *std::move(rf);
  }
  return absl::OkStatus();
}

client::FrameInput UplinkFrame::input() const {
  switch (kind_) {
    case FrameKind::kDisparity:
      return client::DisparityFrame{disparity(), colour()};
    case FrameKind::kDepth:
      return client::DepthFrame{depth(), colour()};
    case FrameKind::kStereo:
      return client::StereoFrame{colour(), right()};
  }
  return client::DisparityFrame{disparity(), colour()};
}

client::DisparityInput UplinkFrame::disparity() const {
  if (Encoded(encoding_)) return client::EncodedImage{geometry_file_};
  return disparity_view_;
}

client::DepthInput UplinkFrame::depth() const {
  if (Encoded(encoding_)) return client::EncodedImage{geometry_file_};
  return depth_view_;
}

client::ColorInput UplinkFrame::colour() const {
  if (Encoded(encoding_)) return client::EncodedImage{colour_file_};
  return colour_view_;
}

client::ColorInput UplinkFrame::right() const {
  if (Encoded(encoding_)) return client::EncodedImage{right_file_};
  return right_view_;
}

absl::Status UplinkFrame::ToProto(v1::Frame* frame) const {
  switch (kind_) {
    case FrameKind::kDisparity:
      if (absl::Status s = DisparityToProto(disparity(), frame->mutable_disparity()); !s.ok()) {
        return s;
      }
      return ColourToProto(colour(), "colour", frame->mutable_color());
    case FrameKind::kDepth:
      if (absl::Status s = DepthToProto(depth(), frame->mutable_depth()); !s.ok()) return s;
      return ColourToProto(colour(), "colour", frame->mutable_color());
    case FrameKind::kStereo:
      if (absl::Status s = ColourToProto(colour(), "left", frame->mutable_color()); !s.ok()) {
        return s;
      }
      return ColourToProto(right(), "right", frame->mutable_right());
  }
  return absl::InternalError("unknown frame kind");
}

}  // namespace cloudcast::sources
