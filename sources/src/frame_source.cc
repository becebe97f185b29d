#include "cloudcast/sources/frame_source.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <map>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/datasets/tsukuba.h"
#include "cloudcast/sources/files.h"
#include "images.h"

namespace cloudcast::sources {
namespace {

namespace fs = std::filesystem;
using internal::CheckSameSize;
using internal::ReadImage;

std::uint64_t Bytes(const std::vector<cv::Mat>& images) {
  std::uint64_t n = 0;
  for (const cv::Mat& m : images) n += m.total() * m.elemSize();
  return n;
}

// ---------------------------------------------------------------------------------------------
// A list of frames stored as files (New Tsukuba folders and globs), a path per role.

struct FramePaths {
  std::vector<std::string> paths;  // one per RolesOf(kind)
  std::string name;
};

class ImageListSource : public FrameSource {
 public:
  // `depth_from_disparity`: the depth role's files are disparity maps, converted (New Tsukuba).
  ImageListSource(std::vector<FramePaths> frames, std::vector<std::string> flags,
                  const SourceOptions& options, bool depth_from_disparity = false)
      : frames_(std::move(frames)),
        flags_(std::move(flags)),
        options_(options),
        depth_from_disparity_(depth_from_disparity),
        caching_(options.loop && options.cache_bytes > 0) {}

  // Loads the first frame, so that size errors show before streaming and info() has a size.
  absl::Status Init(std::string kind, std::string description) {
    auto first = Load(0);
    if (!first.ok()) return first.status();
    first_ = *std::move(first);
    info_.kind = std::move(kind);
    info_.description = std::move(description);
    info_.width = static_cast<std::uint32_t>(first_->front().cols);
    info_.height = static_cast<std::uint32_t>(first_->front().rows);
    info_.frames_per_pass = frames_.size();
    info_.looped = options_.loop;
    info_.camera = CameraModel::PclCompatible(info_.width, info_.height, options_.focal);
    info_.camera.baseline = options_.baseline;
    return absl::OkStatus();
  }

  absl::StatusOr<bool> Next(SourceFrame* frame) override {
    if (position_ == frames_.size()) {
      if (!options_.loop) return false;
      position_ = 0;
      // A complete first pass is in the cache; an incomplete one was given up on.
      if (cache_.size() != frames_.size()) cache_.clear();
      caching_ = false;
    }
    const std::size_t i = position_;
    std::vector<cv::Mat> loaded;
    if (i < cache_.size() && !caching_) {
      loaded = cache_[i];
    } else if (i == 0 && first_) {
      loaded = *std::move(first_);
      first_.reset();
    } else {
      auto l = Load(i);
      if (!l.ok()) return l.status();
      loaded = *std::move(l);
    }
    if (caching_) {
      cached_bytes_ += Bytes(loaded);
      if (cached_bytes_ <= options_.cache_bytes) {
        cache_.push_back(loaded);  // Mats share their pixels: no copy
      } else {
        caching_ = false;
        cache_.clear();
      }
    }
    frame->kind = options_.kind;
    frame->images = std::move(loaded);
    frame->name = frames_[i].name;
    frame->index = produced_++;
    frame->keep_alive.reset();
    ++position_;
    return true;
  }

 private:
  absl::StatusOr<std::vector<cv::Mat>> Load(std::size_t i) const {
    const FramePaths& f = frames_[i];
    const std::vector<ImageRole>& roles = RolesOf(options_.kind);
    std::vector<cv::Mat> images;
    for (std::size_t r = 0; r < roles.size(); ++r) {
      const bool converted = depth_from_disparity_ && roles[r] == ImageRole::kDepth;
      auto m = ReadImage(converted ? ImageRole::kDisparity : roles[r], f.paths[r], flags_[r]);
      if (!m.ok()) return m.status();
      if (converted) {
        CameraModel camera;
        camera.fx = camera.fy = options_.focal;
        camera.baseline = options_.baseline;
        *m = internal::DepthFromDisparity(*m, camera);
      }
      images.push_back(*std::move(m));
    }
    if (absl::Status s = CheckSameSize(options_.kind, images, f.paths); !s.ok()) return s;
    return images;
  }

