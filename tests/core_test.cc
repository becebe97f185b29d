// The core stages on their own: semantics, validation of every input field, odd sizes, the
// general voxel-key path, and fused == stand-alone. No PCL here (see pcl_equivalence_test.cc).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <tuple>

#include "cloudcast/core/camera.h"
#include "cloudcast/core/filters.h"
#include "cloudcast/core/pipeline.h"
#include "support/test_support.h"

namespace cloudcast {
namespace {

using testing::CloudsIdentical;
using testing::CloudsMatch;
using testing::CloudsMatchInOrder;
using testing::CloudTolerance;
using testing::MakeFrame;
using testing::RandomFrame;
using testing::SetSample;

MATCHER_P(StatusMentions, text, "") {
  return !arg.ok() && std::string(arg.message()).find(text) != std::string::npos;
}

PointCloud CloudOf(std::initializer_list<Point> points) {
  PointCloud c;
  for (const Point& p : points) c.points.push_back(p);
  c.width = static_cast<std::uint32_t>(c.size());
  c.height = 1;
  return c;
}

TEST(Point, PackedColourRoundTrip) {
  const std::uint32_t c = PackRgba(10, 20, 30, 40);
  EXPECT_EQ(c, 0x280A141Eu);
  EXPECT_EQ(RedOf(c), 10);
  EXPECT_EQ(GreenOf(c), 20);
  EXPECT_EQ(BlueOf(c), 30);
  EXPECT_EQ(AlphaOf(c), 40);
}

TEST(Camera, PclPresetUsesIntegerHalfSizes) {
  const CameraModel c = CameraModel::PclCompatible(641, 479, 500);
  EXPECT_EQ(c.cx, 320.0);
  EXPECT_EQ(c.cy, 239.0);
  EXPECT_EQ(c.fx, 500.0);
  EXPECT_EQ(c.fy, 500.0);
  EXPECT_EQ(c.baseline, 1.0);
  EXPECT_TRUE(c.Validate().ok());
}

TEST(Camera, RejectsBadFields) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  struct Case {
    std::function<void(CameraModel&)> mutate;
    std::string field;
  };
  const std::vector<Case> cases = {
      {[](CameraModel& c) { c.fx = 0; }, "camera.fx"},
      {[&](CameraModel& c) { c.fx = nan; }, "camera.fx"},
      {[](CameraModel& c) { c.fx = -615; }, "camera.fx"},
      {[&](CameraModel& c) { c.fy = inf; }, "camera.fy"},
      {[](CameraModel& c) { c.baseline = 0; }, "camera.baseline"},
      {[&](CameraModel& c) { c.cx = nan; }, "camera.cx"},
      {[&](CameraModel& c) { c.cy = inf; }, "camera.cy"},
      {[](CameraModel& c) { c.disparity_scale = 0; }, "camera.disparity_scale"},
      {[&](CameraModel& c) { c.disparity_offset = nan; }, "camera.disparity_offset"},
      {[&](CameraModel& c) { c.invalid_disparities = {nan}; }, "camera.invalid_disparities"},
      {[](CameraModel& c) { c.invalid_disparities.assign(17, 1.0); }, "camera.invalid_disparities"},
  };
  for (const Case& k : cases) {
    CameraModel c;
    k.mutate(c);
    EXPECT_THAT(c.Validate(), StatusMentions(k.field));
  }
}

TEST(Validation, BadFramesGetErrorsNamingTheField) {
  auto f = MakeFrame(8, 6, DisparityEncoding::kU8, ColorEncoding::kBGR8);
  const CameraModel camera = CameraModel::PclCompatible(8, 6);
  PointCloud out;
  Pipeline pipeline;
  PipelineOptions options;
  options.camera = camera;
  auto run = [&](DisparityView d, ColorView c) {
    const absl::Status fused = pipeline.Run(options, d, c, &out);
    const absl::Status staged = ConvertToOrganized(camera, d, c, &out);
    EXPECT_EQ(fused.message(), staged.message());
    return fused;
  };
  EXPECT_TRUE(run(f.disparity, f.colour).ok());

  DisparityView d = f.disparity;
  d.size_bytes -= 1;
  EXPECT_THAT(run(d, f.colour), StatusMentions("disparity.data holds 47 bytes"));
  d = f.disparity;
  d.stride_bytes = 7;
  EXPECT_THAT(run(d, f.colour), StatusMentions("disparity.stride_bytes"));
  d = f.disparity;
  d.data = nullptr;
  EXPECT_THAT(run(d, f.colour), StatusMentions("disparity.data is null"));
  d = f.disparity;
  d.width = 0;
  EXPECT_THAT(run(d, f.colour), StatusMentions("disparity.width is 0"));
  d = f.disparity;
  d.height = 0;
  EXPECT_THAT(run(d, f.colour), StatusMentions("disparity.height is 0"));
  d = f.disparity;
  d.width = 100000;
  d.height = 100000;
  EXPECT_THAT(run(d, f.colour), StatusMentions("pixels per side"));
  d = f.disparity;
  d.width = 16000;
  d.height = 16000;
  EXPECT_THAT(run(d, f.colour), StatusMentions("pixels (width x height)"));
  d = f.disparity;
  d.encoding = static_cast<DisparityEncoding>(9);
  EXPECT_THAT(run(d, f.colour), StatusMentions("disparity.encoding"));

  ColorView c = f.colour;
  c.size_bytes = 10;
  EXPECT_THAT(run(f.disparity, c), StatusMentions("colour.data holds 10 bytes"));
  c = f.colour;
  c.width = 7;
  c.stride_bytes = 21;
  EXPECT_THAT(run(f.disparity, c), StatusMentions("colour is 7x6 but disparity is 8x6"));
  c = f.colour;
  c.encoding = ColorEncoding::kRGBA8;  // 4 bytes per pixel: the 24-byte rows are too short
  EXPECT_THAT(run(f.disparity, c), StatusMentions("colour.stride_bytes"));

  options.camera.fx = 0;
  EXPECT_THAT(pipeline.Run(options, f.disparity, f.colour, &out), StatusMentions("camera.fx"));
  EXPECT_TRUE(out.empty());
  options.camera = camera;
  options.voxel.SetLeaf(0.0f);
  EXPECT_THAT(pipeline.Run(options, f.disparity, f.colour, &out), StatusMentions("voxel.leaf_x"));
  options.voxel.SetLeaf(-0.03f);
  EXPECT_THAT(pipeline.Run(options, f.disparity, f.colour, &out), StatusMentions("voxel.leaf_x"));
  options.voxel.leaf_x = 0.03f;
  options.voxel.leaf_y = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THAT(pipeline.Run(options, f.disparity, f.colour, &out), StatusMentions("voxel.leaf_y"));
  options.voxel.leaf_y = 0.03f;
  options.voxel.leaf_z = 1e-45f;  // 1/leaf is infinite in float
  EXPECT_THAT(pipeline.Run(options, f.disparity, f.colour, &out), StatusMentions("voxel.leaf_z"));
  options.voxel = VoxelGridParams{};
  options.passthrough.min = 5;
  options.passthrough.max = 4;
  EXPECT_THAT(pipeline.Run(options, f.disparity, f.colour, &out),
              StatusMentions("passthrough.min (5) must not exceed passthrough.max (4)"));
  options.passthrough.max = std::numeric_limits<float>::infinity();
  EXPECT_THAT(pipeline.Run(options, f.disparity, f.colour, &out), StatusMentions("must be finite"));
  // The pipeline still works after all those errors.
  options.passthrough = PassThroughParams{};
  EXPECT_TRUE(pipeline.Run(options, f.disparity, f.colour, &out).ok());
}

TEST(Validation, OneByOneAndOddFramesWork) {
  for (auto [w, h] : {std::pair{1u, 1u}, {1u, 7u}, {7u, 1u}, {3u, 5u}, {641u, 479u}}) {
    auto f = MakeFrame(w, h, DisparityEncoding::kU8, ColorEncoding::kMono8);
    for (std::uint32_t v = 0; v < h; ++v)
      for (std::uint32_t u = 0; u < w; ++u) SetSample<std::uint8_t>(f, u, v, 100);
    CameraModel camera = CameraModel::PclCompatible(w, h, 615);
    PointCloud organized;
    ASSERT_TRUE(ConvertToOrganized(camera, f.disparity, f.colour, &organized).ok());
    ASSERT_EQ(organized.width, w);
    ASSERT_EQ(organized.height, h);
    // Pixel (u, v) lands at x = (u - w/2) z / f: rows and columns do not slip at odd sizes.
    const Point& last = organized.points.back();
    EXPECT_FLOAT_EQ(last.z, 6.15f);
    EXPECT_FLOAT_EQ(last.x, (static_cast<float>(w - 1) - static_cast<float>(w / 2)) * 6.15f / 615);
    EXPECT_FLOAT_EQ(last.y, (static_cast<float>(h - 1) - static_cast<float>(h / 2)) * 6.15f / 615);
    Pipeline pipeline;
    PipelineOptions options;
    options.camera = camera;
    PointCloud fused;
    StageCounts counts;
    ASSERT_TRUE(pipeline.Run(options, f.disparity, f.colour, &fused, &counts).ok());
    EXPECT_EQ(counts.valid_points, std::uint64_t{w} * h);
    EXPECT_GE(fused.size(), 1u);
  }
}

TEST(Conversion, FormulaAndInvalidValues) {
  auto f = MakeFrame(4, 2, DisparityEncoding::kU16, ColorEncoding::kRGB8);
  SetSample<std::uint16_t>(f, 0, 0, 0);      // invalid: 0
  SetSample<std::uint16_t>(f, 1, 0, 0x7FF);  // invalid: 2047
  SetSample<std::uint16_t>(f, 2, 0, 160);
  SetSample<std::uint16_t>(f, 3, 1, 320);
  f.colour_bytes[3 * 2 + 0] = 200;  // pixel (2, 0): r
  f.colour_bytes[3 * 2 + 1] = 100;
  f.colour_bytes[3 * 2 + 2] = 50;
  CameraModel camera;
  camera.fx = 400;
  camera.fy = 200;
  camera.cx = 1.5;
  camera.cy = 0.25;
  camera.baseline = 0.1;
  camera.disparity_scale = 1.0 / 16.0;
  PointCloud out;
  ASSERT_TRUE(ConvertToOrganized(camera, f.disparity, f.colour, &out).ok());
  EXPECT_TRUE(std::isnan(out.points[0].z));
  EXPECT_TRUE(std::isnan(out.points[1].z));
  EXPECT_EQ(out.points[0].rgba, 0u);
  const Point& p = out.points[2];
  EXPECT_FLOAT_EQ(p.z, 400 * 0.1 / 10.0);  // d' = 160/16 = 10
  EXPECT_FLOAT_EQ(p.x, (2 - 1.5) * 4.0 / 400);
  EXPECT_FLOAT_EQ(p.y, (0 - 0.25) * 4.0 / 200);
  EXPECT_EQ(p.rgba, PackRgba(200, 100, 50, 255));
  EXPECT_FLOAT_EQ(out.points[7].z, 2.0f);
  // A negative offset that makes d' <= 0 is invalid, not a point behind the camera.
  camera.disparity_offset = -10.0;
  ASSERT_TRUE(ConvertToOrganized(camera, f.disparity, f.colour, &out).ok());
  EXPECT_TRUE(std::isnan(out.points[2].z));
  EXPECT_FLOAT_EQ(out.points[7].z, 4.0f);
}

TEST(Conversion, ColourEncodingsAgree) {
  // The same pixels in four encodings give the same points (mono: grey).
  auto bgr = MakeFrame(3, 1, DisparityEncoding::kF32, ColorEncoding::kBGR8);
  auto rgb = MakeFrame(3, 1, DisparityEncoding::kF32, ColorEncoding::kRGB8);
  auto rgba = MakeFrame(3, 1, DisparityEncoding::kF32, ColorEncoding::kRGBA8);
  for (std::uint32_t u = 0; u < 3; ++u) {
    for (auto* f : {&bgr, &rgb, &rgba}) SetSample<float>(*f, u, 0, 10.5f + u);
    const std::uint8_t r = 10 + u, g = 20 + u, b = 30 + u;
    bgr.colour_bytes[3 * u] = b, bgr.colour_bytes[3 * u + 1] = g, bgr.colour_bytes[3 * u + 2] = r;
    rgb.colour_bytes[3 * u] = r, rgb.colour_bytes[3 * u + 1] = g, rgb.colour_bytes[3 * u + 2] = b;
    rgba.colour_bytes[4 * u] = r, rgba.colour_bytes[4 * u + 1] = g;
    rgba.colour_bytes[4 * u + 2] = b, rgba.colour_bytes[4 * u + 3] = 7;  // alpha ignored
  }
  const CameraModel camera = CameraModel::PclCompatible(3, 1);
  PointCloud a, b, c;
  ASSERT_TRUE(ConvertToOrganized(camera, bgr.disparity, bgr.colour, &a).ok());
  ASSERT_TRUE(ConvertToOrganized(camera, rgb.disparity, rgb.colour, &b).ok());
  ASSERT_TRUE(ConvertToOrganized(camera, rgba.disparity, rgba.colour, &c).ok());
  EXPECT_TRUE(CloudsIdentical(a, b));
  EXPECT_TRUE(CloudsIdentical(a, c));
  EXPECT_EQ(a.points[1].rgba, PackRgba(11, 21, 31));
}

TEST(PassThrough, InclusiveLimitsNegativeModeAndNonFinite) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  const PointCloud in = CloudOf({{0, 0, 3.0f, 1},
                                 {0, 0, 12.0f, 2},
                                 {0, 0, 2.999999f, 3},
                                 {0, 0, 12.00001f, 4},
                                 {nan, 0, 5.0f, 5},
                                 {0, inf, 5.0f, 6},
                                 {0, 0, 7.0f, 7}});
  PointCloud out;
  PassThroughParams p;
  ASSERT_TRUE(PassThrough(in, p, &out).ok());
  ASSERT_EQ(out.size(), 3u);
  EXPECT_EQ(out.points[0].rgba, 1u);
  EXPECT_EQ(out.points[1].rgba, 2u);
  EXPECT_EQ(out.points[2].rgba, 7u);
  p.negative = true;
  ASSERT_TRUE(PassThrough(in, p, &out).ok());
  ASSERT_EQ(out.size(), 2u);  // outside [3, 12], finite only
  EXPECT_EQ(out.points[0].rgba, 3u);
  EXPECT_EQ(out.points[1].rgba, 4u);
  p.enabled = false;
  ASSERT_TRUE(PassThrough(in, p, &out).ok());
  EXPECT_EQ(out.size(), 5u);  // only the non-finite removed
  p = PassThroughParams{};
  p.axis = Axis::kY;
  p.min = -1;
  p.max = 1;
  ASSERT_TRUE(PassThrough(in, p, &out).ok());
  EXPECT_EQ(out.size(), 5u);
  EXPECT_THAT(PassThrough(in, p, const_cast<PointCloud*>(&in)), StatusMentions("alias"));
}

