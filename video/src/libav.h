// What encoder.cc, decoder.cc and codecs.cc share of FFmpeg: its error text, its log routed into
// the error of the call that caused it instead of stderr, and our packed pixels' formats.
#pragma once

#include <string>

#include "cloudcast/core/image.h"

extern "C" {
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
// The libav pixel format of a packed image of ours (AV_PIX_FMT_NONE for none).
AVPixelFormat PackedFormat(ColorEncoding e);

}  // namespace cloudcast::video::internal
