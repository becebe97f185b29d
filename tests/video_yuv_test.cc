// The video layer's colour conversions (video/src/yuv.h) against swscale, which they replace on
// the decoders' side and for 4:2:0 pictures: the exact colours within swscale's rounding, every
// packed order, limited and full range; and 4:2:0 pictures closer to the image than swscale's.
// Images: uniform noise (every sample value), a frame of the synthetic scene (saturated edges) and
// one of New Tsukuba (a camera's).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "cloudcast/core/image.h"
#include "cloudcast/datasets/synthetic.h"
#include "opencv2/imgcodecs.hpp"
#include "support/test_support.h"
#include "yuv.h"

extern "C" {
#include <libavutil/log.h>
#include <libavutil/pixfmt.h>
#include <libswscale/swscale.h>
}

namespace cloudcast::video::internal {
namespace {

constexpr int kW = 640, kH = 480;
using Layout = YuvPlanes::Layout;

std::vector<std::uint8_t> SceneBgr() {
  SyntheticOptions o;
  o.width = kW;
  o.height = kH;
  o.frame = 3;
  auto f = SyntheticScene::Default().Render(o);
  EXPECT_TRUE(f.ok()) << f.status();
  return f.ok() ? f->colour : std::vector<std::uint8_t>(std::size_t{kW} * kH * 3);
}

std::vector<std::uint8_t> Noise(std::size_t n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<std::uint8_t> v(n);
  for (auto& b : v) b = static_cast<std::uint8_t>(rng() & 0xff);
  return v;
}

// A planar picture that owns its planes.
struct Picture {
  Layout layout = Layout::k420;
  bool full_range = false;
  std::vector<std::uint8_t> y, u, v;

