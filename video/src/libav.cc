#include "libav.h"

#include <cstdarg>
#include <mutex>

extern "C" {
#include <libavutil/error.h>
#include <libavutil/log.h>
}

namespace cloudcast::video::internal {
namespace {

thread_local std::string t_message;
thread_local std::string t_warning;

void Callback(void* avcl, int level, const char* fmt, va_list vl) {
  if (level > AV_LOG_WARNING) return;
  char line[512];
  int print_prefix = 1;
  va_list copy;
  va_copy(copy, vl);
  av_log_format_line2(avcl, level, fmt, copy, line, sizeof(line), &print_prefix);
  va_end(copy);
  std::string text(line);
  while (!text.empty() && (text.back() == '\n' || text.back() == ' ')) text.pop_back();
  if (text.empty()) return;
  // The first message of a failure is the cause; later ones repeat its consequences.
  std::string& slot = level <= AV_LOG_ERROR ? t_message : t_warning;
  if (slot.empty()) slot = std::move(text);
}

}  // namespace

void RouteLibavLog() {
  static std::once_flag once;
  std::call_once(once, [] { av_log_set_callback(Callback); });
}

std::string TakeLibavMessage() {
  std::string m = std::move(t_message);
  t_message.clear();
  return m;
}

std::string TakeLibavWarning() {
  std::string m = std::move(t_warning);
  t_warning.clear();
  return m;
}

void ClearLibavMessage() {
  t_message.clear();
  t_warning.clear();
}

AVPixelFormat PackedFormat(ColorEncoding e) {
  switch (e) {
    case ColorEncoding::kBGR8:
      return AV_PIX_FMT_BGR24;
    case ColorEncoding::kRGB8:
      return AV_PIX_FMT_RGB24;
    case ColorEncoding::kRGBA8:
      return AV_PIX_FMT_RGBA;
    case ColorEncoding::kMono8:
      return AV_PIX_FMT_GRAY8;
  }
  return AV_PIX_FMT_NONE;
}

std::string LibavError(int code) {
  char buf[AV_ERROR_MAX_STRING_SIZE] = {0};
  av_strerror(code, buf, sizeof(buf));
  return buf;
}

}  // namespace cloudcast::video::internal
