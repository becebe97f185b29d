// What encoder.cc and decoder.cc share of FFmpeg: its error text, and its log routed into the
// error of the call that caused it instead of stderr.
#pragma once

#include <string>

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

}  // namespace cloudcast::video::internal