  Picture(Layout l, bool full) : layout(l), full_range(full) {
    y.resize(std::size_t{kW} * kH);
    const std::size_t chroma = l == Layout::k444 ? y.size() : l == Layout::k420 ? y.size() / 4 : 0;
    u.resize(chroma);
    v.resize(chroma);
  }
  int chroma_stride() const { return layout == Layout::k444 ? kW : kW / 2; }
  YuvPlanes planes() {
    YuvPlanes p;
    p.layout = layout;
    p.full_range = full_range;
    p.y = y.data();
    p.u = u.data();
    p.v = v.data();
    p.y_stride = kW;
    p.u_stride = p.v_stride = chroma_stride();
    return p;
  }
  AVPixelFormat format() const {
    if (layout == Layout::kGrey) return AV_PIX_FMT_GRAY8;
    if (layout == Layout::k444) return full_range ? AV_PIX_FMT_YUVJ444P : AV_PIX_FMT_YUV444P;
    return full_range ? AV_PIX_FMT_YUVJ420P : AV_PIX_FMT_YUV420P;
  }
};

AVPixelFormat Packed(ColorEncoding e) {
  return e == ColorEncoding::kBGR8    ? AV_PIX_FMT_BGR24
         : e == ColorEncoding::kRGB8  ? AV_PIX_FMT_RGB24
         : e == ColorEncoding::kRGBA8 ? AV_PIX_FMT_RGBA
                                      : AV_PIX_FMT_GRAY8;
}

// swscale as the decoders and encoders used it (SWS_BILINEAR, its default matrix and ranges),
// quiet about 'yuvj' formats (their range is what is meant here).
void Sws(AVPixelFormat from, const std::uint8_t* const src[], const int src_strides[],
         AVPixelFormat to, std::uint8_t* const dst[], const int dst_strides[]) {
  av_log_set_level(AV_LOG_ERROR);
  SwsContext* c = sws_getContext(kW, kH, from, kW, kH, to, SWS_BILINEAR, nullptr, nullptr, nullptr);
  ASSERT_NE(c, nullptr);
  sws_scale(c, src, src_strides, 0, kH, dst, dst_strides);
  sws_freeContext(c);
}

std::vector<std::uint8_t> SwsToPacked(Picture& p, ColorEncoding to) {
  std::vector<std::uint8_t> out(std::size_t{kW} * kH * BytesPerPixel(to));
  const std::uint8_t* src[3] = {p.y.data(), p.u.data(), p.v.data()};
  const int strides[3] = {kW, p.chroma_stride(), p.chroma_stride()};
  std::uint8_t* dst[1] = {out.data()};
  const int dst_strides[1] = {kW * static_cast<int>(BytesPerPixel(to))};
  Sws(p.format(), src, strides, Packed(to), dst, dst_strides);
  return out;
}

void SwsFromPacked(const std::vector<std::uint8_t>& image, ColorEncoding from, Picture* p) {
  const std::uint8_t* src[1] = {image.data()};
  const int strides[1] = {kW * static_cast<int>(BytesPerPixel(from))};
  std::uint8_t* dst[3] = {p->y.data(), p->u.data(), p->v.data()};
  const int dst_strides[3] = {kW, p->chroma_stride(), p->chroma_stride()};
  Sws(Packed(from), src, strides, p->format(), dst, dst_strides);
}

std::vector<std::uint8_t> Ours(Picture& p, ColorEncoding to) {
  const int stride = kW * static_cast<int>(BytesPerPixel(to));
  std::vector<std::uint8_t> out(std::size_t{kH} * static_cast<std::size_t>(stride));
  const absl::Status s = YuvToPacked(p.planes(), kW, kH, to, out.data(), stride);
  EXPECT_TRUE(s.ok()) << s;
  return out;
}

int MaxDiff(const std::vector<std::uint8_t>& a, const std::vector<std::uint8_t>& b) {
  EXPECT_EQ(a.size(), b.size());
  int worst = 0;
  for (std::size_t i = 0; i < a.size() && i < b.size(); ++i) {
    worst = std::max(worst, std::abs(static_cast<int>(a[i]) - static_cast<int>(b[i])));
  }
  return worst;
}

double Psnr(const std::vector<std::uint8_t>& a, const std::vector<std::uint8_t>& b) {
  double se = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const double e = static_cast<double>(a[i]) - static_cast<double>(b[i]);
    se += e * e;
  }
  return se == 0 ? 99 : 10 * std::log10(255.0 * 255.0 * static_cast<double>(a.size()) / se);
}

// The same picture in another packed order, from BGR8.
std::vector<std::uint8_t> Reorder(const std::vector<std::uint8_t>& bgr, ColorEncoding to) {
  std::vector<std::uint8_t> out;
  for (std::size_t i = 0; i + 2 < bgr.size(); i += 3) {
    const std::uint8_t b = bgr[i], g = bgr[i + 1], r = bgr[i + 2];
    if (to == ColorEncoding::kBGR8) out.insert(out.end(), {b, g, r});
    if (to == ColorEncoding::kRGB8) out.insert(out.end(), {r, g, b});
    if (to == ColorEncoding::kRGBA8) out.insert(out.end(), {r, g, b, 255});
  }
  return out;
}

constexpr ColorEncoding kColour[] = {ColorEncoding::kBGR8, ColorEncoding::kRGB8,
                                     ColorEncoding::kRGBA8};

// BT.601 in doubles, clamped: the colour a picture's sample stands for.
std::uint8_t Clamp(double v) {
  return static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0, 255.0)));
}
void Exact(int y, int u, int v, bool full, std::uint8_t* bgr) {
  const double l = full ? y : 255.0 / 219.0 * (y - 16);
  const double cb = (u - 128) * (full ? 1.0 : 255.0 / 224.0);
  const double cr = (v - 128) * (full ? 1.0 : 255.0 / 224.0);
  bgr[0] = Clamp(l + 1.772 * cb);
  bgr[1] = Clamp(l - 0.344136 * cb - 0.714136 * cr);
  bgr[2] = Clamp(l + 1.402 * cr);
}

