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

absl::Status ColourToProto(const client::ColorInput& input, v1::ColorImage* image) {
  if (const auto* raw = std::get_if<ColorView>(&input)) {
    return convert::ToProto(*raw, "colour", image->mutable_raw());
  }
  if (const auto* bgra = std::get_if<client::BgraView>(&input)) {
    return convert::BgraToProto(bgra->data, bgra->size_bytes, bgra->width, bgra->height,
                                bgra->stride_bytes, "colour", image->mutable_raw());
  }
  if (const auto* z = std::get_if<client::CompressedColorView>(&input)) {
    return convert::ToProto(z->view, z->compression, "colour", image->mutable_compressed());
  }
  if (const auto* file = std::get_if<client::EncodedImage>(&input)) {
    image->set_encoded(std::string(file->bytes));
    return absl::OkStatus();
  }
  return absl::InternalError("colour: an input kind the uplink does not make");
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
  encoding_ = options.encoding;
  float_as_tiff_ = false;
  disparity_mat_ = cv::Mat();
  colour_mat_ = cv::Mat();
  disparity_file_.clear();
  colour_file_.clear();
  if (frame.kind != FrameKind::kDisparity) {
    return absl::UnimplementedError(
        absl::StrCat("the uplink does not carry ", Name(frame.kind), " frames yet"));
  }
  const cv::Mat& d = frame.disparity();
  const cv::Mat& c = frame.colour();
  if (encoding_ == Uplink::kRaw || encoding_ == Uplink::kZstd) {
    absl::StatusOr<client::DisparityInput> d_input = client::DisparityFromMat(d);
    if (!d_input.ok()) return d_input.status();
    absl::StatusOr<client::ColorInput> c_input = client::ColorFromMat(c);
    if (!c_input.ok()) return c_input.status();
    disparity_mat_ = d;  // the views point into these
    colour_mat_ = c;
    disparity_view_ = *std::move(d_input);
    colour_view_ = *std::move(c_input);
    if (encoding_ == Uplink::kZstd) {
      disparity_view_ = client::CompressRaw(disparity_view_);
      colour_view_ = client::CompressRaw(colour_view_);  // a BGRA colour stays raw (as BGR)
    }
    return absl::OkStatus();
  }
  // PNG has no float samples; TIFF keeps them exactly.
  float_as_tiff_ = d.depth() == CV_32F;
  absl::StatusOr<std::string> df = float_as_tiff_ ? client::EncodeImage(d, ".tiff")
                                                  : client::EncodePng(d, options.png_compression);
  if (!df.ok()) return df.status();
  absl::StatusOr<std::string> cf = encoding_ == Uplink::kJpeg
                                       ? client::EncodeJpeg(c, options.jpeg_quality)
                                       : client::EncodePng(c, options.png_compression);
  if (!cf.ok()) return cf.status();
  disparity_file_ = *std::move(df);
  colour_file_ = *std::move(cf);
  return absl::OkStatus();
}

client::FrameInput UplinkFrame::input() const {
  return client::DisparityFrame{disparity(), colour()};
}

client::DisparityInput UplinkFrame::disparity() const {
  if (encoding_ == Uplink::kPng || encoding_ == Uplink::kJpeg) {
    return client::EncodedImage{disparity_file_};
  }
  return disparity_view_;
}

client::ColorInput UplinkFrame::colour() const {
  if (encoding_ == Uplink::kPng || encoding_ == Uplink::kJpeg) {
    return client::EncodedImage{colour_file_};
  }
  return colour_view_;
}

absl::Status UplinkFrame::ToProto(v1::Frame* frame) const {
  if (absl::Status s = DisparityToProto(disparity(), frame->mutable_disparity()); !s.ok()) {
    return s;
  }
  return ColourToProto(colour(), frame->mutable_colour());
}

}  // namespace cloudcast::sources
