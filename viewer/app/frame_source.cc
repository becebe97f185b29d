#include "app/frame_source.h"

#include <glob.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <utility>

#include "absl/strings/str_cat.h"
#include "cloudcast/datasets/synthetic.h"

namespace cloudcast::client::app {
namespace {

namespace fs = std::filesystem;

// ---------------------------------------------------------------------------------------------
// Reading one image pair.

absl::StatusOr<cv::Mat> ReadDisparity(const std::string& path, const std::string& flag) {
  // IMREAD_UNCHANGED keeps 16-bit and float samples as stored; any conversion would scale them.
  cv::Mat m = cv::imread(path, cv::IMREAD_UNCHANGED);
  if (m.empty()) {
    std::error_code ec;
    if (!fs::exists(path, ec)) return absl::NotFoundError(absl::StrCat(flag, ": no file ", path));
    return absl::InvalidArgumentError(
        absl::StrCat(flag, ": cannot decode ", path, " as an image (PNG, TIFF, PFM, ...)"));
  }
  if (m.channels() != 1) {
    return absl::InvalidArgumentError(absl::StrCat(
        flag, ": disparity image ", path, " has ", m.channels(),
        " channels; a disparity map has one (8- or 16-bit PNG/TIFF, or 32-bit float TIFF/PFM)"));
  }
  if (m.depth() != CV_8U && m.depth() != CV_16U && m.depth() != CV_32F) {
    return absl::InvalidArgumentError(
        absl::StrCat(flag, ": disparity image ", path, " has samples of type ",
                     cv::typeToString(m.type()), "; supported: 8U, 16U, 32F"));
  }
  return m;
}

absl::StatusOr<cv::Mat> ReadColour(const std::string& path, const std::string& flag) {
  // IMREAD_COLOR gives 8-bit BGR for every input: RGBA (New Tsukuba, alpha down to 0) loses its
  // alpha, grey is expanded, 16-bit is scaled, as the server would do with the encoded file.
  cv::Mat m = cv::imread(path, cv::IMREAD_COLOR);
  if (m.empty()) {
    std::error_code ec;
    if (!fs::exists(path, ec)) return absl::NotFoundError(absl::StrCat(flag, ": no file ", path));
    return absl::InvalidArgumentError(
        absl::StrCat(flag, ": cannot decode ", path, " as an image (PNG, JPEG, TIFF, ...)"));
  }
  return m;
}

absl::Status CheckSameSize(const cv::Mat& d, const cv::Mat& c, const std::string& dpath,
                           const std::string& cpath) {
  if (d.size() == c.size()) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat("disparity ", dpath, " is ", d.cols, "x", d.rows,
                                                 " but colour ", cpath, " is ", c.cols, "x", c.rows,
                                                 "; a frame's two images must match"));
}

CameraModel FileCamera(std::uint32_t w, std::uint32_t h, double focal) {
  return CameraModel::PclCompatible(w, h, focal);
}

// ---------------------------------------------------------------------------------------------
// A list of image pairs (New Tsukuba folders and globs).

struct PairPaths {
  std::string disparity;
  std::string colour;
  std::string name;
};

class ImageListSource : public FrameSource {
 public:
  ImageListSource(std::vector<PairPaths> pairs, std::string disparity_flag, std::string colour_flag,
                  const SourceOptions& options)
      : pairs_(std::move(pairs)),
        disparity_flag_(std::move(disparity_flag)),
        colour_flag_(std::move(colour_flag)),
        options_(options),
        caching_(options.loop && options.cache_bytes > 0) {}

  // Loads the first pair, so that size errors show before streaming and info() has a size.
  absl::Status Init(std::string kind, std::string description) {
    auto first = Load(0);
    if (!first.ok()) return first.status();
    first_ = *std::move(first);
    info_.kind = std::move(kind);
    info_.description = std::move(description);
    info_.width = static_cast<std::uint32_t>(first_->disparity.cols);
    info_.height = static_cast<std::uint32_t>(first_->disparity.rows);
    info_.frames_per_pass = pairs_.size();
    info_.looped = options_.loop;
    info_.camera = FileCamera(info_.width, info_.height, options_.focal);
    return absl::OkStatus();
  }