// The largest difference between a packed image and the exact colours of a picture's samples,
// over the pixels `count` picks (the channels in `to`'s order; alpha must be opaque).
template <typename Pick>
int WorstAgainstExact(Picture& p, const std::vector<std::uint8_t>& image, ColorEncoding to,
                      Pick count) {
  const int bpp = static_cast<int>(BytesPerPixel(to));
  const int shift = p.layout == Layout::k420 ? 1 : 0;
  int worst = 0;
  for (int row = 0; row < kH; ++row) {
    for (int col = 0; col < kW; ++col) {
      if (!count(row, col)) continue;
      const std::size_t c =
          static_cast<std::size_t>(row >> shift) * static_cast<std::size_t>(p.chroma_stride()) +
          static_cast<std::size_t>(col >> shift);
      std::uint8_t bgr[3];
      Exact(p.y[static_cast<std::size_t>(row) * kW + static_cast<std::size_t>(col)], p.u[c], p.v[c],
            p.full_range, bgr);
      const std::uint8_t* got =
          &image[(static_cast<std::size_t>(row) * kW + static_cast<std::size_t>(col)) *
                 static_cast<std::size_t>(bpp)];
      const bool red_first = to != ColorEncoding::kBGR8;
      for (int k = 0; k < 3; ++k) {
        worst = std::max(worst, std::abs(int{got[k]} - int{bgr[red_first ? 2 - k : k]}));
      }
      if (bpp == 4) worst = std::max(worst, 255 - int{got[3]});
    }
  }
  return worst;
}

// The decoders' way, on uniform noise (every sample value, colours out of gamut included): every
// layout and range in every packed order within three levels of the exact colours (libyuv rounds
// its coefficients to 6 bits; swscale's worst is as large) and never further than swscale's, and
// the luma itself for Mono8. swscale's 4:4:4 path, which this
// replaces, wraps some out-of-gamut blues to 0 (printed: a worst of 255). 4:2:0 chroma is
// interpolated between samples, so there the noise is in the luma and each chroma sample is
// repeated over 8x8 samples, and the pixels checked are those whose neighbours share its chroma.
TEST(VideoYuv, DecodedPicturesHaveTheirSamplesColours) {
  for (const Layout layout : {Layout::k420, Layout::k444}) {
    for (const bool full : {false, true}) {
      Picture p(layout, full);
      p.y = Noise(p.y.size(), 1);
      p.u = Noise(p.u.size(), 2);
      p.v = Noise(p.v.size(), 3);
      const int cw = p.chroma_stride();
      auto interior = [&](int row, int col) {
        if (layout == Layout::k444) return true;
        const int r = (row >> 1) % 8, c = (col >> 1) % 8;  // inside its 8x8 block of samples
        return r >= 1 && r <= 6 && c >= 1 && c <= 6;
      };
      if (layout == Layout::k420) {
        for (std::size_t i = 0; i < p.u.size(); ++i) {
          const std::size_t r = i / static_cast<std::size_t>(cw),
                            c = i % static_cast<std::size_t>(cw);
          const std::size_t first = (r / 8 * 8) * static_cast<std::size_t>(cw) + c / 8 * 8;
          p.u[i] = p.u[first];
          p.v[i] = p.v[first];
        }
      }
      for (const ColorEncoding to : kColour) {
        const int ours = WorstAgainstExact(p, Ours(p, to), to, interior);
        const int swscale = WorstAgainstExact(p, SwsToPacked(p, to), to, interior);
        std::printf("%s%s to %s: worst against the exact colours %d (swscale %d)\n",
                    layout == Layout::k444 ? "4:4:4" : "4:2:0", full ? " full range" : "",
                    std::string(Name(to)).c_str(), ours, swscale);
        SCOPED_TRACE(::testing::Message() << (layout == Layout::k444 ? "4:4:4" : "4:2:0")
                                          << (full ? " full range" : "") << " to " << Name(to));
        EXPECT_LE(ours, 3);
        EXPECT_LE(ours, swscale);
      }
      EXPECT_EQ(Ours(p, ColorEncoding::kMono8), p.y);
    }
  }
}

// A grey picture is full range, as swscale reads it: r = g = b = y, alpha opaque.
TEST(VideoYuv, GreyPicturesAreTheirLuma) {
  Picture p(Layout::kGrey, true);
  p.y = Noise(p.y.size(), 4);
  for (const ColorEncoding to : kColour) {
    EXPECT_EQ(Ours(p, to), SwsToPacked(p, to)) << Name(to);
  }
  EXPECT_EQ(Ours(p, ColorEncoding::kMono8), p.y);
}

