#include "images.h"

#include <algorithm>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"

namespace cloudcast::sources::internal {
namespace {

namespace fs = std::filesystem;

absl::Status Unreadable(const std::string& path, const std::string& flag, const char* formats) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return absl::NotFoundError(absl::StrCat(flag, ": no file ", path));
  return absl::InvalidArgumentError(
      absl::StrCat(flag, ": cannot decode ", path, " as an image (", formats, ")"));
}

absl::Status CheckDisparity(const cv::Mat& m, const std::string& what, const std::string& flag) {
  if (m.channels() != 1) {
    return absl::InvalidArgumentError(absl::StrCat(
        flag, ": disparity ", what, " has ", m.channels(),
        " channels; a disparity map has one (8- or 16-bit PNG/TIFF, or 32-bit float TIFF/PFM)"));
  }
  if (m.depth() != CV_8U && m.depth() != CV_16U && m.depth() != CV_32F) {
    return absl::InvalidArgumentError(
        absl::StrCat(flag, ": disparity ", what, " has samples of type ",
                     cv::typeToString(m.type()), "; supported: 8U, 16U, 32F"));
  }
  return absl::OkStatus();
}

absl::Status CheckDepth(const cv::Mat& m, const std::string& what, const std::string& flag) {
  if (m.channels() != 1 || (m.depth() != CV_16U && m.depth() != CV_32F)) {
    return absl::InvalidArgumentError(absl::StrCat(
        flag, ": depth ", what, " is ", cv::typeToString(m.type()),
        "; a depth image has one channel of 16-bit millimetres (16UC1 PNG) or float metres "
        "(32FC1 TIFF/PFM)"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<std::vector<std::string>> PathsPerRole(FrameKind kind, const RolePaths& paths,
                                                      const std::string& suffix) {
  std::vector<std::string> out;
  std::vector<std::string> flags;
  for (ImageRole role : RolesOf(kind)) flags.push_back(RoleFlag(role, suffix));
  for (ImageRole role : RolesOf(kind)) {
    auto it = paths.find(role);
    if (it == paths.end() || it->second.empty()) {
      return absl::InvalidArgumentError(absl::StrCat("no ", RoleFlag(role, suffix),
                                                     " given: ", Name(kind), " frames need ",
                                                     absl::StrJoin(flags, " and ")));
    }
    out.push_back(it->second);
  }
  for (const auto& [role, path] : paths) {
    if (std::find(RolesOf(kind).begin(), RolesOf(kind).end(), role) == RolesOf(kind).end()) {
      return absl::InvalidArgumentError(
          absl::StrCat(RoleFlag(role, suffix), " does not apply to ", Name(kind), " frames"));
    }
  }
  return out;
}

absl::StatusOr<cv::Mat> ReadImage(ImageRole role, const std::string& path,
                                  const std::string& flag) {
  switch (role) {
    case ImageRole::kDisparity: {
      // IMREAD_UNCHANGED keeps 16-bit and float samples as stored; any conversion would scale.
      cv::Mat m = cv::imread(path, cv::IMREAD_UNCHANGED);
      if (m.empty()) return Unreadable(path, flag, "PNG, TIFF, PFM, ...");
      if (absl::Status s = CheckDisparity(m, absl::StrCat("image ", path), flag); !s.ok()) return s;
      return m;
    }
    case ImageRole::kDepth: {
      cv::Mat m = cv::imread(path, cv::IMREAD_UNCHANGED);  // millimetres or metres as stored
      if (m.empty()) return Unreadable(path, flag, "16-bit PNG, TIFF, PFM, ...");
      if (absl::Status s = CheckDepth(m, absl::StrCat("image ", path), flag); !s.ok()) return s;
      return m;
    }
    case ImageRole::kColour:
    case ImageRole::kRight: {
      // IMREAD_COLOR gives 8-bit BGR for every input: RGBA (New Tsukuba, alpha down to 0) loses
      // its alpha, grey is expanded, 16-bit is scaled, as the server would do with the file.
      cv::Mat m = cv::imread(path, cv::IMREAD_COLOR);
      if (m.empty()) return Unreadable(path, flag, "PNG, JPEG, TIFF, ...");
      return m;
    }
  }
  return absl::InternalError("unknown image role");
}

cv::Mat DepthFromDisparity(const cv::Mat& disparity, const CameraModel& camera) {
  cv::Mat d;
  disparity.convertTo(d, CV_64F);
  cv::Mat depth(disparity.size(), CV_32FC1);
  const double fb = camera.fx * camera.baseline;
  for (int v = 0; v < d.rows; ++v) {
    const double* in = d.ptr<double>(v);
    float* out = depth.ptr<float>(v);
    for (int u = 0; u < d.cols; ++u) {
      // Raw 0 is "no match" for every disparity encoding; so is a disparity behind the camera.
      const double scaled = in[u] * camera.disparity_scale + camera.disparity_offset;
      out[u] = in[u] == 0 || !(scaled > 0) ? 0.0f : static_cast<float>(fb / scaled);
    }
  }
  return depth;
}

bool NeedsLosslessVideo(ImageRole role) {
  return role == ImageRole::kDisparity || role == ImageRole::kDepth;
}

absl::StatusOr<cv::Mat> FromVideo(ImageRole role, cv::Mat frame, const std::string& flag,
                                  const std::string& path, bool first,
                                  std::vector<std::string>* warnings) {
  switch (role) {
    case ImageRole::kDisparity: {
      if (frame.channels() == 3 || frame.channels() == 4) {
        if (first) {
          // A grey video decodes to equal channels; unequal ones mean a colour-coded or lossy
          // (chroma-subsampled) disparity, whose values cannot be trusted.
          std::vector<cv::Mat> planes;
          cv::split(frame, planes);
          if (cv::norm(planes[0], planes[1], cv::NORM_INF) != 0 ||
              cv::norm(planes[1], planes[2], cv::NORM_INF) != 0) {
            warnings->push_back(absl::StrCat(
                flag, " ", path,
                ": the first frame is not grey (its colour channels differ); disparities are "
                "taken as its luminance"));
          }
        }
        cv::Mat grey;
        // For equal channels the weights sum to exactly one, so grey values come back unchanged.
        cv::cvtColor(frame, grey, frame.channels() == 3 ? cv::COLOR_BGR2GRAY : cv::COLOR_BGRA2GRAY);
        frame = grey;
      } else if (frame.channels() != 1) {
        return absl::InvalidArgumentError(absl::StrCat(
            flag, " ", path, ": frames have ", frame.channels(), " channels; expected grey"));
      }
      if (absl::Status s = CheckDisparity(frame, absl::StrCat("video ", path, "'s frames"), flag);
          !s.ok()) {
        return s;
      }
      return frame;
    }
    case ImageRole::kDepth: {
      // Decoders hand 16-bit grey (FFV1 gray16le) back as it is; anything else is no depth.
      if (absl::Status s = CheckDepth(frame, absl::StrCat("video ", path, "'s frames"), flag);
          !s.ok()) {
        return s;
      }
      return frame;
    }
    case ImageRole::kColour:
    case ImageRole::kRight: {
      if (frame.depth() != CV_8U) {
        cv::Mat c8;
        frame.convertTo(c8, CV_8U, 1.0 / 257.0);
        frame = c8;
      }
      return frame;
    }
  }
  return absl::InternalError("unknown image role");
}

absl::Status CheckSameSize(FrameKind kind, const std::vector<cv::Mat>& images,
                           const std::vector<std::string>& paths) {
  const std::vector<ImageRole>& roles = RolesOf(kind);
  for (std::size_t i = 1; i < images.size(); ++i) {
    if (images[i].size() == images[0].size()) continue;
    return absl::InvalidArgumentError(
        absl::StrCat(Name(roles[0]), " ", paths[0], " is ", images[0].cols, "x", images[0].rows,
                     " but ", Name(roles[i]), " ", paths[i], " is ", images[i].cols, "x",
                     images[i].rows, "; a frame's images must match"));
  }
  return absl::OkStatus();
}

}  // namespace cloudcast::sources::internal
