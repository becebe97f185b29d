// Depth images (ROS REP 118: 16UC1 millimetres, 32FC1 metres) in the core: the points equal, bit
// for bit, what ROS depth_image_proc's point_cloud_xyzrgb computes (its conversion is written out
// below as it is in depth_image_proc/depth_conversions.h, noetic, the version Debian 12 ships),
// the fused pipeline equals the stand-alone stages, and bad depth inputs are refused naming the
// field.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "cloudcast/core/camera.h"
#include "cloudcast/core/filters.h"
#include "cloudcast/core/pipeline.h"
#include "support/test_support.h"

namespace cloudcast {
namespace {

using testing::CloudsIdentical;

// depth_image_proc's DepthTraits and convert(), with its types; only the output container
// differs (a vector of x, y, z instead of a PointCloud2 iterator).
template <typename T>
struct DepthTraits {};
template <>
struct DepthTraits<std::uint16_t> {
  static inline bool valid(std::uint16_t depth) { return depth != 0; }
  static inline float toMeters(std::uint16_t depth) { return depth * 0.001f; }  // mm
};
template <>
struct DepthTraits<float> {
  static inline bool valid(float depth) { return std::isfinite(depth); }
  static inline float toMeters(float depth) { return depth; }
};

struct Xyz {
  float x, y, z;
};

// `unit_scaling` is toMeters(T(1)) in depth_image_proc; a depth_scale other than REP 118's is the
// same formula with another unit, which the caller passes (as depth_image_proc would if its
// traits had that unit).
template <typename T>
std::vector<Xyz> DepthImageProcConvert(const std::vector<T>& depth, int width, int height,
                                       double fx, double fy, double cx, double cy, float unit) {
  const float center_x = cx;
  const float center_y = cy;
  const double unit_scaling = DepthTraits<T>::toMeters(T(1)) == 1.0f ? 1.0 * unit : unit;
  const float constant_x = unit_scaling / fx;
  const float constant_y = unit_scaling / fy;
  const float bad_point = std::numeric_limits<float>::quiet_NaN();
  std::vector<Xyz> out(static_cast<std::size_t>(width) * height);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      Xyz& p = out[static_cast<std::size_t>(v) * width + u];
      T d = depth[static_cast<std::size_t>(v) * width + u];
      if (!DepthTraits<T>::valid(d)) {
        p.x = p.y = p.z = bad_point;
        continue;
      }
      p.x = (u - center_x) * d * constant_x;
      p.y = (v - center_y) * d * constant_y;
      if constexpr (std::is_same_v<T, float>) {
        p.z = unit == 1.0f ? DepthTraits<T>::toMeters(d) : d * unit;
      } else {
        p.z = unit == 0.001f ? DepthTraits<T>::toMeters(d) : d * unit;
      }
    }
  }
  return out;
}

bool SameBits(float a, float b) { return std::memcmp(&a, &b, sizeof a) == 0; }

struct DepthFrame {
  std::vector<std::uint8_t> depth_bytes;
  std::vector<std::uint8_t> colour_bytes;
  DepthView depth;
  ColorView colour;
};

template <typename T>
DepthFrame MakeDepthFrame(const std::vector<T>& values, std::uint32_t w, std::uint32_t h) {
  DepthFrame f;
  f.depth_bytes.resize(values.size() * sizeof(T));
  std::memcpy(f.depth_bytes.data(), values.data(), f.depth_bytes.size());
  f.colour_bytes.resize(std::size_t{w} * h * 3);
  for (std::size_t i = 0; i < f.colour_bytes.size(); ++i) f.colour_bytes[i] = (i * 37) & 0xFF;
  f.depth = DepthView{f.depth_bytes.data(),
                      f.depth_bytes.size(),
                      w,
                      h,
                      w * sizeof(T),
                      std::is_same_v<T, float> ? DepthEncoding::kF32 : DepthEncoding::kU16};
  f.colour =
      ColorView{f.colour_bytes.data(), f.colour_bytes.size(), w, h, w * 3u, ColorEncoding::kBGR8};
  return f;
}