  std::vector<FramePaths> frames_;
  std::vector<std::string> flags_;  // one per role, for errors
  SourceOptions options_;
  bool depth_from_disparity_;
  std::optional<std::vector<cv::Mat>> first_;
  std::size_t position_ = 0;
  std::uint64_t produced_ = 0;
  // Filled during the first pass while `caching_`; used from the second pass on.
  bool caching_;
  std::vector<std::vector<cv::Mat>> cache_;
  std::uint64_t cached_bytes_ = 0;
};

// The trailing run of digits of a file stem ("tsukuba_disparity_L_00200" -> "00200").
std::string TrailingNumber(const std::string& stem) {
  std::size_t start = stem.size();
  while (start > 0 && std::isdigit(static_cast<unsigned char>(stem[start - 1]))) --start;
  return stem.substr(start);
}

// PNG files of a folder by their frame number.
absl::StatusOr<std::map<std::uint64_t, std::string>> FramesIn(const fs::path& dir) {
  std::map<std::uint64_t, std::string> frames;
  std::error_code ec;
  for (const fs::directory_entry& e : fs::directory_iterator(dir, ec)) {
    if (!e.is_regular_file()) continue;
    std::string ext = e.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char ch) { return std::tolower(ch); });
    if (ext != ".png") continue;
    const std::string number = TrailingNumber(e.path().stem().string());
    if (number.empty() || number.size() > 18) continue;
    frames[std::stoull(number)] = e.path().string();
  }
  if (ec) {
    return absl::NotFoundError(absl::StrCat("cannot list ", dir.string(), ": ", ec.message()));
  }
  return frames;
}

// ---------------------------------------------------------------------------------------------
// The synthetic scene, the repeated still frame, and the frame limit.

int MatType(DisparityEncoding e) {
  switch (e) {
    case DisparityEncoding::kU8:
      return CV_8UC1;
    case DisparityEncoding::kU16:
      return CV_16UC1;
    case DisparityEncoding::kF32:
      return CV_32FC1;
  }
  return CV_32FC1;
}

const char* EncodingName(DisparityEncoding e) {
  switch (e) {
    case DisparityEncoding::kU8:
      return "u8";
    case DisparityEncoding::kU16:
      return "u16";
    case DisparityEncoding::kF32:
      return "f32";
  }
  return "?";
}

class SyntheticSource : public FrameSource {
 public:
  SyntheticSource(std::uint32_t width, std::uint32_t height, DisparityEncoding encoding,
                  FrameKind kind)
      : scene_(SyntheticScene::Default()), kind_(kind) {
    options_.width = width;
    options_.height = height;
    // Depth is computed from exact disparities; a stereo pair needs none.
    options_.disparity_encoding =
        kind == FrameKind::kDisparity ? encoding : DisparityEncoding::kF32;
  }

