#include "cloudcast/cli/video_flags.h"

#include <string>
#include <vector>

#include "cloudcast/cli/checks.h"

namespace cloudcast::cli {
namespace {

const char* const kFlags[] = {
    "--h264-preset",  "--h264-crf", "--h264-mbps", "--h264-keyframe-interval",
    "--h264-threads", "--h264-444", "--h264-grey", "--h264-separate-stereo",
    "--h264-lossless", "--h264-x264-params"};

}  // namespace

VideoFlags::VideoFlags(CLI::App& app, const std::string& group) : app_(app) {
  app.add_option("--h264-preset", s_.preset,
                 "x264 preset with --encoding h264 (ultrafast .. medium; docs/video.md measures "
                 "them)")
      ->check(CLI::IsMember(std::vector<std::string>(video::kH264Presets.begin(),
                                                     video::kH264Presets.end())))
      ->capture_default_str()
      ->group(group);
  app.add_option("--h264-crf", s_.crf,
                 "Constant quality with --encoding h264 (1..51, lower is better), capped by "
                 "--h264-mbps; 0: --h264-mbps alone")
      ->check(NumberCheck(video::H264Settings::kCrfRule, video::H264Settings::CrfOk))
      ->capture_default_str()
      ->group(group);
  app.add_option("--h264-mbps", s_.mbps,
                 "Bitrate with --encoding h264, Mbit/s, both views of a pair together: the cap "
                 "of a one-frame VBV (no frame waits behind a large one); with cloudcast-client's "
                 "--rate-control, the most the rate controller's target may give the encoder")
      ->check(NumberCheck(video::H264Settings::kMbpsRule, video::H264Settings::MbpsOk))
      ->capture_default_str()
      ->group(group);
  app.add_option("--h264-keyframe-interval", s_.keyframe_interval,
                 "Frames between IDRs with --encoding h264 (0: only the first and those the "
                 "server asks for)")
      ->check(CLI::Range(0, video::H264Settings::kMaxKeyframeInterval))
      ->capture_default_str()
      ->group(group);
  app.add_option("--h264-threads", s_.threads,
                 "Encoder threads with --encoding h264 (x264 sliced threads: no added latency)")
      ->check(CLI::Range(1, video::H264Settings::kMaxThreads))
      ->capture_default_str()
      ->group(group);
  app.add_flag("--h264-444", s_.colour_444,
               "Colour as 4:4:4 with --encoding h264 (4:2:0 alone caps colour near 28-39 dB "
               "PSNR; docs/video.md)")
      ->group(group);
  app.add_flag("--h264-grey", s_.grey,
               "Images coded grey with --encoding h264 (4:0:0: what stereo matching reads, in "
               "fewer bits; the points are grey)")
      ->group(group);
  app.add_flag("--h264-separate-stereo", s_.separate_stereo,
               "A bitstream per view of a stereo pair with --encoding h264, instead of the right "
               "view interleaved after the left (the measured best)")
      ->group(group);
  app.add_flag("--h264-lossless", s_.lossless,
               "Every picture exactly as given with --encoding h264 (qp 0): for rendered, "
               "noise-free cameras (a simulator's), where it costs less than near-lossless CRFs; "
               "a real camera's noise makes it 40 Mbit/s and more (docs/video.md)")
      ->excludes(app.get_option("--h264-crf"))
      ->excludes(app.get_option("--h264-mbps"))
      ->group(group);
  app.add_option("--h264-x264-params", s_.x264_params,
                 "More x264 options with --encoding h264, key=value:key=value, after ours (e.g. "
                 "partitions=all:ref=4; the latency and rate control options are refused)")
      ->check(CLI::Validator(
          [](std::string& v) -> std::string {
            const std::string why = video::H264Settings::X264ParamsProblem(v);
            return why.empty() ? std::string() : "'" + v + "': " + why;
          },
          "KEY=VALUE:...", ""))
      ->group(group);
}

std::vector<std::string> VideoFlags::GivenFlags() const {
  std::vector<std::string> given;
  for (const char* flag : kFlags) {
    if (app_.count(flag) > 0) given.emplace_back(flag);
  }
  return given;
}

}  // namespace cloudcast::cli