// Random depths with the special values a depth camera sends: 0 everywhere holes are, and for
// floats NaN and infinities.
template <typename T>
std::vector<T> RandomDepths(std::mt19937& rng, std::size_t n) {
  std::vector<T> out(n);
  for (T& d : out) {
    const unsigned r = rng() % 100;
    if constexpr (std::is_same_v<T, float>) {
      if (r < 8) {
        d = 0.0f;
      } else if (r < 12) {
        d = std::numeric_limits<float>::quiet_NaN();
      } else if (r < 14) {
        d = r % 2 ? std::numeric_limits<float>::infinity()
                  : -std::numeric_limits<float>::infinity();
      } else {
        d = std::uniform_real_distribution<float>(0.2f, 15.0f)(rng);
      }
    } else {
      d = r < 10 ? 0 : static_cast<T>(200 + rng() % 15000);  // 0.2 m .. 15.2 m
    }
  }
  return out;
}

template <typename T>
void ExpectEqualsDepthImageProc(std::optional<double> depth_scale) {
  std::mt19937 rng(7);
  const std::uint32_t w = 67, h = 45;
  const std::vector<T> values = RandomDepths<T>(rng, std::size_t{w} * h);
  DepthFrame f = MakeDepthFrame(values, w, h);
  CameraModel camera;
  camera.fx = 525.3;
  camera.fy = 521.7;
  camera.cx = 33.41;
  camera.cy = 21.9;
  camera.depth_scale = depth_scale;
  const float unit = static_cast<float>(camera.DepthScale(f.depth.encoding));
  const std::vector<Xyz> ref =
      DepthImageProcConvert(values, w, h, camera.fx, camera.fy, camera.cx, camera.cy, unit);

  PointCloud organized;
  ASSERT_TRUE(ConvertToOrganized(camera, f.depth, f.colour, &organized).ok());
  ASSERT_EQ(organized.size(), ref.size());
  std::vector<Point> finite_ref;
  for (std::size_t i = 0; i < ref.size(); ++i) {
    const Point& p = organized.points[i];
    const bool ref_valid = std::isfinite(ref[i].z) && ref[i].z != 0.0f;
    if (!ref_valid) {
      EXPECT_TRUE(std::isnan(p.x) && std::isnan(p.y) && std::isnan(p.z)) << "pixel " << i;
      continue;
    }
    EXPECT_TRUE(SameBits(p.x, ref[i].x) && SameBits(p.y, ref[i].y) && SameBits(p.z, ref[i].z))
        << "pixel " << i << ": ours (" << p.x << ", " << p.y << ", " << p.z
        << "), depth_image_proc (" << ref[i].x << ", " << ref[i].y << ", " << ref[i].z << ")";
    finite_ref.push_back(p);
  }

  // The fused pipeline with both filters off: the valid points in raster order, the same bits.
  PipelineOptions o;
  o.camera = camera;
  o.passthrough.enabled = false;
  o.voxel.enabled = false;
  Pipeline pipeline;
  PointCloud fused;
  StageCounts counts;
  ASSERT_TRUE(pipeline.Run(o, f.depth, f.colour, &fused, &counts).ok());
  EXPECT_EQ(counts.valid_points, finite_ref.size());
  ASSERT_EQ(fused.size(), finite_ref.size());
  for (std::size_t i = 0; i < fused.size(); ++i) {
    const Point& a = fused.points[i];
    const Point& b = finite_ref[i];
    ASSERT_TRUE(SameBits(a.x, b.x) && SameBits(a.y, b.y) && SameBits(a.z, b.z) && a.rgba == b.rgba)
        << "point " << i;
  }
}

TEST(DepthConversion, Millimetres16BitEqualDepthImageProcBitForBit) {
  ExpectEqualsDepthImageProc<std::uint16_t>(std::nullopt);
}
TEST(DepthConversion, FloatMetresEqualDepthImageProcBitForBit) {
  ExpectEqualsDepthImageProc<float>(std::nullopt);
}
TEST(DepthConversion, OtherDepthScalesFollowTheSameFormula) {
  ExpectEqualsDepthImageProc<std::uint16_t>(0.0002);  // 0.2 mm units, as some cameras send
  ExpectEqualsDepthImageProc<float>(0.01);            // centimetres in float
}

// One row of float depths through the fused pipeline with both filters off: every valid depth's
// point, in order.
void RunUnfiltered(const DepthFrame& f, const CameraModel& camera, PointCloud* cloud,
                   StageCounts* counts) {
  PipelineOptions o;
  o.camera = camera;
  o.passthrough.enabled = false;
  o.voxel.enabled = false;
  Pipeline pipeline;
  ASSERT_TRUE(pipeline.Run(o, f.depth, f.colour, cloud, counts).ok());
}

