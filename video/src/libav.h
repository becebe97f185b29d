// What encoder.cc and decoder.cc share of FFmpeg: its error text, and its log routed into the
// error of the call that caused it instead of stderr.
#pragma once

#include <string>

namespace cloudcast::video::internal {

// Installs (once per process) an av_log callback that keeps the last error-level message of each
// thread instead of printing it; libavcodec explains a corrupt slice only there.
void RouteLibavLog();
// The last libav message of this thread since ClearLibavMessage (empty if none).
std::string TakeLibavMessage();
void ClearLibavMessage();
// av_strerror's text for an AVERROR code.
std::string LibavError(int code);

}  // namespace cloudcast::video::internal
