// Videos, one per role of the frame kind, read with cv::VideoCapture and paired frame by frame.
#include <algorithm>
#include <filesystem>
#include <opencv2/videoio.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "cloudcast/sources/files.h"
#include "cloudcast/sources/frame_source.h"
#include "images.h"

namespace cloudcast::sources {
namespace {

class VideoSource : public FrameSource {
 public:
  VideoSource(std::vector<std::string> paths, const SourceOptions& options)
      : roles_(RolesOf(options.kind)),
        paths_(std::move(paths)),
        options_(options),
        captures_(roles_.size()) {
    for (ImageRole role : roles_) flags_.push_back(RoleFlag(role, "-video"));
  }

  absl::Status Init() {
    if (absl::Status s = Open(); !s.ok()) return s;
    std::vector<std::string> parts;
    for (std::size_t r = 0; r < roles_.size(); ++r) {
      const std::string codec =
          FourccToString(static_cast<int>(captures_[r].get(cv::CAP_PROP_FOURCC)));
      parts.push_back(absl::StrCat(paths_[r], " (", codec, ")"));
      if (internal::NeedsLosslessVideo(roles_[r]) && !IsLosslessCodec(codec)) {
        info_.warnings.push_back(absl::StrCat(
            flags_[r], " ", paths_[r], " uses codec '", codec, "', which is not known to be ",
            "lossless: ", Name(roles_[r]), " values may be changed, which moves points; encode ",
            Name(roles_[r]), " videos with FFV1 (.mkv) or PNG (.avi)"));
      }
    }
    // The first frame is read now: it gives the size and shows unreadable files before streaming.
    auto first = ReadOne();
    if (!first.ok()) return first.status();
    if (!*first) {
      std::vector<std::string> named;
      for (std::size_t r = 0; r < roles_.size(); ++r) {
        named.push_back(absl::StrCat(flags_[r], " ", paths_[r]));
      }
      return absl::InvalidArgumentError(
          absl::StrCat(absl::StrJoin(named, " / "), ": no frame could be decoded"));
    }
    have_first_ = true;
    info_.kind = "video";
    info_.width = static_cast<std::uint32_t>(current_.front().cols);
    info_.height = static_cast<std::uint32_t>(current_.front().rows);
    info_.camera = CameraModel::PclCompatible(info_.width, info_.height, options_.focal);
    info_.native_fps = captures_.front().get(cv::CAP_PROP_FPS);
    info_.looped = options_.loop;
    std::vector<double> counts;
    for (cv::VideoCapture& c : captures_) counts.push_back(c.get(cv::CAP_PROP_FRAME_COUNT));
    const auto [fewest, most] = std::minmax_element(counts.begin(), counts.end());
    if (*fewest > 0) {
      info_.frames_per_pass = static_cast<std::uint64_t>(*fewest);
      if (*fewest != *most) {
        std::vector<std::string> each;
        for (std::size_t r = 0; r < roles_.size(); ++r) {
          each.push_back(absl::StrCat(Name(roles_[r]), " ", counts[r]));
        }
        info_.warnings.push_back(absl::StrCat("the videos hold different frame counts (",
                                              absl::StrJoin(each, ", "),
                                              "); streaming stops at the end of the shortest"));
      }
    }
    info_.description =
        absl::StrCat("videos ", absl::StrJoin(parts, " + "), ", ", info_.width, "x", info_.height);
    if (info_.frames_per_pass) {
      absl::StrAppend(&info_.description, ", ", *info_.frames_per_pass, " frames");
    }
    return absl::OkStatus();
  }

  absl::StatusOr<bool> Next(SourceFrame* frame) override {
    if (!have_first_) {
      auto got = ReadOne();
      if (!got.ok()) return got.status();
      if (!*got) {
        if (!options_.loop || position_ == 0) return false;
        // Reopening is exact where seeking to frame 0 is not, for some containers.
        if (absl::Status s = Open(); !s.ok()) return s;
        position_ = 0;
        got = ReadOne();
        if (!got.ok()) return got.status();
        if (!*got) return false;
      }
    }
    have_first_ = false;
    // Moved out: the decoder writes the next frame into fresh Mats, never into these.
    frame->kind = options_.kind;
    frame->images = std::move(current_);
    current_.clear();
    frame->name = absl::StrCat("video_", position_);
    frame->index = produced_++;
    frame->keep_alive.reset();
    ++position_;
    return true;
  }

 private:
  absl::Status Open() {
    std::error_code ec;
    for (std::size_t r = 0; r < roles_.size(); ++r) {
      captures_[r].release();
      if (!std::filesystem::exists(paths_[r], ec)) {
        return absl::NotFoundError(absl::StrCat(flags_[r], ": no file ", paths_[r]));
      }
    }
    for (std::size_t r = 0; r < roles_.size(); ++r) {
      if (!captures_[r].open(paths_[r])) {
        return absl::InvalidArgumentError(
            absl::StrCat(flags_[r], ": OpenCV cannot open ", paths_[r], " as a video"));
      }
    }
    return absl::OkStatus();
  }

  // Reads the next frame of every video into current_. False at the end of any.
  absl::StatusOr<bool> ReadOne() {
    std::vector<cv::Mat> images;
    for (std::size_t r = 0; r < roles_.size(); ++r) {
      cv::Mat m;
      if (!captures_[r].read(m) || m.empty()) return false;
      auto image = internal::FromVideo(roles_[r], std::move(m), flags_[r], paths_[r],
                                       position_ == 0 && !checked_first_, &info_.warnings);
      if (!image.ok()) return image.status();
      images.push_back(*std::move(image));
    }
    checked_first_ = true;
    if (absl::Status s = internal::CheckSameSize(options_.kind, images, paths_); !s.ok()) return s;
    current_ = std::move(images);
    return true;
  }

  const std::vector<ImageRole>& roles_;
  std::vector<std::string> paths_;
  std::vector<std::string> flags_;
  SourceOptions options_;
  std::vector<cv::VideoCapture> captures_;
  std::vector<cv::Mat> current_;
  bool have_first_ = false;
  bool checked_first_ = false;
  std::uint64_t position_ = 0;  // within the current pass
  std::uint64_t produced_ = 0;
};

}  // namespace

absl::StatusOr<std::unique_ptr<FrameSource>> OpenVideos(const RolePaths& videos,
                                                        const SourceOptions& options) {
  auto paths = internal::PathsPerRole(options.kind, videos, "-video");
  if (!paths.ok()) return paths.status();
  auto source = std::make_unique<VideoSource>(*std::move(paths), options);
  if (absl::Status s = source->Init(); !s.ok()) return s;
  return std::unique_ptr<FrameSource>(std::move(source));
}

}  // namespace cloudcast::sources