TEST(VoxelGrid, CentroidAndTruncatedMeanColour) {
  const PointCloud in = CloudOf({{0.01f, 0.01f, 0.01f, PackRgba(10, 20, 30)},
                                 {0.02f, 0.02f, 0.02f, PackRgba(11, 21, 30)},
                                 {0.04f, 0.01f, 0.01f, PackRgba(1, 2, 3)},
                                 {-0.01f, 0.01f, 0.01f, PackRgba(5, 5, 5)}});
  VoxelGrid grid;
  PointCloud out;
  VoxelGridParams p;
  ASSERT_TRUE(grid.Filter(in, p, &out).ok());
  ASSERT_EQ(out.size(), 3u);
  EXPECT_FLOAT_EQ(out.points[0].x, 0.015f);
  EXPECT_EQ(out.points[0].rgba, PackRgba(10, 20, 30));  // (10+11)/2 = 10.5 -> 10
  EXPECT_EQ(out.points[1].rgba, PackRgba(1, 2, 3));
  EXPECT_FLOAT_EQ(out.points[2].x, -0.01f);  // floor(-0.33) = -1: its own voxel
  p.min_points_per_voxel = 2;
  ASSERT_TRUE(grid.Filter(in, p, &out).ok());
  EXPECT_EQ(out.size(), 1u);
}