  absl::StatusOr<bool> Next(SourceFrame* frame) override {
    if (position_ == pairs_.size()) {
      if (!options_.loop) return false;
      position_ = 0;
      // A complete first pass is in the cache; an incomplete one was given up on.
      if (cache_.size() != pairs_.size()) cache_.clear();
      caching_ = false;
    }
    const std::size_t i = position_;
    Loaded loaded;
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
      cached_bytes_ += loaded.disparity.total() * loaded.disparity.elemSize() +
                       loaded.colour.total() * loaded.colour.elemSize();
      if (cached_bytes_ <= options_.cache_bytes) {
        cache_.push_back(loaded);  // Mats share their pixels: no copy
      } else {
        caching_ = false;
        cache_.clear();
      }
    }
    frame->disparity = loaded.disparity;
    frame->colour = loaded.colour;
    frame->name = pairs_[i].name;
    frame->index = produced_++;
    frame->keep_alive.reset();
    ++position_;
    return true;
  }

 private:
  struct Loaded {
    cv::Mat disparity, colour;
  };

  absl::StatusOr<Loaded> Load(std::size_t i) const {
    const PairPaths& p = pairs_[i];
    auto d = ReadDisparity(p.disparity, disparity_flag_);
    if (!d.ok()) return d.status();
    auto c = ReadColour(p.colour, colour_flag_);
    if (!c.ok()) return c.status();
    if (absl::Status s = CheckSameSize(*d, *c, p.disparity, p.colour); !s.ok()) return s;
    return Loaded{*std::move(d), *std::move(c)};
  }

  std::vector<PairPaths> pairs_;
  std::string disparity_flag_, colour_flag_;
  SourceOptions options_;
  std::optional<Loaded> first_;
  std::size_t position_ = 0;
  std::uint64_t produced_ = 0;
  // Filled during the first pass while `caching_`; used from the second pass on.
  bool caching_;
  std::vector<Loaded> cache_;
  std::uint64_t cached_bytes_ = 0;
};

// The trailing run of digits of a file stem ("tsukuba_disparity_L_00200" -> "00200").
std::string TrailingNumber(const std::string& stem) {
  std::size_t end = stem.size();
  std::size_t start = end;
  while (start > 0 && std::isdigit(static_cast<unsigned char>(stem[start - 1]))) --start;
  return stem.substr(start, end - start);
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
  if (ec)
    return absl::NotFoundError(absl::StrCat("cannot list ", dir.string(), ": ", ec.message()));
  return frames;
}

// ---------------------------------------------------------------------------------------------
// Videos.

class VideoSource : public FrameSource {
 public:
  VideoSource(std::string disparity_path, std::string colour_path, const SourceOptions& options)
      : disparity_path_(std::move(disparity_path)),
        colour_path_(std::move(colour_path)),
        options_(options) {}

  absl::Status Init() {
    if (absl::Status s = Open(); !s.ok()) return s;
    const std::string codec = FourccToString(static_cast<int>(disparity_.get(cv::CAP_PROP_FOURCC)));
    const std::string colour_codec =
        FourccToString(static_cast<int>(colour_.get(cv::CAP_PROP_FOURCC)));
    if (!IsLosslessCodec(codec)) {
      info_.warnings.push_back(absl::StrCat(
          "--disparity-video ", disparity_path_, " uses codec '", codec,
          "', which is not known to be lossless: disparity values may be changed, which moves "
          "points; encode disparity videos with FFV1 (.mkv) or PNG (.avi)"));
    }
    // The first frame is read now: it gives the size and shows unreadable files before streaming.
    auto first = ReadOne();
    if (!first.ok()) return first.status();
    if (!*first) {
      return absl::InvalidArgumentError(absl::StrCat("--disparity-video ", disparity_path_, " / ",
                                                     "--colour-video ", colour_path_,
                                                     ": no frame could be decoded"));
    }
    have_first_ = true;
    double frames_d = disparity_.get(cv::CAP_PROP_FRAME_COUNT);
    double frames_c = colour_.get(cv::CAP_PROP_FRAME_COUNT);
    info_.kind = "video";
    info_.width = static_cast<std::uint32_t>(current_.disparity.cols);
    info_.height = static_cast<std::uint32_t>(current_.disparity.rows);
    info_.camera = FileCamera(info_.width, info_.height, options_.focal);
    info_.native_fps = disparity_.get(cv::CAP_PROP_FPS);
    info_.looped = options_.loop;
    if (frames_d > 0 && frames_c > 0) {
      info_.frames_per_pass = static_cast<std::uint64_t>(std::min(frames_d, frames_c));
      if (frames_d != frames_c) {
        info_.warnings.push_back(absl::StrCat("the videos hold different frame counts (disparity ",
                                              frames_d, ", colour ", frames_c,
                                              "); streaming stops at the end of the shorter"));
      }
    }
    info_.description = absl::StrCat("videos ", disparity_path_, " (", codec, ") + ", colour_path_,
                                     " (", colour_codec, "), ", info_.width, "x", info_.height);
    if (info_.frames_per_pass)
      absl::StrAppend(&info_.description, ", ", *info_.frames_per_pass, " frames");
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
    frame->disparity = std::move(current_.disparity);
    frame->colour = std::move(current_.colour);
    current_ = {};
    frame->name = absl::StrCat("video_", position_);
    frame->index = produced_++;
    frame->keep_alive.reset();
    ++position_;
    return true;
  }

