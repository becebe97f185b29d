#include "yuv.h"

#include <cstring>

#include "libyuv/convert.h"
#include "libyuv/convert_argb.h"
#include "libyuv/convert_from_argb.h"
#include "libyuv/scale.h"

extern "C" {
#include <libavutil/pixfmt.h>
#include <libswscale/swscale.h>
}

namespace cloudcast::video::internal {
namespace {

using Layout = YuvPlanes::Layout;

// libyuv names packed formats by their order in a little-endian word: its RGB24 is our BGR8 (B,
// G, R in memory), RAW our RGB8, ABGR our RGBA8, and ARGB is B, G, R, A in memory.

// swscale's name of a packed image of ours.
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

void CopyPlane(const std::uint8_t* src, int src_stride, std::uint8_t* dst, int dst_stride,
               int width, int height) {
  for (int v = 0; v < height; ++v) {
    std::memcpy(dst + static_cast<std::ptrdiff_t>(v) * dst_stride,
                src + static_cast<std::ptrdiff_t>(v) * src_stride, static_cast<std::size_t>(width));
  }
}

}  // namespace

PackedToYuv::~PackedToYuv() { sws_freeContext(sws_); }

absl::Status PackedToYuv::Convert(const std::uint8_t* src, int src_stride, ColorEncoding from,
                                  int width, int height, const YuvPlanes& dst) {
  const YuvPlanes& d = dst;
  if (d.layout == Layout::kGrey || d.full_range) {
    return absl::InternalError("PackedToYuv makes limited-range 4:2:0 or 4:4:4 pictures only");
  }
  if (d.layout == Layout::k444) {  // swscale's: see yuv.h
    sws_ = sws_getCachedContext(sws_, width, height, PackedFormat(from), width, height,
                                AV_PIX_FMT_YUV444P, SWS_BILINEAR, nullptr, nullptr, nullptr);
    if (sws_ == nullptr) return absl::InternalError("swscale cannot convert to YUV");
    const std::uint8_t* planes[1] = {src};
    const int strides[1] = {src_stride};
    std::uint8_t* out[3] = {d.y, d.u, d.v};
    const int out_strides[3] = {d.y_stride, d.u_stride, d.v_stride};
    sws_scale(sws_, planes, strides, 0, height, out, out_strides);
    return absl::OkStatus();
  }
  int rc = -1;
  switch (from) {
    case ColorEncoding::kBGR8:
      rc = libyuv::RGB24ToI420(src, src_stride, d.y, d.y_stride, d.u, d.u_stride, d.v, d.v_stride,
                               width, height);
      break;
    case ColorEncoding::kRGB8:
      rc = libyuv::RAWToI420(src, src_stride, d.y, d.y_stride, d.u, d.u_stride, d.v, d.v_stride,
                             width, height);
      break;
    case ColorEncoding::kRGBA8:
      rc = libyuv::ABGRToI420(src, src_stride, d.y, d.y_stride, d.u, d.u_stride, d.v, d.v_stride,
                              width, height);
      break;
    case ColorEncoding::kMono8: {  // full range, as swscale reads grey: r = g = b = y
      scratch_.resize(static_cast<std::size_t>(width) * 4 * static_cast<std::size_t>(height));
      rc = libyuv::J400ToARGB(src, src_stride, scratch_.data(), width * 4, width, height);
      if (rc == 0) {
        rc = libyuv::ARGBToI420(scratch_.data(), width * 4, d.y, d.y_stride, d.u, d.u_stride, d.v,
                                d.v_stride, width, height);
      }
      break;
    }
  }
  if (rc != 0) return absl::InternalError("libyuv cannot convert the image to YUV");
  return absl::OkStatus();
}

absl::Status YuvToPacked(const YuvPlanes& src, int width, int height, ColorEncoding to,
                         std::uint8_t* dst, int dst_stride) {
  const YuvPlanes& s = src;
  if (to == ColorEncoding::kMono8) {
    CopyPlane(s.y, s.y_stride, dst, dst_stride, width, height);
    return absl::OkStatus();
  }
  if (s.layout == Layout::kGrey) {  // full range: r = g = b = y
    for (int v = 0; v < height; ++v) {
      const std::uint8_t* in = s.y + static_cast<std::ptrdiff_t>(v) * s.y_stride;
      std::uint8_t* out = dst + static_cast<std::ptrdiff_t>(v) * dst_stride;
      if (to == ColorEncoding::kRGBA8) {
        for (int x = 0; x < width; ++x, out += 4) out[0] = out[1] = out[2] = in[x], out[3] = 255;
      } else {
        for (int x = 0; x < width; ++x, out += 3) out[0] = out[1] = out[2] = in[x];
      }
    }
    return absl::OkStatus();
  }
  // Our RGB8 and RGBA8 put red first, libyuv's RGB24 and ARGB blue: the same conversion with U
  // and V swapped and the matrix mirrored (libyuv's own way to its RAW and ABGR).
  const bool red_first = to != ColorEncoding::kBGR8;
  const libyuv::YuvConstants* m =
      s.full_range ? (red_first ? &libyuv::kYvuJPEGConstants : &libyuv::kYuvJPEGConstants)
                   : (red_first ? &libyuv::kYvuI601Constants : &libyuv::kYuvI601Constants);
  const std::uint8_t* u = red_first ? s.v : s.u;
  const std::uint8_t* v = red_first ? s.u : s.v;
  const int us = red_first ? s.v_stride : s.u_stride;
  const int vs = red_first ? s.u_stride : s.v_stride;
  const bool four = to == ColorEncoding::kRGBA8;
  int rc;
  if (s.layout == Layout::k444) {
    rc = four ? libyuv::I444ToARGBMatrix(s.y, s.y_stride, u, us, v, vs, dst, dst_stride, m, width,
                                         height)
              : libyuv::I444ToRGB24Matrix(s.y, s.y_stride, u, us, v, vs, dst, dst_stride, m, width,
                                          height);
  } else {  // chroma interpolated, as swscale's was: 0.3 dB closer than repeated, for 0.05 ms
    rc = four ? libyuv::I420ToARGBMatrixFilter(s.y, s.y_stride, u, us, v, vs, dst, dst_stride, m,
                                               width, height, libyuv::kFilterBilinear)
              : libyuv::I420ToRGB24MatrixFilter(s.y, s.y_stride, u, us, v, vs, dst, dst_stride, m,
                                                width, height, libyuv::kFilterBilinear);
  }
  if (rc != 0) return absl::InternalError("libyuv cannot convert the picture");
  return absl::OkStatus();
}

}  // namespace cloudcast::video::internal