TEST(VoxelGrid, KeyOrderIsPclOrder) {
  // Voxels (x, y, z indices) first met as (0, 0, 0), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, 0, -1),
  // (-1, 1, 0); PCL's order is by z, then y, then x.
  const PointCloud in = CloudOf({{0.01f, 0.01f, 0.01f, PackRgba(1, 1, 1)},
                                 {0.04f, 0.01f, 0.01f, PackRgba(2, 2, 2)},
                                 {-0.01f, 0.01f, 0.01f, PackRgba(3, 3, 3)},
                                 {0.01f, 0.04f, 0.01f, PackRgba(4, 4, 4)},
                                 {0.02f, 0.02f, 0.02f, PackRgba(1, 1, 1)},
                                 {0.01f, 0.01f, -0.01f, PackRgba(5, 5, 5)},
                                 {-0.02f, 0.05f, 0.02f, PackRgba(6, 6, 6)}});
  VoxelGrid grid;
  PointCloud out;
  VoxelGridParams p;
  p.key_order = true;
  ASSERT_TRUE(grid.Filter(in, p, &out).ok());
  std::vector<int> reds;
  for (const Point& q : out.points) reds.push_back(RedOf(q.rgba));
  EXPECT_THAT(reds, ::testing::ElementsAre(5, 3, 1, 2, 6, 4));
  p.min_points_per_voxel = 2;  // only voxel (0, 0, 0) keeps its point
  ASSERT_TRUE(grid.Filter(in, p, &out).ok());
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(RedOf(out.points[0].rgba), 1);
}