 private:
  absl::Status Open() {
    disparity_.release();
    colour_.release();
    std::error_code ec;
    for (const auto& [flag, path] :
         {std::pair<const char*, const std::string&>{"--disparity-video", disparity_path_},
          {"--colour-video", colour_path_}}) {
      if (!fs::exists(path, ec)) return absl::NotFoundError(absl::StrCat(flag, ": no file ", path));
    }
    if (!disparity_.open(disparity_path_)) {
      return absl::InvalidArgumentError(
          absl::StrCat("--disparity-video: OpenCV cannot open ", disparity_path_, " as a video"));
    }
    if (!colour_.open(colour_path_)) {
      return absl::InvalidArgumentError(
          absl::StrCat("--colour-video: OpenCV cannot open ", colour_path_, " as a video"));
    }
    return absl::OkStatus();
  }

  // Reads the next frame of both videos into current_. False at the end of either.
  absl::StatusOr<bool> ReadOne() {
    cv::Mat d, c;
    if (!disparity_.read(d) || d.empty() || !colour_.read(c) || c.empty()) return false;
    if (d.channels() == 3 || d.channels() == 4) {
      if (position_ == 0 && !checked_grey_) {
        checked_grey_ = true;
        // A grey video decodes to equal channels; unequal ones mean a colour-coded or lossy
        // (chroma-subsampled) disparity, whose values cannot be trusted.
        std::vector<cv::Mat> planes;
        cv::split(d, planes);
        if (cv::norm(planes[0], planes[1], cv::NORM_INF) != 0 ||
            cv::norm(planes[1], planes[2], cv::NORM_INF) != 0) {
          info_.warnings.push_back(absl::StrCat(
              "--disparity-video ", disparity_path_,
              ": the first frame is not grey (its colour channels differ); disparities are "
              "taken as its luminance"));
        }
      }
      cv::Mat grey;
      // For equal channels the weights sum to exactly one, so grey values come back unchanged.
      cv::cvtColor(d, grey, d.channels() == 3 ? cv::COLOR_BGR2GRAY : cv::COLOR_BGRA2GRAY);
      d = grey;
    } else if (d.channels() != 1) {
      return absl::InvalidArgumentError(absl::StrCat("--disparity-video ", disparity_path_,
                                                     ": frames have ", d.channels(),
                                                     " channels; expected grey"));
    }
    if (d.depth() != CV_8U && d.depth() != CV_16U && d.depth() != CV_32F) {
      return absl::InvalidArgumentError(absl::StrCat(
          "--disparity-video ", disparity_path_, ": frames of type ", cv::typeToString(d.type())));
    }
    if (c.depth() != CV_8U) {
      cv::Mat c8;
      c.convertTo(c8, CV_8U, 1.0 / 257.0);
      c = c8;
    }
    if (absl::Status s = CheckSameSize(d, c, disparity_path_, colour_path_); !s.ok()) return s;
    current_.disparity = d;
    current_.colour = c;
    return true;
  }

