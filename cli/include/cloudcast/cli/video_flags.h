// The video uplink's flags (--encoding h264's settings), defined once for the programs that send
// frames (cloudcast-client, cloudcast-load): --h264-preset, --h264-crf, --h264-mbps,
// --h264-keyframe-interval, --h264-threads, --h264-444, --h264-grey, --h264-separate-stereo.
// Bad values are refused by the parser with the flag's name ("--h264-crf: Value 60 not in range").
//
//   cloudcast::cli::VideoFlags h264(app, "Streaming");
//   app.parse(argc, argv);
//   if (encoding != video::kH264 && h264.AnyGiven()) ...   // "--h264-crf needs --encoding h264"
//   video::FrameEncoderOptions o = h264.Options(fps);
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "cloudcast/video/frame_encoder.h"
#include "cloudcast/video/h264_settings.h"

namespace cloudcast::cli {

class VideoFlags {
 public:
  // Registers the flags on `app` (which must outlive this object) in `group`.
  VideoFlags(CLI::App& app, const std::string& group);
  VideoFlags(const VideoFlags&) = delete;
  VideoFlags& operator=(const VideoFlags&) = delete;

  // The encoder's settings for a stream of `fps` frames (pairs) per second (the one-frame VBV is
  // bitrate / fps); fps <= 0 (a closed loop, an unpaced source) counts as 30.
  video::FrameEncoderOptions Options(double fps) const {
    return video::ToFrameEncoderOptions(s_, fps);
  }
  // The --h264-* flags given, in the order registered (for "needs --encoding h264").
  std::vector<std::string> GivenFlags() const;
  bool AnyGiven() const { return !GivenFlags().empty(); }

 private:
  CLI::App& app_;
  // The values, defaults and mapping the ROS bridges' h264/* parameters share.
  video::H264Settings s_;
};

}  // namespace cloudcast::cli