TEST(VoxelGrid, MatchesBruteForceOnRandomCloudsIncludingWideKeys) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> coord(-50.0f, 50.0f);
  VoxelGrid grid;
  // The last: 1e7 voxels along x (24 bits, beyond the fast 21-bit key) but 52 bits in all.
  for (float leaf : {1.0f, 0.03f, 1e-4f, 1e-5f}) {
    PointCloud in;
    for (int i = 0; i < 20000; ++i) {
      // Clustered points so that voxels hold several points even at fine leaves.
      const float cx = coord(rng), cy = coord(rng), cz = coord(rng);
      for (int k = 0; k < 5; ++k) {
        in.points.push_back(Point{cx + k * leaf * 0.1f, cy, cz - k * leaf * 0.1f,
                                  static_cast<std::uint32_t>(rng())});
      }
    }
    in.width = static_cast<std::uint32_t>(in.size());
    in.height = 1;
    VoxelGridParams p;
    p.SetLeaf(leaf < 1e-4f ? 0.01f : leaf);
    p.leaf_x = leaf;
    PointCloud out;
    ASSERT_TRUE(grid.Filter(in, p, &out).ok()) << grid.Filter(in, p, &out);
    EXPECT_TRUE(CloudsMatch(testing::BruteForceVoxelGrid(in, p), out,
                            CloudTolerance::Equivalence(/*colour=*/0)))
        << "leaf " << leaf;
    p.key_order = true;  // 32- and 64-bit keys alike come out in (z, y, x) index order
    ASSERT_TRUE(grid.Filter(in, p, &out).ok());
    EXPECT_TRUE(CloudsMatchInOrder(testing::BruteForceVoxelGrid(in, p, /*pcl_order=*/true), out,
                                   CloudTolerance::Equivalence(/*colour=*/0)))
        << "leaf " << leaf << ", key order";
  }
}