  std::string disparity_path_, colour_path_;
  SourceOptions options_;
  cv::VideoCapture disparity_, colour_;
  struct {
    cv::Mat disparity, colour;
  } current_;
  bool have_first_ = false;
  bool checked_grey_ = false;
  std::uint64_t position_ = 0;  // within the current pass
  std::uint64_t produced_ = 0;
};

// ---------------------------------------------------------------------------------------------
// Synthetic scene and the single pair.

class SyntheticSource : public FrameSource {
 public:
  SyntheticSource(std::uint32_t width, std::uint32_t height, std::uint64_t first_frame)
      : scene_(SyntheticScene::Default()), first_frame_(first_frame) {
    options_.width = width;
    options_.height = height;
  }

  absl::Status Init() {
    options_.frame = first_frame_;
    auto f = scene_.Render(options_);
    if (!f.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("--synthetic ", options_.width, "x",
                                                     options_.height, ": ", f.status().message()));
    }
    first_ = std::make_shared<SyntheticFrame>(*std::move(f));
    info_.kind = "synthetic";
    info_.width = options_.width;
    info_.height = options_.height;
    info_.camera = first_->camera;
    info_.description = absl::StrCat("synthetic scene ", options_.width, "x", options_.height,
                                     " (f32 disparity), endless");
    return absl::OkStatus();
  }

  absl::StatusOr<bool> Next(SourceFrame* frame) override {
    std::shared_ptr<SyntheticFrame> f = std::move(first_);
    if (f == nullptr) {
      options_.frame = first_frame_ + produced_;
      auto rendered = scene_.Render(options_);
      if (!rendered.ok()) return rendered.status();
      f = std::make_shared<SyntheticFrame>(*std::move(rendered));
    }
    const int h = static_cast<int>(f->height), w = static_cast<int>(f->width);
    frame->disparity = cv::Mat(h, w, CV_32FC1, f->disparity.data());
    frame->colour = cv::Mat(h, w, CV_8UC3, f->colour.data());
    frame->name = absl::StrCat("synthetic_", options_.frame);
    frame->index = produced_++;
    frame->keep_alive = std::move(f);
    return true;
  }

 private:
  SyntheticScene scene_;
  SyntheticOptions options_;
  std::uint64_t first_frame_;
  std::shared_ptr<SyntheticFrame> first_;
  std::uint64_t produced_ = 0;
};

class PairSource : public FrameSource {
 public:
  absl::Status Init(const std::string& disparity_path, const std::string& colour_path,
                    const SourceOptions& options) {
    auto d = ReadDisparity(disparity_path, "--disparity");
    if (!d.ok()) return d.status();
    auto c = ReadColour(colour_path, "--colour");
    if (!c.ok()) return c.status();
    if (absl::Status s = CheckSameSize(*d, *c, disparity_path, colour_path); !s.ok()) return s;
    disparity_ = *std::move(d);
    colour_ = *std::move(c);
    name_ = fs::path(disparity_path).stem().string();
    info_.kind = "pair";
    info_.width = static_cast<std::uint32_t>(disparity_.cols);
    info_.height = static_cast<std::uint32_t>(disparity_.rows);
    info_.camera = FileCamera(info_.width, info_.height, options.focal);
    info_.description = absl::StrCat("image pair ", disparity_path, " + ", colour_path, ", ",
                                     info_.width, "x", info_.height, ", sent repeatedly");
    return absl::OkStatus();
  }

  absl::StatusOr<bool> Next(SourceFrame* frame) override {
    frame->disparity = disparity_;
    frame->colour = colour_;
    frame->name = name_;
    frame->index = produced_++;
    frame->keep_alive.reset();
    return true;
  }

