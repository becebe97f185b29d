#include "cloudcast/client/adaptive_jpeg_coder.h"

#include <algorithm>
#include <opencv2/core/mat.hpp>
#include <opencv2/imgproc.hpp>
#include <utility>
#include <variant>

#include "absl/strings/str_cat.h"
#include "cloudcast/client/opencv.h"

namespace cloudcast::client {
namespace {

// A raw view of a disparity or depth image, with the compression it asks for (its own when it
// is a Compressed view, else the coder's).
template <typename View, typename CompressedView, typename Input>
const View* RawGeometry(const Input& input, const convert::Compression& fallback,
                        convert::Compression* compression) {
  if (const auto* view = std::get_if<View>(&input)) {
    *compression = fallback;
    return view;
  }
  if (const auto* c = std::get_if<CompressedView>(&input)) {
    *compression = c->compression;
    return &c->view;
  }
  return nullptr;
}

}  // namespace

AdaptiveJpegCoder::AdaptiveJpegCoder(AdaptiveJpegOptions options)
    : options_(std::move(options)),
      full_(options_.start_quality, options_.min_quality, options_.max_quality),
      half_(options_.min_quality, options_.min_quality, options_.max_quality),
      camera_(options_.stream_camera) {}

void AdaptiveJpegCoder::SetCamera(std::uint64_t from_sequence, v1::CameraModel camera) {
  std::lock_guard<std::mutex> lock(cameras_mu_);
  cameras_.emplace_back(from_sequence, std::move(camera));
}

void AdaptiveJpegCoder::SetStreamBitrate(std::int64_t stream_bps,
                                         std::size_t /*other_bytes_per_frame*/) {
  // Every image of the frame is this coder's: its share is the whole target.
  stream_bps_ = stream_bps;
}

FrameCoder::Resolution AdaptiveJpegCoder::last_resolution() const {
  Resolution r;
  if (last_half_.load()) {
    r.divisor = 2;
    r.camera = HalfResolutionCamera(camera_, disparity_frame_);
  }
  return r;
}

void AdaptiveJpegCoder::Follow(bool halvable) {
  if (!made_ || stream_bps_ <= 0 || options_.fps <= 0) return;
  const auto budget = static_cast<std::size_t>(static_cast<double>(stream_bps_) / 8 / options_.fps);
  const std::size_t bytes = last_bytes_.load();
  if (!at_half_) {
    const bool at_floor = last_quality_.load() <= options_.min_quality;
    if (at_floor) full_floor_bytes_ = bytes;
    full_.Encoded(bytes, budget);
    // Even the lowest quality at full resolution is over the budget, or the lossless geometry
    // alone is (no JPEG quality can help then: straight down, as after a step down of the link):
    // the floor below it.
    const bool geometry_over = last_geometry_bytes_.load() > budget;
    if ((at_floor || geometry_over) && bytes > budget && halvable &&
        options_.half_resolution_floor) {
      // What a full-resolution frame takes at the lowest quality, at least (to come back).
      if (!at_floor) full_floor_bytes_ = std::max(full_floor_bytes_, last_geometry_bytes_.load());
      at_half_ = true;
      half_ = QualityFollower(options_.min_quality, options_.min_quality, options_.max_quality);
    }
    return;
  }
  half_.Encoded(bytes, budget);
  if (static_cast<double>(budget) >=
      options_.full_resolution_margin * static_cast<double>(full_floor_bytes_)) {
    // The target carries a full-resolution frame again: from its lowest quality up.
    at_half_ = false;
    full_ = QualityFollower(options_.min_quality, options_.min_quality, options_.max_quality);
  }
}

absl::Status AdaptiveJpegCoder::EncodeColour(const ColorInput& colour, const char* field,
                                             std::string* out) {
  const auto* view = std::get_if<ColorView>(&colour);
  if (view == nullptr || view->rows != nullptr || view->data == nullptr) {
    return absl::InvalidArgumentError(absl::StrCat(
        "AdaptiveJpegCoder: the ", field, " must be a raw ColorView (bgr8, rgb8, rgba8, mono8)"));
  }
  if (absl::Status s = ValidateView(*view, Limits{}, field); !s.ok()) return s;
  void* data = const_cast<void*>(view->data);  // cv::Mat views; nothing writes to it
  cv::Mat bgr;
  switch (view->encoding) {
    case ColorEncoding::kBGR8:
      bgr = cv::Mat(static_cast<int>(view->height), static_cast<int>(view->width), CV_8UC3, data,
                    view->stride_bytes);
      break;
    case ColorEncoding::kMono8:
      bgr = cv::Mat(static_cast<int>(view->height), static_cast<int>(view->width), CV_8UC1, data,
                    view->stride_bytes);
      break;
    case ColorEncoding::kRGB8:
      cv::cvtColor(cv::Mat(static_cast<int>(view->height), static_cast<int>(view->width), CV_8UC3,
                           data, view->stride_bytes),
                   bgr, cv::COLOR_RGB2BGR);
      break;
    case ColorEncoding::kRGBA8:
      cv::cvtColor(cv::Mat(static_cast<int>(view->height), static_cast<int>(view->width), CV_8UC4,
                           data, view->stride_bytes),
                   bgr, cv::COLOR_RGBA2BGR);
      break;
  }
  absl::StatusOr<std::string> jpeg = EncodeJpeg(bgr, last_quality_.load());
  if (!jpeg.ok()) return jpeg.status();
  *out = *std::move(jpeg);
  return absl::OkStatus();
}

absl::StatusOr<FrameInput> AdaptiveJpegCoder::Encode(const FrameInput& raw,
                                                     std::uint64_t sequence) {
  {
    // The newest camera due by this frame (SetCamera's, in the order given).
    std::lock_guard<std::mutex> lock(cameras_mu_);
    for (const auto& [from, camera] : cameras_) {
      if (from <= sequence) camera_ = camera;
    }
    cameras_.erase(std::remove_if(cameras_.begin(), cameras_.end(),
                                  [&](const auto& c) { return c.first <= sequence; }),
                   cameras_.end());
  }
  const bool halvable = !std::holds_alternative<StereoFrame>(raw);
  disparity_frame_ = std::holds_alternative<DisparityFrame>(raw);
  Follow(halvable);
  const bool half = at_half_ && halvable;
  last_quality_.store(half ? half_.quality() : full_.quality());
  // The images to encode: the frame's own, or their halves.
  FrameInput source = raw;
  if (half) {
    convert::Compression compression = options_.compression;
    FrameInput views;
    if (const auto* f = std::get_if<DisparityFrame>(&raw)) {
      const DisparityView* d = RawGeometry<DisparityView, CompressedDisparityView>(
          f->disparity, compression, &compression);
      views = DisparityFrame{d != nullptr ? DisparityInput(*d) : f->disparity, f->colour};
    } else {
      const auto& depth = std::get<DepthFrame>(raw);
      const DepthView* d =
          RawGeometry<DepthView, CompressedDepthView>(depth.depth, compression, &compression);
      views = DepthFrame{d != nullptr ? DepthInput(*d) : depth.depth, depth.colour};
    }
    if (absl::Status s = halved_.Make(views); !s.ok()) return s;
    if (disparity_frame_) {
      source = DisparityFrame{Compressed(halved_.disparity(), compression), halved_.colour()};
    } else {
      source = DepthFrame{Compressed(halved_.depth(), compression), halved_.colour()};
    }
  }
  std::size_t bytes = 0, geometry_bytes = 0;
  FrameInput coded;
  if (const auto* pair = std::get_if<StereoFrame>(&source)) {
    if (absl::Status s = EncodeColour(pair->left, "left", &colour_jpeg_); !s.ok()) return s;
    if (absl::Status s = EncodeColour(pair->right, "right", &right_jpeg_); !s.ok()) return s;
    bytes = colour_jpeg_.size() + right_jpeg_.size();
    coded = StereoFrame{EncodedImage{colour_jpeg_}, EncodedImage{right_jpeg_}};
  } else if (const auto* f = std::get_if<DisparityFrame>(&source)) {
    convert::Compression compression;
    const DisparityView* d = RawGeometry<DisparityView, CompressedDisparityView>(
        f->disparity, options_.compression, &compression);
    if (d == nullptr) {
      return absl::InvalidArgumentError(
          "AdaptiveJpegCoder: the disparity must be a raw DisparityView (or Compressed)");
    }
    if (absl::Status s = convert::ToProto(*d, compression, "disparity", &disparity_); !s.ok()) {
      return s;
    }
    if (absl::Status s = EncodeColour(f->colour, "colour", &colour_jpeg_); !s.ok()) return s;
    geometry_bytes = disparity_.payload().size();
    bytes = geometry_bytes + colour_jpeg_.size();
    coded = DisparityFrame{PrecompressedDisparity{&disparity_}, EncodedImage{colour_jpeg_}};
  } else {
    const auto& depth = std::get<DepthFrame>(source);
    convert::Compression compression;
    const DepthView* d = RawGeometry<DepthView, CompressedDepthView>(
        depth.depth, options_.compression, &compression);
    if (d == nullptr) {
      return absl::InvalidArgumentError(
          "AdaptiveJpegCoder: the depth must be a raw DepthView (or Compressed)");
    }
    if (absl::Status s = convert::ToProto(*d, compression, "depth", &depth_); !s.ok()) return s;
    if (absl::Status s = EncodeColour(depth.colour, "colour", &colour_jpeg_); !s.ok()) return s;
    geometry_bytes = depth_.payload().size();
    bytes = geometry_bytes + colour_jpeg_.size();
    coded = DepthFrame{PrecompressedDepth{&depth_}, EncodedImage{colour_jpeg_}};
  }
  last_half_.store(half);
  last_bytes_.store(bytes);
  last_geometry_bytes_.store(geometry_bytes);
  made_ = true;
  return coded;
}

}  // namespace cloudcast::client
