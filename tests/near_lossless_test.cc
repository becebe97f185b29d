// Near-lossless disparity and depth (issue 27 item 5, core/near_lossless.h): on every New
// Tsukuba frame, in every disparity and depth encoding, at several bounds, each valid pixel's
// point (as the server's own conversion makes it) stays within the bound of the lossless one,
// invalid pixels stay invalid and valid ones valid; the quantized planes compress smaller; bad
// arguments are refused naming them.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <random>
#include <variant>
#include <string>
#include <vector>

#include "cloudcast/client/near_lossless.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/core/filters.h"
#include "cloudcast/core/frame_codec.h"
#include "cloudcast/core/near_lossless.h"
#include "cloudcast/core/settings.h"
#include "cloudcast/datasets/tsukuba.h"
#include "support/test_support.h"

namespace cloudcast {
namespace {

constexpr double kBounds[] = {0.001, 0.005, 0.01, 0.02};

// Packed rows of one encoding, with the camera that reads them.
template <typename Encoding>
struct Plane {
  std::string name;
  std::vector<std::uint8_t> bytes;
  std::uint32_t width = 0, height = 0;
  Encoding encoding{};
  CameraModel camera;
  ImageView<Encoding> view() const {
    const std::size_t stride = std::size_t{width} * BytesPerPixel(encoding);
    return ImageView<Encoding>{bytes.data(), bytes.size(), width, height, stride, encoding};
  }
};

template <typename T, typename Encoding>
Plane<Encoding> MakePlane(std::string name, std::uint32_t w, std::uint32_t h, Encoding e,
                          const CameraModel& camera, const std::vector<T>& values) {
  Plane<Encoding> p{std::move(name), {}, w, h, e, camera};
  p.bytes.resize(values.size() * sizeof(T));
  std::memcpy(p.bytes.data(), values.data(), p.bytes.size());
  return p;
}

// The New Tsukuba camera as the server resolves it for a 640x480 frame (the preset: z = 615 / d).
CameraModel TsukubaCamera() {
  FrameSettings settings;
  EXPECT_TRUE(ApplyPreset("new_tsukuba", &settings, "preset", false).ok());
  return settings.PipelineFor(640, 480).camera;
}

// A smooth sub-pixel part for the 8-bit truth (a matcher's output has one), in [0, 1).
double Fraction(std::uint32_t u, std::uint32_t v) {
  return 0.5 + 0.5 * std::sin(0.05 * u + 0.03 * v) * std::cos(0.02 * v);
}

// One frame's truth in the five geometry inputs: U8 disparity as it is; U16 disparity in 1/16 px
// and F32 disparity with a sub-pixel part; U16 depth in millimetres and F32 depth in metres
// (z = 615 / d, 0 where the truth has none).
struct Inputs {
  std::vector<Plane<DisparityEncoding>> disparities;
  std::vector<Plane<DepthEncoding>> depths;
};
Inputs FromTruth(const tsukuba::Frame& frame) {
  const CameraModel camera = TsukubaCamera();
  const std::uint32_t w = frame.disparity.width, h = frame.disparity.height;
  const std::uint8_t* d = frame.disparity.pixels.data();
  std::vector<std::uint16_t> d16(std::size_t{w} * h), z16(d16.size());
  std::vector<float> df(d16.size()), zf(d16.size());
  for (std::uint32_t v = 0; v < h; ++v) {
    for (std::uint32_t u = 0; u < w; ++u) {
      const std::size_t i = std::size_t{v} * w + u;
      const double disp = d[i] == 0 ? 0.0 : d[i] + Fraction(u, v);
      d16[i] = static_cast<std::uint16_t>(std::lround(disp * 16));
      df[i] = static_cast<float>(disp);
      const double z = disp == 0 ? 0.0 : camera.fx * camera.baseline / disp;
      z16[i] = static_cast<std::uint16_t>(std::lround(z * 1000));
      zf[i] = static_cast<float>(z);
    }
  }
  CameraModel c16 = camera;
  c16.disparity_scale = 1.0 / 16;
  c16.invalid_disparities = {0.0};
  Inputs in;
  in.disparities.push_back(
      MakePlane("u8 disparity", w, h, DisparityEncoding::kU8, camera,
                std::vector<std::uint8_t>(d, d + std::size_t{w} * h)));
  in.disparities.push_back(MakePlane("u16 disparity", w, h, DisparityEncoding::kU16, c16, d16));
  in.disparities.push_back(MakePlane("f32 disparity", w, h, DisparityEncoding::kF32, camera, df));
  in.depths.push_back(MakePlane("u16 depth", w, h, DepthEncoding::kU16, camera, z16));
  in.depths.push_back(MakePlane("f32 depth", w, h, DepthEncoding::kF32, camera, zf));
  return in;
}

// The server's conversion of `plane` as it is and as quantized: every pixel keeps its validity,
// and every valid point moves by at most `bound`. Returns how many points moved.
template <typename Encoding>
std::size_t ExpectWithinBound(const Plane<Encoding>& plane, const ImageView<Encoding>& quantized,
                              double bound, const std::string& what) {
  std::vector<std::uint8_t> grey(std::size_t{plane.width} * plane.height, 128);
  const ColorView colour{grey.data(), grey.size(), plane.width, plane.height, plane.width,
                         ColorEncoding::kMono8};
  PointCloud lossless, near;
  EXPECT_TRUE(ConvertToOrganized(plane.camera, plane.view(), colour, &lossless).ok()) << what;
  EXPECT_TRUE(ConvertToOrganized(plane.camera, quantized, colour, &near).ok()) << what;
  EXPECT_EQ(lossless.size(), near.size()) << what;
  std::size_t moved = 0, bad_validity = 0, over = 0, valid = 0;
  double worst = 0;
  for (std::size_t i = 0; i < lossless.size() && i < near.size(); ++i) {
    const Point& a = lossless.points[i];
    const Point& b = near.points[i];
    const bool va = std::isfinite(a.z), vb = std::isfinite(b.z);
    if (va != vb) {
      ++bad_validity;
      continue;
    }
    if (!va) continue;
    ++valid;
    const double dx = double{a.x} - b.x, dy = double{a.y} - b.y, dz = double{a.z} - b.z;
    const double e = std::sqrt(dx * dx + dy * dy + dz * dz);
    worst = std::max(worst, e);
    if (e > bound) ++over;
    if (e > 0) ++moved;
  }
  EXPECT_EQ(bad_validity, 0u) << what << ": pixels whose validity changed";
  EXPECT_EQ(over, 0u) << what << ": points moved more than " << bound << " (worst " << worst
                      << ")";
  EXPECT_GT(valid, 0u) << what;
  return moved;
}

std::size_t Compressed(const void* data, std::size_t stride, const PlaneLayout& layout) {
  PlaneCompressor compressor;
  std::string out;
  EXPECT_TRUE(compressor
                  .Compress(data, stride, layout, Predictor::kUp, kDefaultCompressionLevel, &out)
                  .ok());
  return out.size();
}

TEST(NearLossless, EveryTsukubaFrameEveryEncodingWithinEachBound) {
  CLOUDCAST_REQUIRE_TSUKUBA();
  absl::StatusOr<std::vector<tsukuba::Frame>> frames = tsukuba::LoadAll(testing::TsukubaDir());
  ASSERT_TRUE(frames.ok()) << frames.status();
  ASSERT_GE(frames->size(), 1u);
  PointErrorQuantizer quantizer;
  // Bytes after row deltas + zstd, summed over the frames, per input and bound.
  std::map<std::string, std::size_t> lossless_bytes, near_bytes_5mm;
  std::map<std::string, std::size_t> moved_5mm;
  for (const tsukuba::Frame& frame : *frames) {
    const Inputs in = FromTruth(frame);
    for (const auto& plane : in.disparities) {
      lossless_bytes[plane.name] += Compressed(plane.bytes.data(), plane.view().stride_bytes,
                                               LayoutOf(plane.view()));
      for (double bound : kBounds) {
        const std::string what = frame.id + " " + plane.name + " at " + std::to_string(bound);
        DisparityView q;
        ASSERT_TRUE(quantizer.Quantize(plane.view(), plane.camera, bound, "disparity", &q).ok());
        const std::size_t moved = ExpectWithinBound(plane, q, bound, what);
        if (bound == 0.005) {
          near_bytes_5mm[plane.name] += Compressed(q.data, q.stride_bytes, LayoutOf(q));
          moved_5mm[plane.name] += moved;
        }
      }
    }
    for (const auto& plane : in.depths) {
      lossless_bytes[plane.name] += Compressed(plane.bytes.data(), plane.view().stride_bytes,
                                               LayoutOf(plane.view()));
      for (double bound : kBounds) {
        const std::string what = frame.id + " " + plane.name + " at " + std::to_string(bound);
        DepthView q;
        ASSERT_TRUE(quantizer.Quantize(plane.view(), plane.camera, bound, "depth", &q).ok());
        const std::size_t moved = ExpectWithinBound(plane, q, bound, what);
        if (bound == 0.005) {
          near_bytes_5mm[plane.name] += Compressed(q.data, q.stride_bytes, LayoutOf(q));
          moved_5mm[plane.name] += moved;
        }
      }
    }
  }
  // Whole pixels of disparity at z = 615 / d move points by centimetres: the 8-bit truth has no
  // value to spare at a 5 mm bound, and stays lossless.
  EXPECT_EQ(moved_5mm["u8 disparity"], 0u);
  EXPECT_EQ(near_bytes_5mm["u8 disparity"], lossless_bytes["u8 disparity"]);
  // Sub-pixel disparities and depths have values to spare: fewer bytes.
  for (const char* name : {"u16 disparity", "f32 disparity", "u16 depth", "f32 depth"}) {
    EXPECT_GT(moved_5mm[name], 0u) << name;
    EXPECT_LT(near_bytes_5mm[name], lossless_bytes[name]) << name;
  }
}

// Random planes with holes, the camera's other invalid values, non-finite floats, an offset
// and a scale: validity kept, bound kept.
TEST(NearLossless, RandomPlanesKeepValidityAndBound) {
  std::mt19937 rng(27);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  PointErrorQuantizer quantizer;
  for (int round = 0; round < 6; ++round) {
    const std::uint32_t w = 64 + rng() % 32, h = 48 + rng() % 16;
    CameraModel camera;
    camera.fx = 300 + 400 * unit(rng);
    camera.fy = camera.fx * (0.9 + 0.2 * unit(rng));
    camera.cx = w * unit(rng);
    camera.cy = h * unit(rng);
    camera.baseline = 0.05 + 0.5 * unit(rng);
    camera.disparity_scale = round % 2 == 0 ? 1.0 / 16 : 1.0 / 8;
    camera.disparity_offset = round % 3 == 0 ? 2.5 : 0.0;
    camera.invalid_disparities = {0.0, 2047.0};
    std::vector<std::uint16_t> d16(std::size_t{w} * h), z16(d16.size());
    std::vector<float> df(d16.size()), zf(d16.size());
    for (std::size_t i = 0; i < d16.size(); ++i) {
      const double r = unit(rng);
      const double smooth = 200 + 1500 * std::sin(0.01 * i) * std::sin(0.01 * i);
      d16[i] = r < 0.05 ? 0 : r < 0.08 ? 2047 : static_cast<std::uint16_t>(smooth);
      z16[i] = r < 0.05 ? 0 : static_cast<std::uint16_t>(smooth * 5);
      df[i] = r < 0.03   ? 0.0f
              : r < 0.05 ? std::numeric_limits<float>::quiet_NaN()
              : r < 0.07 ? std::numeric_limits<float>::infinity()
                         : static_cast<float>(smooth / 16);
      zf[i] = r < 0.03   ? 0.0f
              : r < 0.05 ? std::numeric_limits<float>::quiet_NaN()
                         : static_cast<float>(smooth / 300);
    }
    const std::vector<Plane<DisparityEncoding>> disparities = {
        MakePlane("u16 disparity", w, h, DisparityEncoding::kU16, camera, d16),
        MakePlane("f32 disparity", w, h, DisparityEncoding::kF32, camera, df)};
    const std::vector<Plane<DepthEncoding>> depths = {
        MakePlane("u16 depth", w, h, DepthEncoding::kU16, camera, z16),
        MakePlane("f32 depth", w, h, DepthEncoding::kF32, camera, zf)};
    for (double bound : kBounds) {
      for (const auto& plane : disparities) {
        DisparityView q;
        ASSERT_TRUE(quantizer.Quantize(plane.view(), camera, bound, "disparity", &q).ok());
        ExpectWithinBound(plane, q, bound, plane.name + " round " + std::to_string(round));
      }
      for (const auto& plane : depths) {
        DepthView q;
        ASSERT_TRUE(quantizer.Quantize(plane.view(), camera, bound, "depth", &q).ok());
        ExpectWithinBound(plane, q, bound, plane.name + " round " + std::to_string(round));
      }
    }
  }
}

TEST(NearLossless, ZeroBoundIsLossless) {
  std::vector<float> values(40 * 30);
  for (std::size_t i = 0; i < values.size(); ++i) values[i] = 1.0f + 0.37f * (i % 17);
  CameraModel camera;
  const auto plane = MakePlane("f32", 40, 30, DepthEncoding::kF32, camera, values);
  PointErrorQuantizer quantizer;
  DepthView q;
  ASSERT_TRUE(quantizer.Quantize(plane.view(), camera, 0.0, "depth", &q).ok());
  ASSERT_EQ(q.size_bytes, plane.bytes.size());
  EXPECT_EQ(std::memcmp(q.data, plane.bytes.data(), plane.bytes.size()), 0);
  EXPECT_EQ(quantizer.stats().changed, 0u);
}

TEST(NearLossless, RoundestInRangeHasTheMostTrailingZeros) {
  auto zeros = [](std::uint32_t x) { return x == 0 ? 32 : __builtin_ctz(x); };
  for (std::uint32_t lo = 0; lo < 300; ++lo) {
    for (std::uint32_t hi = lo; hi < 300; ++hi) {
      const std::uint32_t r = RoundestInRange(lo, hi);
      ASSERT_GE(r, lo);
      ASSERT_LE(r, hi);
      for (std::uint32_t x = lo; x <= hi; ++x) ASSERT_LE(zeros(x), zeros(r)) << lo << " " << hi;
    }
  }
  EXPECT_EQ(RoundestInRange(0xFFFFFFFEu, 0xFFFFFFFFu), 0xFFFFFFFEu);
  EXPECT_EQ(RoundestInRange(1u, 0xFFFFFFFFu), 0x80000000u);
}

// The client library's form: a frame's raw or Compressed disparity or depth replaced by the
// quantized pixels of the same kind (the compression kept), colour untouched, encoded inputs
// refused naming the image, stereo pairs as they are.
TEST(NearLossless, ClientFramesKeepTheirKind) {
  std::vector<float> depth(64 * 48);
  for (std::size_t i = 0; i < depth.size(); ++i) depth[i] = 2.0f + 0.001237f * (i % 97);
  std::vector<std::uint8_t> grey(64 * 48, 7);
  CameraModel camera;
  camera.cx = 32;
  camera.cy = 24;
  const auto plane = MakePlane("f32", 64, 48, DepthEncoding::kF32, camera, depth);
  const ColorView colour{grey.data(), grey.size(), 64, 48, 64, ColorEncoding::kMono8};
  PointErrorQuantizer quantizer;
  convert::Compression compression;
  compression.level = 3;
  client::FrameInput compressed =
      client::DepthFrame{client::Compressed(plane.view(), compression), colour};
  absl::StatusOr<client::FrameInput> near =
      client::NearLossless(compressed, camera, 0.01, &quantizer);
  ASSERT_TRUE(near.ok()) << near.status();
  const auto& frame = std::get<client::DepthFrame>(*near);
  const auto& c = std::get<client::CompressedDepthView>(frame.depth);
  EXPECT_EQ(c.compression.level, 3);
  EXPECT_NE(c.view.data, plane.view().data);  // the quantizer's buffer
  EXPECT_GT(quantizer.stats().changed, 0u);
  ExpectWithinBound(plane, c.view, 0.01, "client frame");
  EXPECT_EQ(std::get<ColorView>(frame.colour).data, colour.data);

  client::FrameInput raw = client::DepthFrame{plane.view(), colour};
  near = client::NearLossless(raw, camera, 0.01, &quantizer);
  ASSERT_TRUE(near.ok()) << near.status();
  EXPECT_TRUE(std::holds_alternative<DepthView>(std::get<client::DepthFrame>(*near).depth));

  const std::string png = "not really a png";
  client::FrameInput encoded =
      client::DisparityFrame{client::EncodedImage{png}, colour};
  near = client::NearLossless(encoded, camera, 0.01, &quantizer);
  EXPECT_EQ(near.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(near.status().message()), ::testing::StartsWith("disparity"));

  client::FrameInput stereo = client::StereoFrame{colour, colour};
  near = client::NearLossless(stereo, camera, 0.01, &quantizer);
  ASSERT_TRUE(near.ok());
  EXPECT_TRUE(std::holds_alternative<client::StereoFrame>(*near));
}

TEST(NearLossless, BadArgumentsNameTheField) {
  std::vector<std::uint16_t> values(16, 1000);
  CameraModel camera;
  const auto plane = MakePlane("u16", 4, 4, DepthEncoding::kU16, camera, values);
  PointErrorQuantizer quantizer;
  DepthView q;
  for (double bad : {-0.001, std::numeric_limits<double>::quiet_NaN(),
                     std::numeric_limits<double>::infinity()}) {
    const absl::Status s = quantizer.Quantize(plane.view(), camera, bad, "depth", &q);
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(std::string(s.message()), ::testing::HasSubstr("max_point_error"));
  }
  CameraModel bad_camera;
  bad_camera.fx = 0;
  absl::Status s = quantizer.Quantize(plane.view(), bad_camera, 0.01, "depth", &q);
  EXPECT_THAT(std::string(s.message()), ::testing::HasSubstr("camera.fx"));
  DepthView short_view = plane.view();
  short_view.size_bytes = 8;
  s = quantizer.Quantize(short_view, camera, 0.01, "frame.depth", &q);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), ::testing::HasSubstr("frame.depth"));
}

}  // namespace
}  // namespace cloudcast
