// The synthetic scene is the project's ground truth: these tests check that what it renders is
// exactly the geometry it claims (points converted from its disparities lie on its surfaces),
// that every encoding and size renders, and that it exercises the paper's filters meaningfully.
#include "cloudcast/datasets/synthetic.h"

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "cloudcast/core/camera.h"
#include "cloudcast/core/filters.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/limits.h"
#include "cloudcast/core/point.h"
#include "gtest/gtest.h"

namespace cloudcast {
namespace {

constexpr DisparityEncoding kAllEncodings[] = {DisparityEncoding::kU8, DisparityEncoding::kU16,
                                               DisparityEncoding::kF32};

SyntheticFrame RenderOrDie(std::uint32_t width, std::uint32_t height, std::uint64_t frame,
                           DisparityEncoding encoding) {
  SyntheticOptions options;
  options.width = width;
  options.height = height;
  options.frame = frame;
  options.disparity_encoding = encoding;
  absl::StatusOr<SyntheticFrame> rendered = SyntheticScene::Default().Render(options);
  EXPECT_TRUE(rendered.ok()) << rendered.status();
  return rendered.ok() ? *std::move(rendered) : SyntheticFrame{};
}

// The raw disparity value of pixel i, whatever the encoding.
double RawDisparity(const SyntheticFrame& f, std::size_t i) {
  switch (f.disparity_encoding) {
    case DisparityEncoding::kU8:
      return f.disparity[i];
    case DisparityEncoding::kU16: {
      std::uint16_t v;
      std::memcpy(&v, f.disparity.data() + 2 * i, 2);
      return v;
    }
    case DisparityEncoding::kF32: {
      float v;
      std::memcpy(&v, f.disparity.data() + 4 * i, 4);
      return v;
    }
  }
  return 0;
}

bool IsInvalid(const CameraModel& camera, double raw) {
  for (double bad : camera.invalid_disparities) {
    if (raw == bad) return true;
  }
  return !std::isfinite(raw) || raw * camera.disparity_scale + camera.disparity_offset <= 0.0;
}

// camera.h, in double and written out independently of the library:
//   d' = d * disparity_scale + disparity_offset, z = fx * baseline / d',
//   x = (u - cx) * z / fx, y = (v - cy) * z / fy.
struct Point3 {
  double x, y, z;
};
Point3 Unproject(const CameraModel& c, double u, double v, double raw) {
  const double denominator = raw * c.disparity_scale + c.disparity_offset;
  const double z = c.fx * c.baseline / denominator;
  return {(u - c.cx) * z / c.fx, (v - c.cy) * z / c.fy, z};
}

// Depths of the valid pixels of a kF32 render (exact up to float rounding of the disparity).
std::vector<double> ValidDepths(const SyntheticFrame& f) {
  std::vector<double> depths;
  for (std::size_t i = 0; i < std::size_t{f.width} * f.height; ++i) {
    const double raw = RawDisparity(f, i);
    if (!IsInvalid(f.camera, raw)) {
      depths.push_back(Unproject(f.camera, 0, 0, raw).z);
    }
  }
  return depths;
}

TEST(SyntheticTest, CameraIsThePclPresetScaledToTheWidth) {
  const SyntheticFrame f = RenderOrDie(1280, 720, 0, DisparityEncoding::kU16);
  EXPECT_DOUBLE_EQ(f.camera.fx, 615.0 * 2);
  EXPECT_DOUBLE_EQ(f.camera.fy, 615.0 * 2);
  EXPECT_EQ(f.camera.cx, 640.0);
  EXPECT_EQ(f.camera.cy, 360.0);
  EXPECT_EQ(f.camera.baseline, 1.0);
  EXPECT_EQ(f.camera.disparity_scale, 1.0 / 16.0);
  EXPECT_EQ(f.camera.disparity_offset, 0.0);
  EXPECT_TRUE(f.camera.Validate().ok());

  const SyntheticFrame odd = RenderOrDie(641, 479, 0, DisparityEncoding::kF32);
  EXPECT_EQ(odd.camera.cx, 320.0);  // integer division, as PCL
  EXPECT_EQ(odd.camera.cy, 239.0);
  EXPECT_EQ(odd.camera.disparity_scale, 1.0);
}

TEST(SyntheticTest, RejectsBadSizesNamingTheField) {
  const SyntheticScene scene = SyntheticScene::Default();
  const Limits limits;
  struct Case {
    std::uint32_t width, height;
    std::string field;
  };
  for (const Case& c : {Case{0, 480, "synthetic.width"}, Case{640, 0, "synthetic.height"},
                        Case{limits.max_side + 1, 1, "synthetic.width"},
                        Case{1, limits.max_side + 1, "synthetic.height"},
                        Case{limits.max_side, limits.max_side, "synthetic.width"}}) {
    SyntheticOptions options;
    options.width = c.width;
    options.height = c.height;
    absl::StatusOr<SyntheticFrame> f = scene.Render(options);
    ASSERT_FALSE(f.ok()) << c.width << "x" << c.height;
    EXPECT_EQ(f.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(std::string(f.status().message()).find(c.field), std::string::npos) << f.status();
  }
  SyntheticOptions options;
  options.disparity_encoding = static_cast<DisparityEncoding>(7);
  absl::StatusOr<SyntheticFrame> f = scene.Render(options);
  ASSERT_FALSE(f.ok());
  EXPECT_NE(std::string(f.status().message()).find("synthetic.disparity_encoding"),
            std::string::npos);
}

TEST(SyntheticTest, SameFrameRendersIdenticalBytes) {
  for (DisparityEncoding e : kAllEncodings) {
    const SyntheticFrame a = RenderOrDie(320, 240, 17, e);
    const SyntheticScene copy = SyntheticScene::Default();  // a second scene object, same bytes
    SyntheticOptions options;
    options.width = 320;
    options.height = 240;
    options.frame = 17;
    options.disparity_encoding = e;
    absl::StatusOr<SyntheticFrame> b = copy.Render(options);
    ASSERT_TRUE(b.ok());
    EXPECT_EQ(a.disparity, b->disparity) << Name(e);
    EXPECT_EQ(a.colour, b->colour) << Name(e);
  }
}

TEST(SyntheticTest, CameraMovesWithTheFrame) {
  const SyntheticFrame f0 = RenderOrDie(320, 240, 0, DisparityEncoding::kF32);
  const SyntheticFrame f1 = RenderOrDie(320, 240, 1, DisparityEncoding::kF32);
  const SyntheticFrame f90 = RenderOrDie(320, 240, 90, DisparityEncoding::kF32);
  EXPECT_NE(f0.disparity, f1.disparity);
  EXPECT_NE(f0.colour, f1.colour);
  // A quarter of the way round the path most pixels change.
  std::size_t changed = 0;
  for (std::size_t i = 0; i < 320 * 240; ++i) {
    changed += RawDisparity(f0, i) != RawDisparity(f90, i);
  }
  EXPECT_GT(changed, 320u * 240u / 2);
}

TEST(SyntheticTest, AnyFrameIndexIsAValidView) {
  for (std::uint64_t frame :
       {std::uint64_t{0}, std::uint64_t{123456789}, std::numeric_limits<std::uint64_t>::max()}) {
    const SyntheticFrame f = RenderOrDie(160, 120, frame, DisparityEncoding::kF32);
    const std::vector<double> depths = ValidDepths(f);
    EXPECT_GT(depths.size(), 160u * 120u / 2) << frame;
  }
}

TEST(SyntheticTest, RendersEverySizeAndEncoding) {
  const std::pair<std::uint32_t, std::uint32_t> sizes[] = {{1, 1},     {2, 2},     {1, 7},   {7, 1},
                                                           {641, 479}, {639, 481}, {3, 1000}};
  for (DisparityEncoding e : kAllEncodings) {
    for (auto [w, h] : sizes) {
      SCOPED_TRACE(::testing::Message() << w << "x" << h << " " << Name(e));
      const SyntheticFrame f = RenderOrDie(w, h, 5, e);
      EXPECT_EQ(f.width, w);
      EXPECT_EQ(f.height, h);
      EXPECT_EQ(f.disparity_encoding, e);
      EXPECT_EQ(f.disparity.size(), std::size_t{w} * h * BytesPerPixel(e));
      EXPECT_EQ(f.colour.size(), std::size_t{w} * h * 3);
      const DisparityView dv = f.disparity_view();
      const ColorView cv = f.colour_view();
      EXPECT_EQ(dv.data, f.disparity.data());
      EXPECT_EQ(dv.size_bytes, f.disparity.size());
      EXPECT_EQ(dv.stride_bytes, std::size_t{w} * BytesPerPixel(e));
      EXPECT_EQ(dv.encoding, e);
      EXPECT_EQ(cv.data, f.colour.data());
      EXPECT_EQ(cv.stride_bytes, std::size_t{w} * 3);
      EXPECT_EQ(cv.encoding, ColorEncoding::kBGR8);
      EXPECT_TRUE(ValidateFrame(dv, cv, Limits{}).ok());
    }
  }
  // The centre pixel of a 1x1 frame looks along the optical axis, at the scene.
  const SyntheticFrame one = RenderOrDie(1, 1, 0, DisparityEncoding::kF32);
  EXPECT_GT(RawDisparity(one, 0), 0.0);
}

TEST(SyntheticTest, LargeFramesRender) {
  const SyntheticFrame f = RenderOrDie(2560, 1920, 3, DisparityEncoding::kF32);
  EXPECT_EQ(f.disparity.size(), 2560u * 1920u * 4u);
  EXPECT_GT(ValidDepths(f).size(), 2560u * 1920u / 2);
}

TEST(SyntheticTest, U8At640x480HoldsTheSceneInEightBits) {
  for (std::uint64_t frame : {0, 45, 90, 180, 270}) {
    const SyntheticFrame f = RenderOrDie(640, 480, frame, DisparityEncoding::kU8);
    std::size_t valid = 0, in_design_range = 0;
    for (std::uint8_t d : f.disparity) {
      if (d == 0) continue;
      ++valid;
      // Depths 2.5..16.5 at f = 615: disparities 37..246.
      in_design_range += d >= 37 && d <= 246;
    }
    EXPECT_GT(valid, 640u * 480u * 8 / 10) << frame;
    EXPECT_EQ(in_design_range, valid) << frame;
  }
}

// kU8 / kU16 values are the exact disparity rounded to the nearest code; out of range is 0.
TEST(SyntheticTest, IntegerEncodingsRoundTheExactDisparity) {
  for (auto [w, h] : {std::pair<std::uint32_t, std::uint32_t>{640, 480}, {1280, 960}}) {
    const SyntheticFrame exact = RenderOrDie(w, h, 30, DisparityEncoding::kF32);
    const SyntheticFrame u8 = RenderOrDie(w, h, 30, DisparityEncoding::kU8);
    const SyntheticFrame u16 = RenderOrDie(w, h, 30, DisparityEncoding::kU16);
    std::size_t too_near_u8 = 0;
    for (std::size_t i = 0; i < std::size_t{w} * h; ++i) {
      const double d = RawDisparity(exact, i);
      const double d8 = RawDisparity(u8, i), d16 = RawDisparity(u16, i);
      if (d == 0.0) {
        ASSERT_EQ(d8, 0.0);
        ASSERT_EQ(d16, 0.0);
        continue;
      }
      if (d > 255.5) {
        ASSERT_EQ(d8, 0.0) << i << " d=" << d;  // does not fit: invalid, never wrapped
        ++too_near_u8;
      } else {
        ASSERT_LE(std::fabs(d8 - d), 0.5 + 1e-4) << i;
      }
      // 2047 is PCL's "invalid" code; a real disparity there moves to a neighbouring code.
      ASSERT_NE(d16, 2047.0) << i;
      ASSERT_LE(std::fabs(d16 / 16.0 - d),
                (d16 == 2046.0 || d16 == 2048.0 ? 1.0 : 0.5) / 16.0 + 1e-4)
          << i;
    }
    if (w == 640) {
      EXPECT_EQ(too_near_u8, 0u);
    } else {
      EXPECT_GT(too_near_u8, 0u);  // at 1280 px the bottom of the floor is nearer than 4.8
    }
  }
}

// The key property: every valid pixel of an exact render, unprojected with camera.h's formulas,
// lies on a surface of the scene.
TEST(SyntheticTest, ExactPointsLieOnTheSurfaces) {
  const SyntheticScene scene = SyntheticScene::Default();
  for (auto [w, h, frame] : {std::tuple<std::uint32_t, std::uint32_t, std::uint64_t>{640, 480, 0},
                             {640, 480, 77},
                             {641, 479, 200},
                             {320, 240, 359},
                             {333, 211, 1000003}}) {
    SCOPED_TRACE(::testing::Message() << w << "x" << h << " frame " << frame);
    const SyntheticFrame f = RenderOrDie(w, h, frame, DisparityEncoding::kF32);
    std::size_t valid = 0;
    double worst = 0;
    for (std::uint32_t v = 0; v < h; ++v) {
      for (std::uint32_t u = 0; u < w; ++u) {
        const double raw = RawDisparity(f, std::size_t{v} * w + u);
        if (IsInvalid(f.camera, raw)) continue;
        ++valid;
        const Point3 p = Unproject(f.camera, u, v, raw);
        const double distance = scene.DistanceToSurface(frame, p.x, p.y, p.z);
        worst = std::max(worst, distance / p.z);
        ASSERT_LT(distance, 1e-6 * p.z) << "pixel (" << u << ", " << v << ") z=" << p.z;
      }
    }
    EXPECT_GT(valid, std::size_t{w} * h / 2);
    RecordProperty("worst_relative_distance", std::to_string(worst));
  }
}

// Quantized disparities move each point along its ray by at most the depth step of the rounding.
TEST(SyntheticTest, U16PointsLieWithinTheQuantizationOfTheSurfaces) {
  const SyntheticScene scene = SyntheticScene::Default();
  for (std::uint64_t frame : {0, 123}) {
    const SyntheticFrame f = RenderOrDie(640, 480, frame, DisparityEncoding::kU16);
    std::size_t valid = 0;
    for (std::uint32_t v = 0; v < 480; ++v) {
      for (std::uint32_t u = 0; u < 640; ++u) {
        const double raw = RawDisparity(f, std::size_t{v} * 640 + u);
        if (IsInvalid(f.camera, raw)) continue;
        ++valid;
        const Point3 p = Unproject(f.camera, u, v, raw);
        // The true raw value is within half a code (a whole code next to the moved 2047).
        const double step = (raw == 2046.0 || raw == 2048.0) ? 1.0 : 0.5;
        const double z_far = Unproject(f.camera, u, v, raw - step).z;
        const double z_near = Unproject(f.camera, u, v, raw + step).z;
        // Moving along the ray t * (a, b, 1) by dz moves the point dz * |(a, b, 1)|.
        const double ray_length = std::sqrt(p.x * p.x + p.y * p.y + p.z * p.z) / p.z;
        const double bound = (z_far - z_near) * ray_length * (1 + 1e-9) + 1e-9;
        ASSERT_LE(scene.DistanceToSurface(frame, p.x, p.y, p.z), bound)
            << "pixel (" << u << ", " << v << ") raw=" << raw;
      }
    }
    EXPECT_GT(valid, 640u * 480u * 8 / 10);
  }
}

// The same through the library's conversion, in float (depends on filters.cc).
TEST(SyntheticTest, ConvertedPointsLieOnTheSurfaces) {
  const SyntheticScene scene = SyntheticScene::Default();
  for (auto [w, h, frame] : {std::tuple<std::uint32_t, std::uint32_t, std::uint64_t>{640, 480, 0},
                             {640, 480, 150},
                             {641, 479, 7}}) {
    SCOPED_TRACE(::testing::Message() << w << "x" << h << " frame " << frame);
    const SyntheticFrame f = RenderOrDie(w, h, frame, DisparityEncoding::kF32);
    PointCloud cloud;
    const absl::Status status =
        ConvertToOrganized(f.camera, f.disparity_view(), f.colour_view(), &cloud);
    ASSERT_TRUE(status.ok()) << status;
    ASSERT_EQ(cloud.width, w);
    ASSERT_EQ(cloud.height, h);
    ASSERT_EQ(cloud.size(), std::size_t{w} * h);
    std::size_t finite = 0;
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      const Point& p = cloud.points[i];
      const bool valid = !IsInvalid(f.camera, RawDisparity(f, i));
      ASSERT_EQ(std::isfinite(p.z), valid) << i;
      if (!valid) continue;
      ++finite;
      const double distance = scene.DistanceToSurface(frame, p.x, p.y, p.z);
      ASSERT_LT(distance, 1e-5 * p.z) << "pixel (" << i % w << ", " << i / w << ") z=" << p.z;
      // BGR8 in, PCL's packing out.
      ASSERT_EQ(BlueOf(p.rgba), f.colour[3 * i]);
      ASSERT_EQ(GreenOf(p.rgba), f.colour[3 * i + 1]);
      ASSERT_EQ(RedOf(p.rgba), f.colour[3 * i + 2]);
    }
    EXPECT_GT(finite, std::size_t{w} * h / 2);
  }
}

TEST(SyntheticTest, ColoursVaryOverTheSurfaces) {
  const SyntheticFrame f = RenderOrDie(640, 480, 0, DisparityEncoding::kU8);
  std::set<std::uint32_t> colours, colours_of_valid;
  for (std::size_t i = 0; i < 640 * 480; ++i) {
    const std::uint32_t bgr =
        f.colour[3 * i] | (f.colour[3 * i + 1] << 8) | (std::uint32_t{f.colour[3 * i + 2]} << 16);
    colours.insert(bgr);
    if (f.disparity[i] != 0) colours_of_valid.insert(bgr);
  }
  EXPECT_GT(colours_of_valid.size(), 50u);
  // Neighbouring pixels mostly differ a little, not all the same: textures, not flat fills.
  std::size_t same_as_left = 0;
  for (std::size_t v = 0; v < 480; ++v) {
    for (std::size_t u = 1; u < 640; ++u) {
      const std::size_t i = v * 640 + u;
      same_as_left += std::memcmp(&f.colour[3 * i], &f.colour[3 * (i - 1)], 3) == 0;
    }
  }
  EXPECT_LT(same_as_left, 640u * 480u * 9 / 10);
}

// At every frame the depths span about 2.6..16, most of the content is inside the paper's
// passthrough [3, 12], and the back wall (and part of the floor) lies beyond it.
TEST(SyntheticTest, DepthsSuitThePapersPassthroughAlongThePath) {
  for (std::uint64_t frame = 0; frame < 360; frame += 20) {
    SCOPED_TRACE(::testing::Message() << "frame " << frame);
    const SyntheticFrame f = RenderOrDie(320, 240, frame, DisparityEncoding::kF32);
    const std::vector<double> depths = ValidDepths(f);
    ASSERT_GT(depths.size(), 320u * 240u * 8 / 10);
    std::size_t kept = 0, beyond = 0;
    double min_z = 1e9, max_z = 0;
    for (double z : depths) {
      min_z = std::min(min_z, z);
      max_z = std::max(max_z, z);
      kept += z >= 3.0 && z <= 12.0;
      beyond += z > 12.0;
    }
    EXPECT_GE(min_z, 2.5);
    EXPECT_LE(max_z, 16.5);
    EXPECT_GT(kept, depths.size() * 4 / 10);    // substantial...
    EXPECT_LT(kept, depths.size() * 95 / 100);  // ...but partial
    EXPECT_GT(beyond, depths.size() / 20);      // the wall is cut
  }
}

// The same share through the library's conversion and passthrough (depends on filters.cc).
TEST(SyntheticTest, LibraryPassthroughKeepsAPartialShare) {
  const SyntheticFrame f = RenderOrDie(640, 480, 0, DisparityEncoding::kU8);
  PointCloud organized, kept;
  ASSERT_TRUE(ConvertToOrganized(f.camera, f.disparity_view(), f.colour_view(), &organized).ok());
  PassThroughParams params;  // z in [3, 12]
  ASSERT_TRUE(PassThrough(organized, params, &kept).ok());
  std::size_t valid = 0;
  for (std::uint8_t d : f.disparity) valid += d != 0;
  EXPECT_GT(kept.size(), valid * 4 / 10);
  EXPECT_LT(kept.size(), valid * 95 / 100);
}

TEST(SyntheticTest, DistanceToSurfaceIsADistance) {
  const SyntheticScene scene = SyntheticScene::Default();
  for (std::uint64_t frame : {0, 90, 180}) {
    // The camera floats 1.35..1.65 above the floor with nothing nearer.
    const double from_camera = scene.DistanceToSurface(frame, 0, 0, 0);
    EXPECT_GT(from_camera, 1.3);
    EXPECT_LT(from_camera, 1.7);
    // Along a pixel's ray the distance grows no faster than the distance travelled.
    const SyntheticFrame f = RenderOrDie(64, 48, frame, DisparityEncoding::kF32);
    const double raw = RawDisparity(f, 24 * 64 + 32);
    ASSERT_GT(raw, 0.0);
    const Point3 p = Unproject(f.camera, 32, 24, raw);
    for (double s : {0.99, 0.95}) {
      const double d = scene.DistanceToSurface(frame, s * p.x, s * p.y, s * p.z);
      EXPECT_GT(d, 0.0);
      EXPECT_LE(d, (1 - s) * std::sqrt(p.x * p.x + p.y * p.y + p.z * p.z) + 1e-12);
    }
  }
}

// The stereo truth the benchmarks and tests score matchers against: the left view's disparity for
// the pair's baseline (kSyntheticStereoBaseline, half the frame's 1), in whole pixels.
TEST(SyntheticTest, StereoTruthIsTheLeftDisparityAtThePairsBaselineInWholePixels) {
  SyntheticOptions o;
  o.width = 160;
  o.height = 120;
  o.frame = 3;
  auto left = SyntheticScene::Default().Render(o);
  ASSERT_TRUE(left.ok()) << left.status();
  auto truth = SyntheticStereoTruth(*left);
  ASSERT_TRUE(truth.ok()) << truth.status();
  ASSERT_EQ(truth->size(), std::size_t{160} * 120);
  std::size_t known = 0;
  for (std::size_t i = 0; i < truth->size(); ++i) {
    float d;
    std::memcpy(&d, &left->disparity[4 * i], 4);
    const double want = d * kSyntheticStereoBaseline;
    if (std::isfinite(want) && want > 0.5 && want < 255) {
      EXPECT_EQ((*truth)[i], std::lround(want)) << i;
      ++known;
    } else {
      EXPECT_EQ((*truth)[i], 0) << i;
    }
  }
  EXPECT_GT(known, truth->size() / 2);  // the floor, boxes and spheres: most of the view

  o.disparity_encoding = DisparityEncoding::kU16;
  auto fixed = SyntheticScene::Default().Render(o);
  ASSERT_TRUE(fixed.ok());
  const auto refused = SyntheticStereoTruth(*fixed);
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(refused.status().message().find("left.disparity_encoding"), std::string::npos);
}

}  // namespace
}  // namespace cloudcast
