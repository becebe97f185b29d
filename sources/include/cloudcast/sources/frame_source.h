// Where frames come from: a New Tsukuba folder, image globs, videos, the synthetic scene, or one
// frame's files sent again and again. cloudcast-client streams from a FrameSource; cloudcast-load
// reads one pass of it before its run. Every source yields frames of one kind (frame.h) and
// suggests the camera that fits them.
//
// Sources are single-threaded: one thread calls Next.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/core/image.h"
#include "cloudcast/sources/frame.h"

namespace cloudcast::sources {

struct SourceInfo {
  std::string kind;         // "tsukuba", "glob", "video", "synthetic", "pair"
  std::string description;  // one line for logs, e.g. "New Tsukuba folder DIR: 10 frames"
  std::uint32_t width = 0;  // of the first frame
  std::uint32_t height = 0;
  // Frames in one pass; nullopt for endless sources (synthetic, the repeated pair).
  std::optional<std::uint64_t> frames_per_pass;
  // A finite source that starts again at its end (SourceOptions::loop).
  bool looped = false;
  // The camera that fits the frames: PCL's preset (SourceOptions::focal, z = f / d) for files
  // and videos, the scene's own camera for the synthetic scene. Principal point: the centre.
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
  // the source's own (a looped or repeated frame), so treat them as read-only.
  virtual absl::StatusOr<bool> Next(SourceFrame* frame) = 0;

  const SourceInfo& info() const { return info_; }

 protected:
  SourceInfo info_;
};

// How sources read. Constructors check everything they can up front (folders, file counts, the
// first frame's images and sizes), so a typo fails before any streaming starts. Errors name the
// flag (the role's: --disparity-glob, --colour-video, ...) and the path.
struct SourceOptions {
  // What each frame holds; the files and videos give one image per role of this kind.
  FrameKind kind = FrameKind::kDisparity;
  // Repeat a finite source from its start when it ends.
  bool loop = false;
  // With `loop`: keep the decoded frames of image sources in memory (while they fit in
  // cache_bytes), so later passes cost no decoding.
  std::uint64_t cache_bytes = std::uint64_t{512} << 20;
  // Focal length (pixels) and baseline of the suggested camera for file and video sources; New
  // Tsukuba's depth frames are computed from its ground-truth disparity with them.
  double focal = CameraModel{}.fx;
  double baseline = CameraModel{}.baseline;
};

// A New Tsukuba folder (the original layout), each role's images from its folder
// (disparity: groundtruth/disparity_maps/left, colour: illumination/<illumination>/left, right:
// illumination/<illumination>/right), paired by their frame numbers, in frame order; frames are
// named tsukuba_NNNNN. Depth frames: the data set has no depth maps, so the ground-truth
// disparity is converted (z = focal * baseline / d, float, 0 where d is 0), which gives the
// disparity frames' points.
absl::StatusOr<std::unique_ptr<FrameSource>> OpenTsukuba(const std::string& dir,
                                                         const std::string& illumination,
                                                         const SourceOptions& options);

// A glob pattern per role (Glob in files.h: natural order, regular files), paired in that order;
// the counts must match. Frames are named by the stem of their first role's file.
absl::StatusOr<std::unique_ptr<FrameSource>> OpenGlobs(const RolePaths& globs,
                                                       const SourceOptions& options);

// A video per role, read with cv::VideoCapture and paired frame by frame. A disparity video must
// be lossless (FFV1, PNG, raw...): a lossy codec changes disparity values, which is warned
// about. Decoders hand grey videos back as BGR; a disparity is taken back to one channel.
absl::StatusOr<std::unique_ptr<FrameSource>> OpenVideos(const RolePaths& videos,
                                                        const SourceOptions& options);

// One frame's files (a path per role), loaded once and yielded again and again. Endless.
absl::StatusOr<std::unique_ptr<FrameSource>> OpenStill(const RolePaths& files,
                                                       const SourceOptions& options);

// The synthetic scene at width x height as frames of `kind`: disparity (in `encoding`) + colour;
// its exact depth (float, the scene's unit) + colour; or a stereo pair, the right image rendered
// from the right camera (kSyntheticStereoBaseline to the right, the camera's baseline in info()),
// so the pair is rectified by construction.
// The camera moves with the frame index and frames are named synthetic_N. Endless.
absl::StatusOr<std::unique_ptr<FrameSource>> OpenSynthetic(
    std::uint32_t width, std::uint32_t height, DisparityEncoding encoding = DisparityEncoding::kF32,
    FrameKind kind = FrameKind::kDisparity);

// Stops `source` after `max_frames` frames (0: no limit).
std::unique_ptr<FrameSource> LimitFrames(std::unique_ptr<FrameSource> source,
                                         std::uint64_t max_frames);

// Which source a program's flags name: at most one of these, or none for the default.
struct SourceSpec {
  std::string tsukuba_dir;                // --tsukuba
  std::string illumination = "daylight";  // --illumination: New Tsukuba's colour folder
  RolePaths globs;                        // --disparity-glob, --colour-glob, --depth-glob, ...
  RolePaths videos;                       // --disparity-video, --colour-video, ...
  RolePaths stills;                       // --disparity, --colour, --depth, --right: one frame
  std::uint32_t synthetic_width = 0;      // --synthetic WxH
  std::uint32_t synthetic_height = 0;
  DisparityEncoding synthetic_encoding = DisparityEncoding::kF32;

  // The flags of the sources that are set, e.g. {"--tsukuba"}; empty for the default source.
  std::vector<std::string> Given() const;
};

// The default source's size when New Tsukuba is not there.
inline constexpr std::uint32_t kDefaultSyntheticWidth = 640;
inline constexpr std::uint32_t kDefaultSyntheticHeight = 480;

// Opens the source `spec` names. With none: the New Tsukuba frames of DefaultTsukubaDir() when
// they are there, else the synthetic scene at 640x480 (of options.kind). InvalidArgument naming
// the flags when several sources are given, or a role's flag misses its partner ("no
// --colour-glob given: disparity frames need --disparity-glob and --colour-glob").
absl::StatusOr<std::unique_ptr<FrameSource>> OpenSource(const SourceSpec& spec,
                                                        const SourceOptions& options);

// Where the default source looks for New Tsukuba ($CLOUDCAST_DATA, else the folder next to the
// checkout), as a normalized path.
std::string DefaultTsukubaDir();

}  // namespace cloudcast::sources