  absl::Status Init() {
    auto f = Render(0);
    if (!f.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("--synthetic ", options_.width, "x",
                                                     options_.height, ": ", f.status().message()));
    }
    first_ = *std::move(f);
    info_.kind = "synthetic";
    info_.width = options_.width;
    info_.height = options_.height;
    info_.camera = first_->left.camera;
    if (kind_ == FrameKind::kStereo) info_.camera.baseline = kSyntheticStereoBaseline;
    const std::string what =
        kind_ == FrameKind::kDisparity
            ? absl::StrCat(EncodingName(options_.disparity_encoding), " disparity")
            : std::string(kind_ == FrameKind::kDepth ? "float depth" : "stereo pairs");
    info_.description = absl::StrCat("synthetic scene ", options_.width, "x", options_.height, " (",
                                     what, "), endless");
    return absl::OkStatus();
  }

  absl::StatusOr<bool> Next(SourceFrame* frame) override {
    std::shared_ptr<Rendered> f = std::move(first_);
    const std::uint64_t index = produced_;
    if (f == nullptr) {
      auto rendered = Render(index);
      if (!rendered.ok()) return rendered.status();
      f = *std::move(rendered);
    }
    SyntheticFrame& left = f->left;
    const int h = static_cast<int>(left.height), w = static_cast<int>(left.width);
    const cv::Mat colour(h, w, CV_8UC3, left.colour.data());
    frame->kind = kind_;
    switch (kind_) {
      case FrameKind::kDisparity:
        frame->images = {cv::Mat(h, w, MatType(options_.disparity_encoding), left.disparity.data()),
                         colour};
        break;
      case FrameKind::kDepth:
        frame->images = {f->depth, colour};
        break;
      case FrameKind::kStereo:
        frame->images = {colour, cv::Mat(h, w, CV_8UC3, f->right.colour.data())};
        break;
    }
    frame->name = absl::StrCat("synthetic_", index);
    frame->index = produced_++;
    frame->keep_alive = std::move(f);
    return true;
  }

 private:
  // One frame's renders: the left view, and what the kind adds to it.
  struct Rendered {
    SyntheticFrame left;
    SyntheticFrame right;  // kStereo
    cv::Mat depth;         // kDepth
  };

  absl::StatusOr<std::shared_ptr<Rendered>> Render(std::uint64_t index) {
    auto r = std::make_shared<Rendered>();
    SyntheticOptions o = options_;
    o.frame = index;
    auto left = scene_.Render(o);
    if (!left.ok()) return left.status();
    r->left = *std::move(left);
    if (kind_ == FrameKind::kStereo) {
      o.eye_x = kSyntheticStereoBaseline;
      auto right = scene_.Render(o);
      if (!right.ok()) return right.status();
      r->right = *std::move(right);
    } else if (kind_ == FrameKind::kDepth) {
      const cv::Mat d(static_cast<int>(r->left.height), static_cast<int>(r->left.width), CV_32FC1,
                      r->left.disparity.data());
      r->depth = internal::DepthFromDisparity(d, r->left.camera);
    }
    return r;
  }

  SyntheticScene scene_;
  FrameKind kind_;
  SyntheticOptions options_;
  std::shared_ptr<Rendered> first_;
  std::uint64_t produced_ = 0;
};

class StillSource : public FrameSource {
 public:
  absl::Status Init(const std::vector<std::string>& paths, const SourceOptions& options) {
    kind_ = options.kind;
    const std::vector<ImageRole>& roles = RolesOf(kind_);
    for (std::size_t r = 0; r < roles.size(); ++r) {
      auto m = ReadImage(roles[r], paths[r], RoleFlag(roles[r], ""));
      if (!m.ok()) return m.status();
      images_.push_back(*std::move(m));
    }
    if (absl::Status s = CheckSameSize(kind_, images_, paths); !s.ok()) return s;
    name_ = fs::path(paths.front()).stem().string();
    info_.kind = "pair";
    info_.width = static_cast<std::uint32_t>(images_.front().cols);
    info_.height = static_cast<std::uint32_t>(images_.front().rows);
    info_.camera = CameraModel::PclCompatible(info_.width, info_.height, options.focal);
    info_.description = absl::StrCat("image pair ", absl::StrJoin(paths, " + "), ", ", info_.width,
                                     "x", info_.height, ", sent repeatedly");
    return absl::OkStatus();
  }

  absl::StatusOr<bool> Next(SourceFrame* frame) override {
    frame->kind = kind_;
    frame->images = images_;
    frame->name = name_;
    frame->index = produced_++;
    frame->keep_alive.reset();
    return true;
  }

 private:
  FrameKind kind_ = FrameKind::kDisparity;
  std::vector<cv::Mat> images_;
  std::string name_;
  std::uint64_t produced_ = 0;
};

class LimitedSource : public FrameSource {
 public:
  LimitedSource(std::unique_ptr<FrameSource> inner, std::uint64_t max_frames)
      : inner_(std::move(inner)), max_frames_(max_frames) {
    info_ = inner_->info();
    if (!info_.frames_per_pass || *info_.frames_per_pass > max_frames_) {
      info_.description += absl::StrCat(" (first ", max_frames_, " frames)");
    }
  }
  absl::StatusOr<bool> Next(SourceFrame* frame) override {
    if (taken_ >= max_frames_) return false;
    auto got = inner_->Next(frame);
    if (got.ok() && *got) ++taken_;
    return got;
  }

 private:
  std::unique_ptr<FrameSource> inner_;
  std::uint64_t max_frames_;
  std::uint64_t taken_ = 0;
};

}  // namespace