// One VoxelGrid (and its scratch memory) reused over many clouds whose sizes, key widths and
// orders change from cloud to cloud: every result is the definition's.
TEST(VoxelGrid, ReusedOverManyDifferentClouds) {
  std::mt19937 rng(11);
  VoxelGrid grid;
  for (int round = 0; round < 300; ++round) {
    const int clusters = round % 7 == 0 ? 3000 : static_cast<int>(rng() % 200);
    const float spread = round % 5 == 0 ? 1e3f : 20.0f;  // 1e3 with leaf 1e-3: 63-bit keys
    std::uniform_real_distribution<float> coord(-spread, spread);
    PointCloud in;
    for (int i = 0; i < clusters; ++i) {
      const float cx = coord(rng), cy = coord(rng), cz = coord(rng);
      for (int k = 0; k < 4; ++k) {
        in.points.push_back(Point{cx + k * 1e-4f, cy, cz, static_cast<std::uint32_t>(rng())});
      }
    }
    in.width = static_cast<std::uint32_t>(in.size());
    in.height = 1;
    VoxelGridParams p;
    p.SetLeaf(round % 5 == 0 ? 1e-3f : 0.05f);
    p.key_order = round % 3 == 0;
    PointCloud out;
    ASSERT_TRUE(grid.Filter(in, p, &out).ok()) << "round " << round;
    const PointCloud brute = testing::BruteForceVoxelGrid(in, p, /*pcl_order=*/true);
    if (p.key_order) {
      ASSERT_TRUE(CloudsMatchInOrder(brute, out, CloudTolerance::Equivalence(/*colour=*/0)))
          << "round " << round;
    } else {
      ASSERT_TRUE(CloudsMatch(brute, out, CloudTolerance::Equivalence(/*colour=*/0)))
          << "round " << round;
    }
  }
}