// RGB to 4:2:0 and back, ours both ways and swscale's both ways: each one's PSNR against `bgr`.
struct RoundTrip {
  double ours = 0, swscale = 0;
};
RoundTrip Through420(const std::vector<std::uint8_t>& bgr) {
  Picture p(Layout::k420, false), reference(Layout::k420, false);
  PackedToYuv to_yuv;
  EXPECT_TRUE(to_yuv.Convert(bgr.data(), kW * 3, ColorEncoding::kBGR8, kW, kH, p.planes()).ok());
  SwsFromPacked(bgr, ColorEncoding::kBGR8, &reference);
  return {Psnr(bgr, Ours(p, ColorEncoding::kBGR8)),
          Psnr(bgr, SwsToPacked(reference, ColorEncoding::kBGR8))};
}

// The encoders' way to 4:4:4 and 4:2:0 against swscale's: 4:4:4 (ours) within a level of
// swscale's in every sample, 4:2:0 (libyuv's) in the luma. Every packed order makes the same
// picture.
TEST(VideoYuv, EncodedPicturesMatchSwscale) {
  const std::vector<std::uint8_t> scene = SceneBgr();
  for (const Layout layout : {Layout::k444, Layout::k420}) {
    Picture reference(layout, false);
    SwsFromPacked(scene, ColorEncoding::kBGR8, &reference);
    PackedToYuv to_yuv;
    for (const ColorEncoding from : kColour) {
      Picture p(layout, false);
      const std::vector<std::uint8_t> image = Reorder(scene, from);
      ASSERT_TRUE(to_yuv
                      .Convert(image.data(), kW * static_cast<int>(BytesPerPixel(from)), from, kW,
                               kH, p.planes())
                      .ok());
      SCOPED_TRACE(::testing::Message()
                   << (layout == Layout::k444 ? "4:4:4" : "4:2:0") << " from " << Name(from));
      EXPECT_LE(MaxDiff(p.y, reference.y), 1);
      if (layout == Layout::k444) {
        EXPECT_LE(MaxDiff(p.u, reference.u), 1);
        EXPECT_LE(MaxDiff(p.v, reference.v), 1);
      }
    }
  }
}

// BT.601 limited range in doubles: the Y, Cb, Cr an RGB colour stands for, unrounded.
void ExactYuv(int r, int g, int b, double* yuv) {
  const double l = 0.299 * r + 0.587 * g + 0.114 * b;
  yuv[0] = 16 + 219.0 / 255.0 * l;
  yuv[1] = 128 + 224.0 / 255.0 * (b - l) / 1.772;
  yuv[2] = 128 + 224.0 / 255.0 * (r - l) / 1.402;
}

// The encoders' 4:4:4 pictures are the exact colours rounded: a sample may be the neighbour only
// where the exact value is within 1/85 of a level of the half between them (the coefficients'
// rounding), which uniform noise meets in about a quarter of a percent of its samples. Uniform
// noise (every colour), each packed order, Mono8 too (r = g = b, neutral chroma), and widths that
// leave a tail after the 16-sample steps, with padded rows.
TEST(VideoYuv, FourFourFourPicturesAreTheExactColoursRounded) {
  PackedToYuv to_yuv;
  for (const int width : {kW, 37, 5}) {
    constexpr int kRows = 24;
    for (const ColorEncoding from : {ColorEncoding::kBGR8, ColorEncoding::kRGB8,
                                     ColorEncoding::kRGBA8, ColorEncoding::kMono8}) {
      const int bpp = static_cast<int>(BytesPerPixel(from));
      const int src_stride = width * bpp + 7, dst_stride = width + 3;
      const std::vector<std::uint8_t> image = Noise(static_cast<std::size_t>(src_stride) * kRows,
                                                    11 + static_cast<std::uint32_t>(width));
      std::vector<std::uint8_t> y(static_cast<std::size_t>(dst_stride) * kRows), u(y.size()),
          v(y.size());
      YuvPlanes planes;
      planes.layout = Layout::k444;
      planes.y = y.data();
      planes.u = u.data();
      planes.v = v.data();
      planes.y_stride = planes.u_stride = planes.v_stride = dst_stride;
      ASSERT_TRUE(to_yuv.Convert(image.data(), src_stride, from, width, kRows, planes).ok());
      SCOPED_TRACE(::testing::Message() << "from " << Name(from) << ", width " << width);
      int off = 0;
      for (int row = 0; row < kRows; ++row) {
        for (int col = 0; col < width; ++col) {
          const std::uint8_t* px = &image[static_cast<std::size_t>(row) * src_stride +
                                          static_cast<std::size_t>(col) * bpp];
          int r = px[0], g = px[0], b = px[0];
          if (from != ColorEncoding::kMono8) g = px[1], b = px[2];
          if (from == ColorEncoding::kBGR8) std::swap(r, b);
          double exact[3];
          ExactYuv(r, g, b, exact);
          const std::size_t at = static_cast<std::size_t>(row) * dst_stride + col;
          const std::uint8_t got[3] = {y[at], u[at], v[at]};
          for (int k = 0; k < 3; ++k) {
            if (got[k] == std::lround(exact[k])) continue;
            ++off;
            ASSERT_LE(std::abs(got[k] - exact[k]), 0.5 + 1.0 / 85)
                << "row " << row << ", column " << col << ", plane " << k << ": " << int{got[k]}
                << " for " << exact[k];
          }
          if (from == ColorEncoding::kMono8) {
            ASSERT_EQ(u[at], 128);
            ASSERT_EQ(v[at], 128);
          }
        }
      }
      EXPECT_LE(off, width * kRows * 3 / 100 + 2) << "samples off the exact colour rounded";
    }
  }
}