 private:
  cv::Mat disparity_, colour_;
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
  const fs::path disparity_dir = fs::path(dir) / "groundtruth" / "disparity_maps" / "left";
  const fs::path colour_dir = fs::path(dir) / "illumination" / illumination / "left";
  for (const fs::path& p : {disparity_dir, colour_dir}) {
    if (!fs::is_directory(p, ec)) {
      return absl::NotFoundError(
          absl::StrCat("--tsukuba ", dir, ": no folder ", p.string(),
                       " (expected the New Tsukuba layout: groundtruth/disparity_maps/left and "
                       "illumination/<illumination>/left)"));
    }
  }
  auto disparities = FramesIn(disparity_dir);
  if (!disparities.ok()) return disparities.status();
  auto colours = FramesIn(colour_dir);
  if (!colours.ok()) return colours.status();
  std::vector<PairPaths> pairs;
  std::vector<std::string> unpaired;
  for (const auto& [number, path] : *disparities) {
    auto it = colours->find(number);
    if (it == colours->end()) {
      unpaired.push_back(path);
      continue;
    }
    char name[32];
    std::snprintf(name, sizeof(name), "tsukuba_%05llu", static_cast<unsigned long long>(number));
    pairs.push_back({path, it->second, name});
  }
  for (const auto& [number, path] : *colours) {
    if (disparities->count(number) == 0) unpaired.push_back(path);
  }
  if (!unpaired.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--tsukuba ", dir, ": ", unpaired.size(),
        " PNG file(s) have no partner with the same frame number, e.g. ", unpaired.front()));
  }
  if (pairs.empty()) {
    return absl::NotFoundError(
        absl::StrCat("--tsukuba ", dir, ": no numbered PNG frames in ", disparity_dir.string()));
  }
  const std::size_t n = pairs.size();
  auto source =
      std::make_unique<ImageListSource>(std::move(pairs), "--tsukuba", "--tsukuba", options);
  if (absl::Status s = source->Init("tsukuba", absl::StrCat("New Tsukuba folder ", dir, " (",
                                                            illumination, "): ", n, " frames"));
      !s.ok()) {
    return s;
  }
  return std::unique_ptr<FrameSource>(std::move(source));
}

absl::StatusOr<std::unique_ptr<FrameSource>> OpenGlobs(const std::string& disparity_glob,
                                                       const std::string& colour_glob,
                                                       const SourceOptions& options) {
  auto disparities = Glob(disparity_glob);
  if (!disparities.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat("--disparity-glob: ", disparities.status().message()));
  }
  auto colours = Glob(colour_glob);
  if (!colours.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("--colour-glob: ", colours.status().message()));
  }
  if (disparities->empty()) {
    return absl::NotFoundError(
        absl::StrCat("--disparity-glob '", disparity_glob, "' matches no file"));
  }
  if (colours->empty()) {
    return absl::NotFoundError(absl::StrCat("--colour-glob '", colour_glob, "' matches no file"));
  }
  if (disparities->size() != colours->size()) {
    return absl::InvalidArgumentError(
        absl::StrCat("--disparity-glob '", disparity_glob, "' matches ", disparities->size(),
                     " files but --colour-glob '", colour_glob, "' matches ", colours->size(),
                     "; they are paired in sorted order, so the counts must be equal"));
  }
  std::vector<PairPaths> pairs;
  for (std::size_t i = 0; i < disparities->size(); ++i) {
    pairs.push_back(
        {(*disparities)[i], (*colours)[i], fs::path((*disparities)[i]).stem().string()});
  }
  const std::size_t n = pairs.size();
  auto source = std::make_unique<ImageListSource>(std::move(pairs), "--disparity-glob",
                                                  "--colour-glob", options);
  if (absl::Status s = source->Init("glob", absl::StrCat("image globs '", disparity_glob, "' + '",
                                                         colour_glob, "': ", n, " frames"));
      !s.ok()) {
    return s;
  }
  return std::unique_ptr<FrameSource>(std::move(source));
}

absl::StatusOr<std::unique_ptr<FrameSource>> OpenVideos(const std::string& disparity_video,
                                                        const std::string& colour_video,
                                                        const SourceOptions& options) {
  auto source = std::make_unique<VideoSource>(disparity_video, colour_video, options);
  if (absl::Status s = source->Init(); !s.ok()) return s;
  return std::unique_ptr<FrameSource>(std::move(source));
}

absl::StatusOr<std::unique_ptr<FrameSource>> OpenSynthetic(std::uint32_t width,
                                                           std::uint32_t height,
                                                           std::uint64_t first_frame) {
  auto source = std::make_unique<SyntheticSource>(width, height, first_frame);
  if (absl::Status s = source->Init(); !s.ok()) return s;
  return std::unique_ptr<FrameSource>(std::move(source));
}

