// What a frame source yields: a frame of one kind, holding that kind's images.
//
// A kind names its images (their roles) and their order: a disparity map with the colour image
// of the same view, a depth image with its colour image, or a rectified stereo pair (the left
// image is the colour one, as in the protocol). A new kind is one enumerator of FrameKind and one
// row of RolesOf (frame.cc); a new role also gets its file and video checks in images.cc. Every
// source (New Tsukuba, globs, videos, still files) then reads it without further code, and the
// uplink (uplink.h) says how it travels.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <opencv2/core/mat.hpp>
#include <string>
#include <string_view>
#include <vector>

namespace cloudcast::sources {

enum class ImageRole {
  // One channel, CV_8U, CV_16U or CV_32F, values as stored (no scaling): disparity in pixels.
  kDisparity,
  // CV_8UC3 (BGR), CV_8UC4 (BGRA) or CV_8UC1 (grey). Of a stereo pair: the left image.
  kColour,
  // One channel, CV_16U (millimetres, ROS 16UC1) or CV_32F (metres, 32FC1); 0 or NaN: none.
  kDepth,
  // The right image of a rectified stereo pair, 8-bit as kColour.
  kRight,
};

enum class FrameKind {
  kDisparity,  // disparity + colour, same size
  kDepth,      // depth + colour
  kStereo,     // colour (the left image) + right, matched by the server
};

// "disparity", "colour", "depth", "right": also the stem of each role's flags (--disparity-glob,
// --colour-video, --depth-glob, --right).
const char* Name(ImageRole role);
// "disparity", "depth", "stereo": what the programs' --input takes.
const char* Name(FrameKind kind);
bool ParseFrameKind(std::string_view name, FrameKind* out);
// Every kind's name, in the enum's order (for --input's check and help).
const std::vector<std::string>& FrameKindNames();
// The flag that names `role`'s input of one sort: RoleFlag(kColour, "-video") is "--colour-video",
// RoleFlag(kRight, "") is "--right".
std::string RoleFlag(ImageRole role, const std::string& suffix);
// The images of a frame of `kind`, in the order SourceFrame::images holds them.
const std::vector<ImageRole>& RolesOf(FrameKind kind);

// One path (or glob pattern) per role of a kind, e.g. {kDisparity: "d/*.png", kColour: "c/*.png"}.
using RolePaths = std::map<ImageRole, std::string>;

struct SourceFrame {
  FrameKind kind = FrameKind::kDisparity;
  // One per RolesOf(kind), in that order, all of one size.
  std::vector<cv::Mat> images;
  // Position in the stream of frames this source produced, from 0, counting every loop.
  std::uint64_t index = 0;
  // Which frame this is, e.g. "tsukuba_00200" or a file stem; sent as the frame_id.
  std::string name;
  // Keeps the memory the Mats point into alive when it is not the Mats' own (synthetic frames).
  std::shared_ptr<const void> keep_alive;

  // The image of `role`; an empty Mat when this kind has none.
  const cv::Mat& image(ImageRole role) const;
  const cv::Mat& disparity() const { return image(ImageRole::kDisparity); }
  const cv::Mat& colour() const { return image(ImageRole::kColour); }
  const cv::Mat& depth() const { return image(ImageRole::kDepth); }
  const cv::Mat& right() const { return image(ImageRole::kRight); }
};

}  // namespace cloudcast::sources