// 4:2:0 there and back keeps an image better than swscale did both ways: on the synthetic scene,
// whose colour changes pixel to pixel (4:2:0's own ceiling there is near 31 dB), a little; on a
// camera's image (New Tsukuba's first frame), by 5 dB (44.5 against 39.3).
TEST(VideoYuv, FourTwoZeroKeepsTheImageBetterThanSwscale) {
  const RoundTrip scene = Through420(SceneBgr());
  std::printf("4:2:0 round trip, synthetic scene: %.2f dB (swscale both ways %.2f dB)\n",
              scene.ours, scene.swscale);
  EXPECT_GT(scene.ours, scene.swscale);
  CLOUDCAST_REQUIRE_TSUKUBA();
  const std::string path =
      ::cloudcast::testing::TsukubaColourPath(::cloudcast::testing::TsukubaFrameIds().front());
  const cv::Mat image = cv::imread(path, cv::IMREAD_COLOR);
  ASSERT_EQ(image.cols, kW) << path;
  ASSERT_EQ(image.rows, kH) << path;
  ASSERT_TRUE(image.isContinuous());
  const std::vector<std::uint8_t> bgr(image.data, image.data + image.total() * 3);
  const RoundTrip tsukuba = Through420(bgr);
  std::printf("4:2:0 round trip, New Tsukuba: %.2f dB (swscale both ways %.2f dB)\n", tsukuba.ours,
              tsukuba.swscale);
  EXPECT_GT(tsukuba.ours, tsukuba.swscale + 3.0);
}

// A grey image into a colour picture: luma at limited range (16 + 219/255 of the grey, as
// swscale's), chroma neutral.
TEST(VideoYuv, GreyImagesMakeNeutralColourPictures) {
  const std::vector<std::uint8_t> grey = Noise(std::size_t{kW} * kH, 5);
  PackedToYuv to_yuv;
  for (const Layout layout : {Layout::k420, Layout::k444}) {
    Picture p(layout, false), reference(layout, false);
    ASSERT_TRUE(to_yuv.Convert(grey.data(), kW, ColorEncoding::kMono8, kW, kH, p.planes()).ok());
    SwsFromPacked(grey, ColorEncoding::kMono8, &reference);
    EXPECT_LE(MaxDiff(p.y, reference.y), 1);
    for (const std::uint8_t c : p.u) ASSERT_EQ(c, 128);
    for (const std::uint8_t c : p.v) ASSERT_EQ(c, 128);
  }
}

// What the converter refuses: it makes limited-range colour pictures only.
TEST(VideoYuv, PackedToYuvRefusesGreyAndFullRangePictures) {
  const std::vector<std::uint8_t> scene = SceneBgr();
  PackedToYuv to_yuv;
  Picture grey(Layout::kGrey, true), full(Layout::k420, true);
  EXPECT_FALSE(
      to_yuv.Convert(scene.data(), kW * 3, ColorEncoding::kBGR8, kW, kH, grey.planes()).ok());
  EXPECT_FALSE(
      to_yuv.Convert(scene.data(), kW * 3, ColorEncoding::kBGR8, kW, kH, full.planes()).ok());
}

}  // namespace
}  // namespace cloudcast::video::internal
