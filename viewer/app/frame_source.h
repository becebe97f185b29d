// Where cloudcast-client's frames come from: a New Tsukuba folder, two image globs, two video
// files, the synthetic scene, or one image pair sent again and again. Every source yields
// disparity + colour cv::Mat pairs and suggests the camera that fits its frames.
//
// Sources are single-threaded: one thread calls Next (cloudcast-client's sender thread).
#pragma once

#include <cstdint>
#include <memory>
#include <opencv2/core/mat.hpp>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/core/camera.h"

namespace cloudcast::client::app {

struct SourceFrame {
  // One channel, CV_8U, CV_16U or CV_32F, values as stored (no scaling).
  cv::Mat disparity;
  // CV_8UC3 (BGR), CV_8UC4 (BGRA) or CV_8UC1 (grey).
  cv::Mat colour;
  // Position in the stream of frames this source produced, from 0, counting every loop.
  std::uint64_t index = 0;
  // Which frame this is, e.g. "tsukuba_00200" or a file stem; sent as the frame_id.
  std::string name;
  // Keeps the memory the Mats point into alive when it is not the Mats' own (synthetic frames).
  std::shared_ptr<const void> keep_alive;
};

struct SourceInfo {
  std::string kind;         // "tsukuba", "glob", "video", "synthetic", "pair"
  std::string description;  // one line for logs, e.g. "New Tsukuba folder DIR: 10 frames"
  std::uint32_t width = 0;  // of the first frame
  std::uint32_t height = 0;
  // Frames in one pass; nullopt for endless sources (synthetic, the looped pair).
  std::optional<std::uint64_t> frames_per_pass;
  // A finite source that starts again at its end (SourceOptions::loop).
  bool looped = false;
  // The camera that fits the frames: PCL's preset (focal 615, z = f / d) for files and videos,
  // the scene's own camera for the synthetic scene. Its principal point is the image centre.
  CameraModel camera;
  // Frame rate stored in a video file; 0 otherwise.
  double native_fps = 0;
  // Things the user should know but that do not stop streaming (e.g. a lossy disparity codec).
  std::vector<std::string> warnings;
};

class FrameSource {
 public:
  virtual ~FrameSource() = default;

  // The next frame. Returns false at the end of a finite source; an error when a frame cannot be
  // read (the message names the file). `frame` is overwritten; its Mats may share memory with
  // the source's own (a looped pair), so treat them as read-only.
  virtual absl::StatusOr<bool> Next(SourceFrame* frame) = 0;

  const SourceInfo& info() const { return info_; }

 protected:
  SourceInfo info_;
};

// ---------------------------------------------------------------------------------------------
// The sources. Constructors check everything they can up front (folders, file counts, sizes of
// the first frame), so a typo fails before any streaming starts. Errors name the flag and path.

struct SourceOptions {
  // Repeat a finite source from its start when it ends.
  bool loop = false;
  // With `loop`: keep the decoded frames of image sources in memory (while they fit in
  // cache_bytes), so later passes cost no PNG decoding.
  std::uint64_t cache_bytes = std::uint64_t{512} << 20;
  // Focal length (pixels) of the suggested camera for file and video sources.
  double focal = 615.0;
};

// A New Tsukuba folder (the original layout): groundtruth/disparity_maps/left/*.png paired with
// illumination/<illumination>/left/*.png by their frame numbers, in frame order.
absl::StatusOr<std::unique_ptr<FrameSource>> OpenTsukuba(const std::string& dir,
                                                         const std::string& illumination,
                                                         const SourceOptions& options);

// Two glob patterns (POSIX glob, wildcards anywhere in the path), each sorted in natural order
// (digit runs compare as numbers: frame_9 < frame_10). The counts must match.
absl::StatusOr<std::unique_ptr<FrameSource>> OpenGlobs(const std::string& disparity_glob,
                                                       const std::string& colour_glob,
                                                       const SourceOptions& options);

// Two video files read with cv::VideoCapture. The disparity video must be lossless (FFV1, PNG,
// HuffYUV-class codecs, raw): a lossy codec changes disparity values, which is warned about.
// Decoders hand grey videos back as BGR; the disparity is taken back to one channel.
absl::StatusOr<std::unique_ptr<FrameSource>> OpenVideos(const std::string& disparity_video,
                                                        const std::string& colour_video,
                                                        const SourceOptions& options);

// The synthetic scene at width x height; the camera moves with the frame index. Endless.
absl::StatusOr<std::unique_ptr<FrameSource>> OpenSynthetic(std::uint32_t width,
                                                           std::uint32_t height,
                                                           std::uint64_t first_frame = 0);

// One disparity + colour pair, loaded once and yielded again and again. Endless.
absl::StatusOr<std::unique_ptr<FrameSource>> OpenPair(const std::string& disparity_path,
                                                      const std::string& colour_path,
                                                      const SourceOptions& options);

// Stops `source` after `max_frames` frames (0: no limit).
std::unique_ptr<FrameSource> LimitFrames(std::unique_ptr<FrameSource> source,
                                         std::uint64_t max_frames);

// ---------------------------------------------------------------------------------------------
// Helpers, public for tests.

// Sorts strings so that runs of digits compare by value ("a2" < "a10"); ties keep byte order.
void NaturalSort(std::vector<std::string>* names);
bool NaturalLess(const std::string& a, const std::string& b);

// Files matching a POSIX glob pattern, naturally sorted. Empty when nothing matches.
absl::StatusOr<std::vector<std::string>> Glob(const std::string& pattern);

// The four-character code of a video codec as text ("FFV1", "png "), and whether that codec
// keeps 8-bit grey values exactly.
std::string FourccToString(int fourcc);
bool IsLosslessCodec(const std::string& fourcc);

// Whether `dir` holds the New Tsukuba layout (both left folders exist).
bool LooksLikeTsukuba(const std::string& dir, const std::string& illumination = "daylight");

}  // namespace cloudcast::client::app