TEST(VoxelGrid, RejectsExtentsBeyondSixtyFourBitKeys) {
  const PointCloud in = CloudOf({{-3e38f, -3e38f, -3e38f, 0}, {3e38f, 3e38f, 3e38f, 0}});
  VoxelGrid grid;
  PointCloud out;
  VoxelGridParams p;
  p.SetLeaf(1e-3f);
  EXPECT_THAT(grid.Filter(in, p, &out), StatusMentions("use a larger voxel.leaf"));
}

// The fused pipeline equals the three stand-alone stages, for every encoding pair and setting.
TEST(Pipeline, FusedEqualsStagedForAllEncodings) {
  std::mt19937 rng(99);
  Pipeline pipeline;
  VoxelGrid grid;
  for (auto de : {DisparityEncoding::kU8, DisparityEncoding::kU16, DisparityEncoding::kF32}) {
    for (auto ce : {ColorEncoding::kBGR8, ColorEncoding::kRGB8, ColorEncoding::kRGBA8,
                    ColorEncoding::kMono8}) {
      for (int variant = 0; variant < 4; ++variant) {
        const std::uint32_t w = 31 + rng() % 90, h = 17 + rng() % 70;  // odd sizes too
        auto f = RandomFrame(rng, w, h, de, ce, 20, 250);
        PipelineOptions o;
        o.camera = CameraModel::PclCompatible(w, h, 615);
        o.passthrough.axis = static_cast<Axis>(variant % 3);
        o.passthrough.min = variant % 3 == 2 ? 3.0f : -1.0f;
        o.passthrough.max = variant % 3 == 2 ? 12.0f : 1.0f;
        o.passthrough.negative = variant == 3;
        o.voxel.enabled = variant != 1;
        o.voxel.SetLeaf(0.05f);
        PointCloud organized, passed, staged, fused;
        StageCounts counts;
        ASSERT_TRUE(ConvertToOrganized(o.camera, f.disparity, f.colour, &organized).ok());
        ASSERT_TRUE(PassThrough(organized, o.passthrough, &passed).ok());
        ASSERT_TRUE(pipeline.Run(o, f.disparity, f.colour, &fused, &counts).ok());
        EXPECT_EQ(counts.after_passthrough, passed.size());
        if (o.voxel.enabled) {
          ASSERT_TRUE(grid.Filter(passed, o.voxel, &staged).ok());
          // Same points in the same order: both walk the image in raster order.
          EXPECT_TRUE(CloudsIdentical(staged, fused));
          o.voxel.key_order = true;  // and both sort the same voxels the same way
          ASSERT_TRUE(grid.Filter(passed, o.voxel, &staged).ok());
          ASSERT_TRUE(pipeline.Run(o, f.disparity, f.colour, &fused).ok());
          EXPECT_TRUE(CloudsIdentical(staged, fused)) << "key order";
        } else {
          EXPECT_TRUE(CloudsIdentical(passed, fused));
        }
        EXPECT_EQ(counts.after_voxel, fused.size());
      }
    }
  }
}

// A leaf so fine that voxel indices leave the fast 21-bit key: the fused pipeline falls back to
// the general path and still agrees with the definition.
TEST(Pipeline, FallsBackToWideKeys) {
  std::mt19937 rng(5);
  auto f = RandomFrame(rng, 64, 48, DisparityEncoding::kU8, ColorEncoding::kBGR8, 20, 250);
  PipelineOptions o;
  o.camera = CameraModel::PclCompatible(64, 48);
  o.voxel.SetLeaf(2e-5f);  // z up to 30.75: index 1.5e6 > 2^20, yet 57 bits in all
  o.passthrough.enabled = false;
  Pipeline pipeline;
  PointCloud fused, organized, passed;
  StageCounts counts;
  ASSERT_TRUE(pipeline.Run(o, f.disparity, f.colour, &fused, &counts).ok())
      << pipeline.Run(o, f.disparity, f.colour, &fused, &counts);
  ASSERT_TRUE(ConvertToOrganized(o.camera, f.disparity, f.colour, &organized).ok());
  ASSERT_TRUE(PassThrough(organized, o.passthrough, &passed).ok());
  EXPECT_EQ(counts.valid_points, passed.size());
  EXPECT_TRUE(CloudsMatch(testing::BruteForceVoxelGrid(passed, o.voxel), fused,
                          CloudTolerance::Equivalence(/*colour=*/0)));
}

