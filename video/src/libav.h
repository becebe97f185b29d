// What encoder.cc, decoder.cc and codecs.cc share of FFmpeg: its error text, its log routed into
// the error of the call that caused it instead of stderr, and a picture's planes.
#pragma once

#include <string>

#include "cloudcast/core/image.h"
#include "yuv.h"

extern "C" {
#include <libavutil/frame.h>
#include <libavutil/pixfmt.h>
}

namespace cloudcast::video::internal {

// Installs (once per process) an av_log callback that keeps the first error-level message and the
// first warning of each thread instead of printing them; libavcodec explains a corrupt slice only
// there, and an x264 option it could not parse only as a warning.
void RouteLibavLog();
// The last libav message of this thread since ClearLibavMessage (empty if none).
std::string TakeLibavMessage();
// The first warning of this thread since ClearLibavMessage (empty if none).
std::string TakeLibavWarning();
void ClearLibavMessage();
// av_strerror's text for an AVERROR code.
std::string LibavError(int code);
// A picture's planes for YuvToPacked and PackedToYuv; false for a format other than 8-bit grey,
// 4:2:0 or 4:4:4 (limited or full range).
bool PlanesOf(const AVFrame& f, YuvPlanes* out);

}  // namespace cloudcast::video::internal