absl::StatusOr<std::unique_ptr<FrameSource>> OpenPair(const std::string& disparity_path,
                                                      const std::string& colour_path,
                                                      const SourceOptions& options) {
  auto source = std::make_unique<PairSource>();
  if (absl::Status s = source->Init(disparity_path, colour_path, options); !s.ok()) return s;
  return std::unique_ptr<FrameSource>(std::move(source));
}

std::unique_ptr<FrameSource> LimitFrames(std::unique_ptr<FrameSource> source,
                                         std::uint64_t max_frames) {
  if (max_frames == 0) return source;
  return std::make_unique<LimitedSource>(std::move(source), max_frames);
}

// ---------------------------------------------------------------------------------------------

bool NaturalLess(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    const bool da = std::isdigit(static_cast<unsigned char>(a[i])) != 0;
    const bool db = std::isdigit(static_cast<unsigned char>(b[j])) != 0;
    if (da && db) {
      std::size_t ei = i, ej = j;
      while (ei < a.size() && std::isdigit(static_cast<unsigned char>(a[ei]))) ++ei;
      while (ej < b.size() && std::isdigit(static_cast<unsigned char>(b[ej]))) ++ej;
      // Compare by value without overflow: skip leading zeros, then length, then digits.
      std::size_t zi = i, zj = j;
      while (zi + 1 < ei && a[zi] == '0') ++zi;
      while (zj + 1 < ej && b[zj] == '0') ++zj;
      if (ei - zi != ej - zj) return ei - zi < ej - zj;
      const int c = a.compare(zi, ei - zi, b, zj, ej - zj);
      if (c != 0) return c < 0;
      i = ei;
      j = ej;
      continue;
    }
    if (a[i] != b[j]) return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]);
    ++i;
    ++j;
  }
  if ((a.size() - i) != (b.size() - j)) return a.size() - i < b.size() - j;
  return a < b;  // equal up to zero padding: byte order keeps the sort strict
}

void NaturalSort(std::vector<std::string>* names) {
  std::sort(names->begin(), names->end(), NaturalLess);
}

absl::StatusOr<std::vector<std::string>> Glob(const std::string& pattern) {
  glob_t g{};
  const int rc = ::glob(pattern.c_str(), GLOB_NOSORT, nullptr, &g);
  std::vector<std::string> out;
  if (rc == 0) {
    for (std::size_t i = 0; i < g.gl_pathc; ++i) {
      std::error_code ec;
      if (fs::is_regular_file(g.gl_pathv[i], ec)) out.emplace_back(g.gl_pathv[i]);
    }
  }
  ::globfree(&g);
  if (rc != 0 && rc != GLOB_NOMATCH) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot expand '", pattern, "' (glob error ", rc, ")"));
  }
  NaturalSort(&out);
  return out;
}

std::string FourccToString(int fourcc) {
  std::string s;
  for (int i = 0; i < 4; ++i) {
    const char c = static_cast<char>((fourcc >> (8 * i)) & 0xFF);
    s += std::isprint(static_cast<unsigned char>(c)) ? c : '?';
  }
  return s;
}

bool IsLosslessCodec(const std::string& fourcc) {
  // Codecs that store 8-bit grey exactly. HuffYUV is left out: OpenCV writes grey through YUV,
  // which moved values by 1 when measured here.
  static const char* const kLossless[] = {"FFV1", "png ", "PNG ", "MPNG", "Y800", "GREY",
                                          "Y8  ", "Y16 ", "RGB ", "BGR ", "RAW ", "raw ",
                                          "DIB ", "LAGS", "UTVD", "ULY0", "ULRG", "ZMBV"};
  for (const char* c : kLossless) {
    if (fourcc == c) return true;
  }
  return false;
}

bool LooksLikeTsukuba(const std::string& dir, const std::string& illumination) {
  std::error_code ec;
  return fs::is_directory(fs::path(dir) / "groundtruth" / "disparity_maps" / "left", ec) &&
         fs::is_directory(fs::path(dir) / "illumination" / illumination / "left", ec);
}

}  // namespace cloudcast::client::app
