#include "cloudcast/cli/video_flags.h"

#include <algorithm>
#include <cmath>

#include "cloudcast/cli/checks.h"

namespace cloudcast::cli {
namespace {

const char* const kFlags[] = {
    "--h264-preset",  "--h264-crf", "--h264-mbps", "--h264-keyframe-interval",
    "--h264-threads", "--h264-444", "--h264-grey", "--h264-separate-stereo"};

}  // namespace

VideoFlags::VideoFlags(CLI::App& app, const std::string& group) : app_(app) {
  app.add_option("--h264-preset", preset_,
                 "x264 preset with --encoding h264 (ultrafast .. medium; docs/video.md measures "
                 "them)")
      ->check(CLI::IsMember({"ultrafast", "superfast", "veryfast", "faster", "fast", "medium"}))
      ->capture_default_str()
      ->group(group);
  app.add_option("--h264-crf", crf_,
                 "Constant quality with --encoding h264 (1..51, lower is better), capped by "
                 "--h264-mbps; 0: --h264-mbps alone")
      ->check(NumberCheck("0 or a quality in [1, 51]", [](double v) { return v >= 0 && v <= 51; }))
      ->capture_default_str()
      ->group(group);
  app.add_option("--h264-mbps", mbps_,
                 "Bitrate with --encoding h264, Mbit/s, both views of a pair together: the cap "
                 "of a one-frame VBV (no frame waits behind a large one); with cloudcast-client's "
                 "--rate-control, the most the rate controller's target may give the encoder")
      ->check(NumberCheck("a bitrate in [0.05, 1000] Mbit/s",
                          [](double v) { return v >= 0.05 && v <= 1000; }))
      ->capture_default_str()
      ->group(group);
  app.add_option("--h264-keyframe-interval", keyframe_interval_,
                 "Frames between IDRs with --encoding h264 (0: only the first and those the "
                 "server asks for)")
      ->check(CLI::Range(0, 100000))
      ->capture_default_str()
      ->group(group);
  app.add_option("--h264-threads", threads_,
                 "Encoder threads with --encoding h264 (x264 sliced threads: no added latency)")
      ->check(CLI::Range(1, 16))
      ->capture_default_str()
      ->group(group);
  app.add_flag("--h264-444", colour_444_,
               "Colour as 4:4:4 with --encoding h264 (4:2:0 alone caps colour near 28-39 dB "
               "PSNR; docs/video.md)")
      ->group(group);
  app.add_flag("--h264-grey", grey_,
               "Images coded grey with --encoding h264 (4:0:0: what stereo matching reads, in "
               "fewer bits; the points are grey)")
      ->group(group);
  app.add_flag("--h264-separate-stereo", separate_stereo_,
               "A bitstream per view of a stereo pair with --encoding h264, instead of the right "
               "view interleaved after the left (the measured best)")
      ->group(group);
}

video::FrameEncoderOptions VideoFlags::Options(double fps) const {
  video::FrameEncoderOptions o;
  o.encoder.preset = preset_;
  o.encoder.crf = crf_;
  o.encoder.bitrate_bps = static_cast<std::int64_t>(std::llround(mbps_ * 1e6));
  o.encoder.fps = fps > 0 ? std::max(1, static_cast<int>(std::lround(fps))) : 30;
  o.encoder.keyframe_interval = keyframe_interval_;
  o.encoder.threads = threads_;
  o.colour_kind = colour_444_ ? video::PictureKind::kColour444 : video::PictureKind::kColour;
  o.interleave_stereo = !separate_stereo_;
  o.grey = grey_;
  return o;
}

std::vector<std::string> VideoFlags::GivenFlags() const {
  std::vector<std::string> given;
  for (const char* flag : kFlags) {
    if (app_.count(flag) > 0) given.emplace_back(flag);
  }
  return given;
}

}  // namespace cloudcast::cli
