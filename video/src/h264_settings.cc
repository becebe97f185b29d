#include "cloudcast/video/h264_settings.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "cloudcast/video/frame_encoder.h"

namespace cloudcast::video {

FrameEncoderOptions ToFrameEncoderOptions(const H264Settings& s, double fps) {
  FrameEncoderOptions o;
  o.encoder.preset = s.preset;
  o.encoder.crf = s.crf;
  o.encoder.bitrate_bps = static_cast<std::int64_t>(std::llround(s.mbps * 1e6));
  o.encoder.fps = fps > 0 ? std::max(1, static_cast<int>(std::lround(fps))) : 30;
  o.encoder.keyframe_interval = s.keyframe_interval;
  o.encoder.threads = s.threads;
  o.colour_kind = s.colour_444 ? PictureKind::kColour444 : PictureKind::kColour;
  o.interleave_stereo = !s.separate_stereo;
  o.grey = s.grey;
  o.encoder.x264_params = s.x264_params;
  if (s.lossless) {  // qp 0; the VBV's bitrate stays, unused (a rate controller's target too)
    o.encoder.qp = 0;
    o.encoder.crf = 0;
  }
  return o;
}

}  // namespace cloudcast::video