CameraModel OriginCamera() {
  CameraModel camera;
  camera.cx = 0;
  camera.cy = 0;
  return camera;
}

TEST(DepthConversion, ZeroNanAndInfinityMeanNoMeasurement) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  const std::vector<float> values = {0.0f, nan, inf, -inf, 2.0f, -0.0f};
  DepthFrame f = MakeDepthFrame(values, 6, 1);
  PointCloud cloud;
  StageCounts counts;
  RunUnfiltered(f, OriginCamera(), &cloud, &counts);
  ASSERT_EQ(cloud.size(), 1u);
  EXPECT_EQ(cloud.points[0].z, 2.0f);
  EXPECT_EQ(counts.valid_points, 1u);
  EXPECT_EQ(counts.pixels, 6u);
}

// Issue 30, defect 8: a depth behind the camera or too small to be a distance is no measurement,
// as a negative disparity is none. Before, -5 m and 1e-45 m made points (22,794 behind the camera
// in the tester's frame with the passthrough off).
TEST(DepthConversion, NonPositiveAndSubnormalDepthsMeanNoMeasurement) {
  const float denormal = std::numeric_limits<float>::denorm_min();  // 1.4e-45
  const std::vector<float> values = {-5.0f, denormal, -denormal, 1e-39f, 2.0f,
                                     std::numeric_limits<float>::min(), -0.001f, 0.5f};
  DepthFrame f = MakeDepthFrame(values, 8, 1);
  CameraModel camera = OriginCamera();
  PointCloud cloud;
  StageCounts counts;
  RunUnfiltered(f, camera, &cloud, &counts);
  ASSERT_EQ(cloud.size(), 3u);
  EXPECT_EQ(cloud.points[0].z, 2.0f);
  EXPECT_EQ(cloud.points[1].z, std::numeric_limits<float>::min());
  EXPECT_EQ(cloud.points[2].z, 0.5f);
  EXPECT_EQ(counts.valid_points, 3u);
  // The organized conversion agrees: NaN where there is no measurement.
  PointCloud organized;
  ASSERT_TRUE(ConvertToOrganized(camera, f.depth, f.colour, &organized).ok());
  for (std::size_t i : {0, 1, 2, 3, 6}) EXPECT_TRUE(std::isnan(organized.points[i].z)) << i;
  // The rule is on z in metres: a scale that makes a raw depth subnormal takes it out too.
  camera.depth_scale = 1e-9;
  RunUnfiltered(f, camera, &cloud, &counts);
  EXPECT_EQ(counts.valid_points, 2u) << "2 and 0.5 stay; min() * 1e-9 is subnormal";
}

// Passthrough on each axis, negative mode, voxel grid on and off, every colour encoding: the
// fused pipeline equals organized conversion + PassThrough + VoxelGrid, point for point in order.
TEST(DepthPipeline, FusedEqualsStaged) {
  std::mt19937 rng(3);
  Pipeline pipeline;
  VoxelGrid grid;
  for (int variant = 0; variant < 8; ++variant) {
    const std::uint32_t w = 33 + rng() % 80, h = 19 + rng() % 60;
    DepthFrame f = variant % 2
                       ? MakeDepthFrame(RandomDepths<float>(rng, std::size_t{w} * h), w, h)
                       : MakeDepthFrame(RandomDepths<std::uint16_t>(rng, std::size_t{w} * h), w, h);
    PipelineOptions o;
    o.camera.fx = 580;
    o.camera.fy = 580;
    o.camera.cx = w / 2.0 - 0.5;
    o.camera.cy = h / 2.0 + 0.25;
    const int axis = (variant / 2) % 3;
    o.passthrough.axis = static_cast<Axis>(axis);
    o.passthrough.min = axis == 2 ? 1.0f : -0.5f;
    o.passthrough.max = axis == 2 ? 9.0f : 0.5f;
    o.passthrough.negative = variant == 5;
    o.voxel.enabled = variant != 4;
    o.voxel.SetLeaf(0.04f);
    PointCloud organized, passed, staged, fused;
    StageCounts counts;
    ASSERT_TRUE(ConvertToOrganized(o.camera, f.depth, f.colour, &organized).ok());
    ASSERT_TRUE(PassThrough(organized, o.passthrough, &passed).ok());
    ASSERT_TRUE(pipeline.Run(o, f.depth, f.colour, &fused, &counts).ok());
    EXPECT_EQ(counts.after_passthrough, passed.size()) << "variant " << variant;
    if (o.voxel.enabled) {
      ASSERT_TRUE(grid.Filter(passed, o.voxel, &staged).ok());
      EXPECT_TRUE(CloudsIdentical(staged, fused)) << "variant " << variant;
    } else {
      EXPECT_TRUE(CloudsIdentical(passed, fused)) << "variant " << variant;
    }
  }
}