// The server's downlink cap drops the voxels of fewest points from a cloud already made
// (RefilterVoxels): the cloud must be the one a Run with that minimum gives, point for point,
// on every path (banded and whole, first-seen and key order, 32- and 64-bit keys).
TEST(Pipeline, RefilterVoxelsEqualsARunWithThatMinimum) {
  std::mt19937 rng(11);
  Pipeline pipeline;
  for (auto de : {DisparityEncoding::kU8, DisparityEncoding::kU16, DisparityEncoding::kF32}) {
    for (const auto& [w, h, leaf] : {std::tuple{640u, 480u, 0.03f}, std::tuple{53u, 31u, 0.05f},
                                     std::tuple{64u, 48u, 2e-5f}}) {
      for (bool key_order : {false, true}) {
        auto f = RandomFrame(rng, w, h, de, ColorEncoding::kBGR8, 20, 250);
        PipelineOptions o;
        o.camera = CameraModel::PclCompatible(w, h, 615);
        o.passthrough.enabled = leaf > 1e-3f;
        o.voxel.SetLeaf(leaf);
        o.voxel.key_order = key_order;
        o.voxel.min_points_per_voxel = 1;
        PointCloud all, refiltered, direct;
        ASSERT_TRUE(pipeline.Run(o, f.disparity, f.colour, &all).ok());
        for (std::uint32_t k : {2u, 3u, 1u, 5u}) {
          SCOPED_TRACE(::testing::Message() << w << "x" << h << " leaf " << leaf << " key order "
                                            << key_order << " min " << k);
          ASSERT_TRUE(pipeline.RefilterVoxels(k, &refiltered).ok());
          o.voxel.min_points_per_voxel = k;
          Pipeline fresh;
          ASSERT_TRUE(fresh.Run(o, f.disparity, f.colour, &direct).ok());
          EXPECT_TRUE(CloudsIdentical(direct, refiltered));
          EXPECT_LE(refiltered.size(), all.size());
          if (k == 1) {
            EXPECT_TRUE(CloudsIdentical(all, refiltered));
          } else if (leaf > 1e-3f && k == 2) {  // some voxels hold one point, some more
            EXPECT_LT(refiltered.size(), all.size());
            EXPECT_GT(refiltered.size(), 0u);
          }
        }
        EXPECT_GT(all.size(), 0u);
      }
    }
  }
}

TEST(Pipeline, RefilterVoxelsNeedsTheLastRunsVoxels) {
  std::mt19937 rng(3);
  auto f = RandomFrame(rng, 64, 48, DisparityEncoding::kU8, ColorEncoding::kBGR8, 20, 250);
  PipelineOptions o;
  o.camera = CameraModel::PclCompatible(64, 48);
  Pipeline pipeline;
  PointCloud out;
  EXPECT_EQ(pipeline.RefilterVoxels(2, &out).code(), absl::StatusCode::kFailedPrecondition);
  ASSERT_TRUE(pipeline.Run(o, f.disparity, f.colour, &out).ok());
  EXPECT_TRUE(pipeline.RefilterVoxels(2, &out).ok());
  o.voxel.enabled = false;  // a run without the grid holds no voxels
  ASSERT_TRUE(pipeline.Run(o, f.disparity, f.colour, &out).ok());
  EXPECT_EQ(pipeline.RefilterVoxels(2, &out).code(), absl::StatusCode::kFailedPrecondition);
  o.voxel.enabled = true;
  ASSERT_TRUE(pipeline.Run(o, f.disparity, f.colour, &out).ok());
  o.camera.fx = -1;  // nor does a run that failed
  EXPECT_FALSE(pipeline.Run(o, f.disparity, f.colour, &out).ok());
  EXPECT_EQ(pipeline.RefilterVoxels(2, &out).code(), absl::StatusCode::kFailedPrecondition);
}

}  // namespace
}  // namespace cloudcast