// ---------------------------------------------------------------------------------------------

absl::StatusOr<std::unique_ptr<FrameSource>> OpenTsukuba(const std::string& dir,
                                                         const std::string& illumination,
                                                         const SourceOptions& options) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    return absl::NotFoundError(absl::StrCat("--tsukuba: no folder ", dir));
  }
  const std::vector<ImageRole>& roles = RolesOf(options.kind);
  std::vector<std::string> layout;
  for (ImageRole role : roles) layout.push_back(TsukubaFolder("", role, "<illumination>"));
  // Each role's frames by number.
  std::vector<std::map<std::uint64_t, std::string>> by_role;
  for (ImageRole role : roles) {
    const std::string folder = TsukubaFolder(dir, role, illumination);
    if (!fs::is_directory(folder, ec)) {
      return absl::NotFoundError(
          absl::StrCat("--tsukuba ", dir, ": no folder ", folder,
                       " (expected the New Tsukuba layout: ", absl::StrJoin(layout, " and "), ")"));
    }
    auto frames = FramesIn(folder);
    if (!frames.ok()) return frames.status();
    by_role.push_back(*std::move(frames));
  }
  std::vector<FramePaths> frames;
  std::vector<std::string> unpaired;
  for (std::size_t r = 0; r < by_role.size(); ++r) {
    for (const auto& [number, path] : by_role[r]) {
      bool complete = true;
      for (const auto& other : by_role) complete = complete && other.count(number) > 0;
      if (!complete) {
        unpaired.push_back(path);
      } else if (r == 0) {
        FramePaths f;
        for (const auto& role_frames : by_role) f.paths.push_back(role_frames.at(number));
        char name[32];
        std::snprintf(name, sizeof(name), "tsukuba_%05llu",
                      static_cast<unsigned long long>(number));
        f.name = name;
        frames.push_back(std::move(f));
      }
    }
  }
  if (!unpaired.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--tsukuba ", dir, ": ", unpaired.size(),
        " PNG file(s) have no partner with the same frame number, e.g. ", unpaired.front()));
  }
  if (frames.empty()) {
    return absl::NotFoundError(absl::StrCat("--tsukuba ", dir, ": no numbered PNG frames in ",
                                            TsukubaFolder(dir, roles.front(), illumination)));
  }
  const std::size_t n = frames.size();
  auto source = std::make_unique<ImageListSource>(
      std::move(frames), std::vector<std::string>(roles.size(), "--tsukuba"), options,
      /*depth_from_disparity=*/true);
  if (absl::Status s = source->Init("tsukuba", absl::StrCat("New Tsukuba folder ", dir, " (",
                                                            illumination, "): ", n, " frames"));
      !s.ok()) {
    return s;
  }
  return std::unique_ptr<FrameSource>(std::move(source));
}

absl::StatusOr<std::unique_ptr<FrameSource>> OpenGlobs(const RolePaths& globs,
                                                       const SourceOptions& options) {
  auto patterns = internal::PathsPerRole(options.kind, globs, "-glob");
  if (!patterns.ok()) return patterns.status();
  const std::vector<ImageRole>& roles = RolesOf(options.kind);
  std::vector<std::string> flags;
  std::vector<std::vector<std::string>> files;
  for (std::size_t r = 0; r < roles.size(); ++r) {
    flags.push_back(RoleFlag(roles[r], "-glob"));
    auto matched = Glob((*patterns)[r]);
    if (!matched.ok()) {
      return absl::InvalidArgumentError(absl::StrCat(flags[r], ": ", matched.status().message()));
    }
    files.push_back(*std::move(matched));
  }
  for (std::size_t r = 0; r < roles.size(); ++r) {
    if (files[r].empty()) {
      return absl::NotFoundError(absl::StrCat(flags[r], " '", (*patterns)[r], "' matches no file"));
    }
  }
  for (std::size_t r = 1; r < roles.size(); ++r) {
    if (files[r].size() == files[0].size()) continue;
    return absl::InvalidArgumentError(
        absl::StrCat(flags[0], " '", (*patterns)[0], "' matches ", files[0].size(), " files but ",
                     flags[r], " '", (*patterns)[r], "' matches ", files[r].size(),
                     "; they are paired in sorted order, so the counts must be equal"));
  }
  std::vector<FramePaths> frames(files[0].size());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    for (const auto& role_files : files) frames[i].paths.push_back(role_files[i]);
    frames[i].name = fs::path(files[0][i]).stem().string();
  }
  const std::size_t n = frames.size();
  std::vector<std::string> quoted;
  for (const std::string& p : *patterns) quoted.push_back(absl::StrCat("'", p, "'"));
  auto source = std::make_unique<ImageListSource>(std::move(frames), flags, options);
  if (absl::Status s = source->Init(
          "glob", absl::StrCat("image globs ", absl::StrJoin(quoted, " + "), ": ", n, " frames"));
      !s.ok()) {
    return s;
  }
  return std::unique_ptr<FrameSource>(std::move(source));
}

