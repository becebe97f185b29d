#include "cloudcast/client/opencv.h"

#include <cstddef>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"

namespace cloudcast::client {
namespace {

// Bytes from the first pixel to the end of the last row: what a view may read, even for an ROI
// whose rows are far apart.
std::size_t SpanBytes(const cv::Mat& m) {
  return m.step[0] * static_cast<std::size_t>(m.rows - 1) + m.cols * m.elemSize();
}

absl::Status CheckShape(const cv::Mat& m, const char* what) {
  if (m.empty()) return absl::InvalidArgumentError(absl::StrCat(what, " Mat is empty"));
  if (m.dims != 2) {
    return absl::InvalidArgumentError(
        absl::StrCat(what, " Mat has ", m.dims, " dimensions; an image has 2"));
  }
  return absl::OkStatus();
}

template <typename View>
void FillView(const cv::Mat& m, View* view) {
  view->data = m.data;
  view->size_bytes = SpanBytes(m);
  view->width = static_cast<std::uint32_t>(m.cols);
  view->height = static_cast<std::uint32_t>(m.rows);
  view->stride_bytes = m.step[0];
}

}  // namespace

absl::StatusOr<DisparityInput> DisparityFromMat(const cv::Mat& disparity) {
  if (absl::Status s = CheckShape(disparity, "disparity"); !s.ok()) return s;
  DisparityView view;
  switch (disparity.type()) {
    case CV_8UC1:
      view.encoding = DisparityEncoding::kU8;
      break;
    case CV_16UC1:
      view.encoding = DisparityEncoding::kU16;
      break;
    case CV_32FC1:
      view.encoding = DisparityEncoding::kF32;
      break;
    case CV_16SC1:
      return absl::InvalidArgumentError(
          "disparity Mat is CV_16S (signed, e.g. StereoSGBM's 16 x disparity with negative "
          "invalid values), which the protocol does not carry; convert it first, e.g. "
          "sgbm.convertTo(d, CV_32F, 1.0 / 16)");
    default:
      return absl::InvalidArgumentError(absl::StrCat("disparity Mat has type ",
                                                     cv::typeToString(disparity.type()),
                                                     "; supported: CV_8UC1, CV_16UC1, CV_32FC1"));
  }
  FillView(disparity, &view);
  return DisparityInput(view);
}

absl::StatusOr<DepthInput> DepthFromMat(const cv::Mat& depth) {
  if (absl::Status s = CheckShape(depth, "depth"); !s.ok()) return s;
  DepthView view;
  switch (depth.type()) {
    case CV_16UC1:
      view.encoding = DepthEncoding::kU16;
      break;
    case CV_32FC1:
      view.encoding = DepthEncoding::kF32;
      break;
    default:
      return absl::InvalidArgumentError(absl::StrCat(
          "depth Mat has type ", cv::typeToString(depth.type()),
          "; supported: CV_16UC1 (ROS 16UC1, millimetres), CV_32FC1 (ROS 32FC1, metres)"));
  }
  FillView(depth, &view);
  return DepthInput(view);
}

absl::StatusOr<FrameInput> DepthFrameFromMats(const cv::Mat& depth, const cv::Mat& colour) {
  absl::StatusOr<DepthInput> d = DepthFromMat(depth);
  if (!d.ok()) return d.status();
  absl::StatusOr<ColorInput> c = ColorFromMat(colour);
  if (!c.ok()) return c.status();
  return FrameInput(DepthFrame{*d, *c});
}

absl::StatusOr<FrameInput> StereoFrameFromMats(const cv::Mat& left, const cv::Mat& right) {
  absl::StatusOr<ColorInput> l = ColorFromMat(left, "left");
  if (!l.ok()) return l.status();
  absl::StatusOr<ColorInput> r = ColorFromMat(right, "right");
  if (!r.ok()) return r.status();
  return FrameInput(StereoFrame{*l, *r});
}

absl::StatusOr<ColorInput> ColorFromMat(const cv::Mat& colour) {
  return ColorFromMat(colour, "colour");
}

absl::StatusOr<ColorInput> ColorFromMat(const cv::Mat& colour, const char* what) {
  if (absl::Status s = CheckShape(colour, what); !s.ok()) return s;
  switch (colour.type()) {
    case CV_8UC3:
    case CV_8UC1: {
      ColorView view;
      view.encoding = colour.type() == CV_8UC3 ? ColorEncoding::kBGR8 : ColorEncoding::kMono8;
      FillView(colour, &view);
      return ColorInput(view);
    }
    case CV_8UC4: {
      BgraView view;
      FillView(colour, &view);
      return ColorInput(view);
    }
    default:
      return absl::InvalidArgumentError(
          absl::StrCat(what, " Mat has type ", cv::typeToString(colour.type()),
                       "; supported: CV_8UC3 (BGR), CV_8UC4 (BGRA), CV_8UC1 (grey)"));
  }
}

absl::Status SendMats(Stream& stream, const cv::Mat& disparity, const cv::Mat& colour,
                      const FrameMeta& meta) {
  absl::StatusOr<DisparityInput> d = DisparityFromMat(disparity);
  if (!d.ok()) return d.status();
  absl::StatusOr<ColorInput> c = ColorFromMat(colour);
  if (!c.ok()) return c.status();
  return stream.Send(*d, *c, meta);
}

absl::Status SendMats(Stream& stream, const cv::Mat& disparity, const cv::Mat& colour,
                      const FrameMeta& meta, const convert::Compression& compression) {
  absl::StatusOr<DisparityInput> d = DisparityFromMat(disparity);
  if (!d.ok()) return d.status();
  absl::StatusOr<ColorInput> c = ColorFromMat(colour);
  if (!c.ok()) return c.status();
  return stream.Send(CompressRaw(*d, compression), CompressRaw(*c, compression), meta);
}

absl::StatusOr<Result> ProcessMats(Client& client, const cv::Mat& disparity, const cv::Mat& colour,
                                   const StreamConfig& config, const FrameMeta& meta) {
  absl::StatusOr<DisparityInput> d = DisparityFromMat(disparity);
  if (!d.ok()) return d.status();
  absl::StatusOr<ColorInput> c = ColorFromMat(colour);
  if (!c.ok()) return c.status();
  return client.Process(*d, *c, config, meta);
}

absl::StatusOr<std::string> EncodeImage(const cv::Mat& image, const std::string& extension,
                                        const std::vector<int>& params) {
  if (image.empty()) return absl::InvalidArgumentError("cannot encode an empty Mat");
  std::vector<uchar> buffer;
  try {
    if (!cv::imencode(extension, image, buffer, params)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "OpenCV cannot encode a ", cv::typeToString(image.type()), " Mat as ", extension));
    }
  } catch (const cv::Exception& e) {
    // imencode throws for unknown extensions and for sample types the format lacks.
    return absl::InvalidArgumentError(absl::StrCat("encoding a ", cv::typeToString(image.type()),
                                                   " Mat as ", extension, ": ", e.what()));
  }
  return std::string(buffer.begin(), buffer.end());
}

absl::StatusOr<std::string> EncodePng(const cv::Mat& image, int compression) {
  return EncodeImage(image, ".png", {cv::IMWRITE_PNG_COMPRESSION, compression});
}

absl::StatusOr<std::string> EncodeJpeg(const cv::Mat& colour, int quality) {
  return EncodeImage(colour, ".jpg", {cv::IMWRITE_JPEG_QUALITY, quality});
}

}  // namespace cloudcast::client
