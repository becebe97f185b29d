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

bool PlanesOf(const AVFrame& f, YuvPlanes* out) {
  using Layout = YuvPlanes::Layout;
  YuvPlanes p;
  switch (static_cast<AVPixelFormat>(f.format)) {
    case AV_PIX_FMT_GRAY8:
      p.layout = Layout::kGrey;
      p.full_range = true;
      break;
    case AV_PIX_FMT_YUVJ420P:
      p.full_range = true;
      [[fallthrough]];
    case AV_PIX_FMT_YUV420P:
      p.layout = Layout::k420;
      break;
    case AV_PIX_FMT_YUVJ444P:
      p.full_range = true;
      [[fallthrough]];
    case AV_PIX_FMT_YUV444P:
      p.layout = Layout::k444;
      break;
    default:
      return false;
  }
  // A picture tagged full range by its colour properties rather than a 'yuvj' format is too.
  p.full_range |= f.color_range == AVCOL_RANGE_JPEG;
  p.y = f.data[0];
  p.y_stride = f.linesize[0];
  if (p.layout != Layout::kGrey) {
    p.u = f.data[1];
    p.v = f.data[2];
    p.u_stride = f.linesize[1];
    p.v_stride = f.linesize[2];
  }
  *out = p;
  return true;
}

std::string LibavError(int code) {
  char buf[AV_ERROR_MAX_STRING_SIZE] = {0};
  av_strerror(code, buf, sizeof(buf));
  return buf;
}

}  // namespace cloudcast::video::internal