absl::StatusOr<std::unique_ptr<FrameSource>> OpenStill(const RolePaths& files,
                                                       const SourceOptions& options) {
  auto paths = internal::PathsPerRole(options.kind, files, "");
  if (!paths.ok()) return paths.status();
  auto source = std::make_unique<StillSource>();
  if (absl::Status s = source->Init(*paths, options); !s.ok()) return s;
  return std::unique_ptr<FrameSource>(std::move(source));
}

absl::StatusOr<std::unique_ptr<FrameSource>> OpenSynthetic(std::uint32_t width,
                                                           std::uint32_t height,
                                                           DisparityEncoding encoding,
                                                           FrameKind kind) {
  auto source = std::make_unique<SyntheticSource>(width, height, encoding, kind);
  if (absl::Status s = source->Init(); !s.ok()) return s;
  return std::unique_ptr<FrameSource>(std::move(source));
}

std::unique_ptr<FrameSource> LimitFrames(std::unique_ptr<FrameSource> source,
                                         std::uint64_t max_frames) {
  if (max_frames == 0) return source;
  return std::make_unique<LimitedSource>(std::move(source), max_frames);
}

// ---------------------------------------------------------------------------------------------

std::vector<std::string> SourceSpec::Given() const {
  std::vector<std::string> given;
  if (!tsukuba_dir.empty()) given.push_back("--tsukuba");
  for (const auto& [paths, suffix] : {std::pair<const RolePaths&, const char*>{globs, "-glob"},
                                      {videos, "-video"},
                                      {stills, ""}}) {
    std::vector<std::string> flags;
    for (const auto& [role, path] : paths) {
      if (!path.empty()) flags.push_back(RoleFlag(role, suffix));
    }
    if (!flags.empty()) given.push_back(absl::StrJoin(flags, " + "));
  }
  if (synthetic_width != 0 || synthetic_height != 0) given.push_back("--synthetic");
  return given;
}

std::string DefaultTsukubaDir() {
  return fs::path(tsukuba::DefaultDir()).lexically_normal().string();
}

absl::StatusOr<std::unique_ptr<FrameSource>> OpenSource(const SourceSpec& spec,
                                                        const SourceOptions& options) {
  const std::vector<std::string> given = spec.Given();
  if (given.size() > 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("choose one source: ", given[0], " and ", given[1], " were both given"));
  }
  if (!spec.tsukuba_dir.empty()) return OpenTsukuba(spec.tsukuba_dir, spec.illumination, options);
  if (!spec.globs.empty()) return OpenGlobs(spec.globs, options);
  if (!spec.videos.empty()) return OpenVideos(spec.videos, options);
  if (!spec.stills.empty()) return OpenStill(spec.stills, options);
  const bool synthetic = spec.synthetic_width != 0 || spec.synthetic_height != 0;
  const std::string dir = DefaultTsukubaDir();
  if (!synthetic && LooksLikeTsukuba(dir, spec.illumination, options.kind)) {
    return OpenTsukuba(dir, spec.illumination, options);
  }
  return synthetic ? OpenSynthetic(spec.synthetic_width, spec.synthetic_height,
                                   spec.synthetic_encoding, options.kind)
                   : OpenSynthetic(kDefaultSyntheticWidth, kDefaultSyntheticHeight,
                                   spec.synthetic_encoding, options.kind);
}

}  // namespace cloudcast::sources