// A pipeline reused for disparity frames and depth frames in turn keeps their tables apart.
TEST(DepthPipeline, AlternatingWithDisparityFramesKeepsTheirTablesApart) {
  std::mt19937 rng(11);
  auto disparity =
      testing::RandomFrame(rng, 40, 30, DisparityEncoding::kU16, ColorEncoding::kBGR8, 20, 250);
  DepthFrame depth = MakeDepthFrame(RandomDepths<std::uint16_t>(rng, 40 * 30), 40, 30);
  PipelineOptions o;
  o.camera = CameraModel::PclCompatible(40, 30);
  o.passthrough.enabled = false;
  o.voxel.enabled = false;
  Pipeline shared, fresh_disparity, fresh_depth;
  for (int round = 0; round < 3; ++round) {
    PointCloud a, b;
    ASSERT_TRUE(shared.Run(o, disparity.disparity, disparity.colour, &a).ok());
    ASSERT_TRUE(fresh_disparity.Run(o, disparity.disparity, disparity.colour, &b).ok());
    EXPECT_TRUE(CloudsIdentical(a, b));
    ASSERT_TRUE(shared.Run(o, depth.depth, depth.colour, &a).ok());
    ASSERT_TRUE(fresh_depth.Run(o, depth.depth, depth.colour, &b).ok());
    EXPECT_TRUE(CloudsIdentical(a, b));
  }
}

MATCHER_P(StatusMentions, text, "") {
  return !arg.ok() && std::string(arg.message()).find(text) != std::string::npos;
}

TEST(DepthValidation, BadInputsNameTheField) {
  DepthFrame f = MakeDepthFrame(std::vector<std::uint16_t>(12, 1000), 4, 3);
  PipelineOptions o;
  Pipeline pipeline;
  PointCloud cloud;
  for (double bad : {0.0, -1.0, std::numeric_limits<double>::quiet_NaN()}) {
    o.camera.depth_scale = bad;
    EXPECT_THAT(pipeline.Run(o, f.depth, f.colour, &cloud), StatusMentions("camera.depth_scale"));
  }
  o.camera.depth_scale.reset();
  ColorView small = f.colour;
  small.width = 3;
  small.stride_bytes = 9;
  EXPECT_THAT(pipeline.Run(o, f.depth, small, &cloud),
              StatusMentions("colour is 3x3 but depth is 4x3"));
  DepthView short_buffer = f.depth;
  short_buffer.size_bytes = 10;
  EXPECT_THAT(pipeline.Run(o, short_buffer, f.colour, &cloud), StatusMentions("depth.data"));
  DepthView bad_encoding = f.depth;
  bad_encoding.encoding = static_cast<DepthEncoding>(9);
  EXPECT_THAT(pipeline.Run(o, bad_encoding, f.colour, &cloud), StatusMentions("depth.encoding"));
}

TEST(DepthEncodingNames, RoundTrip) {
  for (auto e : {DepthEncoding::kU16, DepthEncoding::kF32}) {
    DepthEncoding parsed;
    ASSERT_TRUE(ParseDepthEncoding(Name(e), &parsed));
    EXPECT_EQ(parsed, e);
  }
  DepthEncoding parsed;
  EXPECT_FALSE(ParseDepthEncoding("u8", &parsed));
  EXPECT_EQ(CameraModel{}.DepthScale(DepthEncoding::kU16), 0.001);
  EXPECT_EQ(CameraModel{}.DepthScale(DepthEncoding::kF32), 1.0);
}

}  // namespace
}  // namespace cloudcast
