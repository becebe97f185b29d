// cv::Mat adapters for the client. Kept apart from client.h so that code which sends raw buffers
// or files never needs OpenCV's headers.
#pragma once

#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/client/client.h"
#include "cloudcast/client/frame.h"

namespace cloudcast::client {

// Views of a Mat's pixels; nothing is copied (the Mat must outlive the Send / Process that uses
// the view). Non-continuous Mats (ROIs) are fine: the view carries Mat::step as the row stride.
//
// Disparity: one channel, CV_8U, CV_16U or CV_32F. CV_16S (StereoSGBM's output, 16 x disparity,
// negative where invalid) is refused: convert it, e.g. sgbm.convertTo(d, CV_32F, 1.0 / 16).
absl::StatusOr<DisparityInput> DisparityFromMat(const cv::Mat& disparity);
// Depth: CV_16UC1 (ROS 16UC1, millimetres) or CV_32FC1 (ROS 32FC1, metres), as cv_bridge gives.
absl::StatusOr<DepthInput> DepthFromMat(const cv::Mat& depth);
// Colour, 8-bit: CV_8UC3 (BGR, OpenCV's order), CV_8UC4 (BGRA; sent as BGR), CV_8UC1 (grey).
// `what` names the image in errors ("colour", "left", "right").
absl::StatusOr<ColorInput> ColorFromMat(const cv::Mat& colour);
absl::StatusOr<ColorInput> ColorFromMat(const cv::Mat& colour, const char* what);
// Whole frames: a depth image and its colour image; a stereo pair (left, right).
absl::StatusOr<FrameInput> DepthFrameFromMats(const cv::Mat& depth, const cv::Mat& colour);
absl::StatusOr<FrameInput> StereoFrameFromMats(const cv::Mat& left, const cv::Mat& right);

// Stream::Send / Client::Process with Mats: the adapters above, then the call.
absl::Status SendMats(Stream& stream, const cv::Mat& disparity, const cv::Mat& colour,
                      const FrameMeta& meta = {});
// The same, with the raw pixels compressed losslessly by Send (CompressRaw in frame.h; a CV_8UC4
// colour Mat still goes raw, as BGR).
absl::Status SendMats(Stream& stream, const cv::Mat& disparity, const cv::Mat& colour,
                      const FrameMeta& meta, const convert::Compression& compression);
absl::StatusOr<Result> ProcessMats(Client& client, const cv::Mat& disparity, const cv::Mat& colour,
                                   const StreamConfig& config = {}, const FrameMeta& meta = {});

// Encodes a Mat as an image file for EncodedImage, trading client CPU for uplink bytes.
// `extension` picks the format (".png", ".jpg", ".tiff"); `params` are cv::imwrite flags.
absl::StatusOr<std::string> EncodeImage(const cv::Mat& image, const std::string& extension,
                                        const std::vector<int>& params = {});
// Lossless, for disparity (8/16-bit) or colour. Compression 0..9; 1 is fast and already shrinks
// typical disparity maps several times.
absl::StatusOr<std::string> EncodePng(const cv::Mat& image, int compression = 1);
// Lossy, for colour only (the server refuses nothing, but JPEG corrupts disparities).
// Quality 0..100.
inline constexpr int kDefaultJpegQuality = 90;
absl::StatusOr<std::string> EncodeJpeg(const cv::Mat& colour, int quality = kDefaultJpegQuality);

}  // namespace cloudcast::client
