// The video uplink's settings as a user gives them (cloudcast-client's and cloudcast-load's
// --h264-* flags, the ROS bridges' h264/* parameters), their rules, and the one mapping onto the
// encoder's options (ToFrameEncoderOptions, in cloudcast_video_frames). The struct and its rules
// need no codec: the bridges read and check their parameters with them in builds without video
// (the client-only arm64 build of the ROS 2 bridge).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <string>
#include <string_view>


namespace cloudcast::video {

struct FrameEncoderOptions;  // frame_encoder.h

// The x264 presets offered (docs/video.md measures them); slower ones cost a robot's core more
// than a frame time.
inline constexpr std::array<std::string_view, 6> kH264Presets = {
    "ultrafast", "superfast", "veryfast", "faster", "fast", "medium"};

struct H264Settings {
  std::string preset = "veryfast";
  // Constant quality (1..51, lower is better), capped by mbps; 0: mbps alone.
  double crf = 18;
  // Both views of a pair together, Mbit/s: the cap of a one-frame VBV; under rate control the
  // most the controller's target may give the encoder.
  double mbps = 8;
  int keyframe_interval = 60;  // 0: only the first, and asked for (EncoderOptions' default)
  int threads = 1;             // x264 sliced threads (EncoderOptions' default)
  bool colour_444 = false;       // colour as 4:4:4 (kColour444) instead of 4:2:0
  bool grey = false;             // every image coded grey (4:0:0)
  bool separate_stereo = false;  // a bitstream per view instead of right interleaved after left
  // Every picture exactly as given (x264's qp 0; crf and mbps unused, and a rate controller
  // cannot lower it): for rendered, noise-free cameras (a simulator's), where lossless costs less
  // than the near-lossless CRFs that keep stereo matching whole (docs/video.md). A real camera's
  // noise makes it 40 Mbit/s and more.
  bool lossless = false;
  // More x264 options, "key=value:key=value", after ours (e.g. "partitions=all:ref=4", which
  // docs/video.md measured a quarter smaller lossless on the synthetic scene). What the encoder
  // sets for latency and rate control (kX264ParamsOurs) is refused.
  std::string x264_params;

  // The rules, each with the text errors give after "must be ".
  static bool PresetOk(std::string_view p) {
    return std::find(kH264Presets.begin(), kH264Presets.end(), p) != kH264Presets.end();
  }
  static constexpr const char* kPresetRule = "ultrafast, superfast, veryfast, faster, fast or medium";
  static bool CrfOk(double v) { return std::isfinite(v) && v >= 0 && v <= 51; }
  static constexpr const char* kCrfRule = "0 or a quality in [1, 51]";
  static bool MbpsOk(double v) { return std::isfinite(v) && v >= 0.05 && v <= 1000; }
  static constexpr const char* kMbpsRule = "a bitrate in [0.05, 1000] Mbit/s";
  // The x264 options the encoder sets itself: without lookahead, B-frames or frame threads a
  // picture is coded at once; the rate control is the flags' (crf, mbps, lossless) and the rate
  // controller's; an IDR repeats the headers for a late joiner.
  static constexpr std::array<std::string_view, 22> kX264ParamsOurs = {
      "bframes", "b-adapt",    "b-pyramid", "rc-lookahead", "sync-lookahead", "lookahead-threads",
      "threads", "sliced-threads", "repeat-headers", "keyint", "min-keyint", "scenecut",
      "intra-refresh", "qp", "crf", "bitrate", "vbv-maxrate", "vbv-bufsize", "vbv-init", "pass",
      "stats", "qpmin"};
  static constexpr std::size_t kMaxX264Params = 256;
  // "" when `params` may be given, else why not (the text after "'<params>': ").
  static std::string X264ParamsProblem(std::string_view params) {
    if (params.empty()) return "";  // none
    if (params.size() > kMaxX264Params) {
      return "longer than " + std::to_string(kMaxX264Params) + " characters";
    }
    for (char c : params) {
      const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                      c == '_' || c == '-' || c == '.' || c == ',' || c == '=' || c == ':' ||
                      c == '+';
      if (!ok) return std::string("the character '") + c + "' is none of x264's (key=value:...)";
    }
    std::size_t at = 0;
    while (at <= params.size()) {
      const std::size_t end = std::min(params.find(':', at), params.size());
      const std::string_view item = params.substr(at, end - at);
      const std::string_view key = item.substr(0, item.find('='));
      if (key.empty()) return "an empty option (key=value:key=value)";
      if (std::find(kX264ParamsOurs.begin(), kX264ParamsOurs.end(), key) != kX264ParamsOurs.end()) {
        return "'" + std::string(key) +
               "' is the encoder's own (latency and rate control: the --h264-* settings)";
      }
      at = end + 1;
    }
    return "";
  }
  static constexpr int kMaxKeyframeInterval = 100000;
  static constexpr int kMaxThreads = 16;
};

// The encoder's settings for a stream of `fps` frames (pairs) per second (the one-frame VBV is
// bitrate / fps); fps <= 0 (a closed loop, an unpaced source) counts as 30. In
// cloudcast_video_frames (h264_settings.cc).
FrameEncoderOptions ToFrameEncoderOptions(const H264Settings& settings, double fps);

}  // namespace cloudcast::video
