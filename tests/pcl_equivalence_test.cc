// cloudcast against stock PCL 1.13, stage by stage and for the whole chain: on the ten real
// New Tsukuba frames and on randomised frames (encodings, sizes, leaves, axes, limits).
#include <gtest/gtest.h>
#include <pcl/common/common.h>
#include <pcl/common/point_tests.h>

#include <random>

#include "cloudcast/core/camera.h"
#include "cloudcast/core/filters.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/io/image_io.h"
#include "cloudcast/reference/pcl_reference.h"
#include "support/test_support.h"

namespace cloudcast {
namespace {

using reference::FromPcl;
using reference::PclCloud;
using reference::ToPcl;
using testing::CloudsIdentical;
using testing::CloudsMatch;
using testing::CloudsMatchInOrder;
using testing::CloudTolerance;

// PCL VoxelGrid's own test (voxel_grid.hpp): it gives up when the voxel count along the bounding
// box exceeds INT32_MAX. PCL computes it with int64 casts and products that overflow for huge
// boxes (and an empty cloud's inverted one), which x86 resolves as below: a float out of int64's
// range becomes INT64_MIN (cvttss2si), and products wrap. Spelled out here, so that this model of
// PCL has no undefined behaviour of its own (UBSan found the overflow).
std::int64_t X86FloatToInt64(float v) {
  constexpr float kTwo63 = 9223372036854775808.0f;
  if (!(v >= -kTwo63 && v < kTwo63)) return std::numeric_limits<std::int64_t>::min();
  return static_cast<std::int64_t>(v);
}

bool PclGivesUp(const PclCloud& cloud, const VoxelGridParams& p) {
  Eigen::Vector4f lo, hi;
  pcl::getMinMax3D(cloud, lo, hi);
  const float inv[3] = {1.0f / p.leaf_x, 1.0f / p.leaf_y, 1.0f / p.leaf_z};
  std::uint64_t n = 1;
  for (int a = 0; a < 3; ++a) {
    n *= static_cast<std::uint64_t>(X86FloatToInt64((hi[a] - lo[a]) * inv[a])) + 1u;
  }
  return static_cast<std::int64_t>(n) >
         static_cast<std::int64_t>(std::numeric_limits<std::int32_t>::max());
}

struct Chain {
  PointCloud organized, passed, voxel, fused;
  StageCounts counts;
};

// Runs PCL's three stages and ours (stand-alone and fused) on one frame and checks that every
// stage agrees. PCL's conversion only takes integer disparities; a float frame is compared through
// its float-depth overload, fed with our depths.
// Returns true when PCL's voxel grid gave up (and ours was checked against the definition).
bool ExpectSameAsPcl(const DisparityView& disparity, const ColorView& colour,
                     const CameraModel& camera, const PassThroughParams& pass,
                     const VoxelGridParams& voxel, const std::string& what) {
  SCOPED_TRACE(what);
  // --- PCL ---
  reference::PclFrame pf;
  PclCloud pcl_organized;
  if (disparity.encoding == DisparityEncoding::kF32) {
    // Same layout helper, then depths: z = fx*B / (d*s + o) exactly as ours (see camera.h).
    DisparityView as_u8 = disparity;  // MakePclFrame only needs the colour here
    std::vector<std::uint8_t> zeros(std::size_t{disparity.width} * disparity.height, 0);
    as_u8 = DisparityView{zeros.data(),     zeros.size(),    disparity.width,
                          disparity.height, disparity.width, DisparityEncoding::kU8};
    pf = reference::MakePclFrame(as_u8, colour);
    std::vector<float> depth(zeros.size(), 0.0f);
    const float fxb = static_cast<float>(camera.fx * camera.baseline);
    for (std::uint32_t v = 0; v < disparity.height; ++v) {
      for (std::uint32_t u = 0; u < disparity.width; ++u) {
        float d;
        std::memcpy(&d, disparity.row(v) + 4 * u, 4);
        bool invalid = !std::isfinite(d);
        for (double x : camera.invalid_disparities) invalid |= d == static_cast<float>(x);
        const float den = d * static_cast<float>(camera.disparity_scale) +
                          static_cast<float>(camera.disparity_offset);
        if (!invalid && den > 0.0f && std::isfinite(fxb / den)) {
          depth[std::size_t{v} * disparity.width + u] = fxb / den;
        }
      }
    }
    reference::PclConvertDepth(depth, pf, static_cast<float>(camera.fx), pcl_organized);
  } else {
    pf = reference::MakePclFrame(disparity, colour);
    reference::PclConvert(pf, static_cast<float>(camera.fx),
                          static_cast<float>(camera.disparity_offset),
                          static_cast<float>(camera.disparity_scale), pcl_organized);
  }
  PclCloud::Ptr pcl_organized_ptr(new PclCloud(pcl_organized));
  PclCloud::Ptr pcl_passed(new PclCloud);
  reference::PclPassThrough(pcl_organized_ptr, pass, *pcl_passed);
  PclCloud pcl_voxel;
  if (voxel.enabled) reference::PclVoxelGrid(pcl_passed, voxel, pcl_voxel);

  // --- cloudcast ---
  Chain ours;
  auto ok = [](const absl::Status& s) {
    EXPECT_TRUE(s.ok()) << s;
    return s.ok();
  };
  if (!ok(ConvertToOrganized(camera, disparity, colour, &ours.organized))) return false;
  if (!ok(PassThrough(ours.organized, pass, &ours.passed))) return false;
  VoxelGrid grid;
  if (voxel.enabled && !ok(grid.Filter(ours.passed, voxel, &ours.voxel))) return false;
  Pipeline pipeline;
  PipelineOptions options;
  options.camera = camera;
  options.passthrough = pass;
  options.voxel = voxel;
  if (!ok(pipeline.Run(options, disparity, colour, &ours.fused, &ours.counts))) return false;

  // Conversion and passthrough keep PCL's order and float arithmetic: bit for bit.
  EXPECT_TRUE(CloudsIdentical(FromPcl(pcl_organized), ours.organized)) << "conversion";
  EXPECT_TRUE(CloudsIdentical(FromPcl(*pcl_passed), ours.passed)) << "passthrough";
  bool pcl_gave_up = false;
  std::size_t expected_voxels = voxel.enabled ? pcl_voxel.size() : pcl_passed->size();
  if (voxel.enabled && PclGivesUp(*pcl_passed, voxel)) {
    // PCL's 32-bit voxel indices would overflow: it returns its input. We still downsample;
    // check against the definition.
    EXPECT_EQ(pcl_voxel.size(), pcl_passed->size());
    const PointCloud brute = testing::BruteForceVoxelGrid(ours.passed, voxel);
    EXPECT_TRUE(CloudsMatch(brute, ours.voxel, CloudTolerance::Equivalence(/*colour=*/0)))
        << "voxel grid (PCL overflowed)";
    EXPECT_TRUE(CloudsMatch(brute, ours.fused, CloudTolerance::Equivalence(/*colour=*/0)))
        << "fused chain (PCL overflowed)";
    expected_voxels = brute.size();
    pcl_gave_up = true;
  } else if (voxel.enabled) {
    // PCL sums voxel points in float in sort order; ours in double: compare within tolerance.
    EXPECT_TRUE(CloudsMatch(FromPcl(pcl_voxel), ours.voxel, CloudTolerance::Equivalence()))
        << "voxel grid";
    EXPECT_TRUE(CloudsMatch(FromPcl(pcl_voxel), ours.fused, CloudTolerance::Equivalence()))
        << "fused chain";
  } else {
    EXPECT_TRUE(CloudsIdentical(FromPcl(*pcl_passed), ours.fused)) << "fused chain, no voxels";
  }
  if (voxel.enabled) {
    // In key order, the voxels come out in PCL's own order: point by point.
    VoxelGridParams in_key_order = voxel;
    in_key_order.key_order = true;
    PointCloud sorted, fused_sorted;
    if (!ok(grid.Filter(ours.passed, in_key_order, &sorted))) return false;
    options.voxel = in_key_order;
    if (!ok(pipeline.Run(options, disparity, colour, &fused_sorted))) return false;
    if (pcl_gave_up) {
      const PointCloud brute = testing::BruteForceVoxelGrid(ours.passed, voxel, /*pcl_order=*/true);
      EXPECT_TRUE(CloudsMatchInOrder(brute, sorted, CloudTolerance::Equivalence(/*colour=*/0)))
          << "voxel grid, key order";
      EXPECT_TRUE(
          CloudsMatchInOrder(brute, fused_sorted, CloudTolerance::Equivalence(/*colour=*/0)))
          << "fused chain, key order";
    } else {
      EXPECT_TRUE(CloudsMatchInOrder(FromPcl(pcl_voxel), sorted, CloudTolerance::Equivalence()))
          << "voxel grid, key order";
      EXPECT_TRUE(
          CloudsMatchInOrder(FromPcl(pcl_voxel), fused_sorted, CloudTolerance::Equivalence()))
          << "fused chain, key order";
    }
  }
  std::uint64_t finite = 0;
  for (const auto& p : pcl_organized) finite += pcl::isFinite(p) ? 1 : 0;
  EXPECT_EQ(ours.counts.valid_points, finite);
  EXPECT_EQ(ours.counts.after_passthrough, pcl_passed->size());
  EXPECT_EQ(ours.counts.after_voxel, expected_voxels);
  return pcl_gave_up;
}

struct Tsukuba {
  OwnedDisparity disparity;
  OwnedColor colour;
};
Tsukuba LoadTsukuba(const std::string& id) {
  auto d = LoadDisparity(testing::TsukubaDisparityPath(id));
  auto c = LoadColor(testing::TsukubaColourPath(id));
  EXPECT_TRUE(d.ok()) << d.status();
  EXPECT_TRUE(c.ok()) << c.status();
  return Tsukuba{d.ok() ? *std::move(d) : OwnedDisparity{}, c.ok() ? *std::move(c) : OwnedColor{}};
}

class TsukubaEquivalence : public ::testing::TestWithParam<std::string> {};

TEST_P(TsukubaEquivalence, PaperParametersMatchPcl) {
  CLOUDCAST_REQUIRE_TSUKUBA();
  const Tsukuba t = LoadTsukuba(GetParam());
  ASSERT_EQ(t.disparity.width, 640u);
  ExpectSameAsPcl(t.disparity.view(), t.colour.view(), CameraModel::PclCompatible(640, 480),
                  PassThroughParams{}, VoxelGridParams{}, "frame " + GetParam());
}

TEST_P(TsukubaEquivalence, OtherStageSettingsMatchPcl) {
  CLOUDCAST_REQUIRE_TSUKUBA();
  const Tsukuba t = LoadTsukuba(GetParam());
  const CameraModel camera = CameraModel::PclCompatible(640, 480);
  PassThroughParams x_axis;
  x_axis.axis = Axis::kX;
  x_axis.min = -2.0f;
  x_axis.max = 1.5f;
  VoxelGridParams coarse;
  coarse.SetLeaf(0.1f);
  coarse.min_points_per_voxel = 3;
  ExpectSameAsPcl(t.disparity.view(), t.colour.view(), camera, x_axis, coarse, "x axis");
  PassThroughParams negative;
  negative.negative = true;
  negative.min = 5.0f;
  negative.max = 9.0f;
  VoxelGridParams anisotropic;
  anisotropic.leaf_x = 0.05f;
  anisotropic.leaf_y = 0.02f;
  anisotropic.leaf_z = 0.08f;
  ExpectSameAsPcl(t.disparity.view(), t.colour.view(), camera, negative, anisotropic, "negative z");
  VoxelGridParams off;
  off.enabled = false;
  ExpectSameAsPcl(t.disparity.view(), t.colour.view(), camera, PassThroughParams{}, off,
                  "no voxel grid");
}

INSTANTIATE_TEST_SUITE_P(AllFrames, TsukubaEquivalence,
                         ::testing::ValuesIn(testing::TsukubaFrameIds()));

// Frame 01200 without the passthrough spans more than 2^31 voxels of 3 cm: PCL gives up and
// returns its input; we still downsample, and agree with the brute-force definition.
TEST(OverflowCase, Frame01200WithoutPassthrough) {
  CLOUDCAST_REQUIRE_TSUKUBA();
  const Tsukuba t = LoadTsukuba("01200");
  const CameraModel camera = CameraModel::PclCompatible(640, 480);
  PassThroughParams off;
  off.enabled = false;
  const VoxelGridParams voxel;

  reference::PclFrame pf = reference::MakePclFrame(t.disparity.view(), t.colour.view());
  PclCloud::Ptr organized(new PclCloud);
  reference::PclConvert(pf, 615.0f, 0.0f, 1.0f, *organized);
  PclCloud pcl_voxel;
  reference::PclVoxelGrid(organized, voxel, pcl_voxel);
  EXPECT_EQ(pcl_voxel.size(), organized->size()) << "PCL is expected to give up here";

  PointCloud ours_organized, ours_voxel, fused;
  ASSERT_TRUE(
      ConvertToOrganized(camera, t.disparity.view(), t.colour.view(), &ours_organized).ok());
  VoxelGrid grid;
  ASSERT_TRUE(grid.Filter(ours_organized, voxel, &ours_voxel).ok());
  const PointCloud brute = testing::BruteForceVoxelGrid(ours_organized, voxel);
  EXPECT_LT(brute.size(), organized->size());  // really downsampled (about 80% remain: far
                                               // surfaces are sparse at 3 cm)
  EXPECT_TRUE(CloudsMatch(brute, ours_voxel, CloudTolerance::Equivalence(/*colour=*/0)));
  Pipeline pipeline;
  PipelineOptions options;
  options.passthrough = off;
  StageCounts counts;
  ASSERT_TRUE(pipeline.Run(options, t.disparity.view(), t.colour.view(), &fused, &counts).ok());
  EXPECT_TRUE(CloudsMatch(brute, fused, CloudTolerance::Equivalence(/*colour=*/0)));
  EXPECT_EQ(counts.valid_points, 640u * 480u);
}

// Random frames: every disparity and colour encoding, sizes, scales, offsets, leaves, axes,
// limits and negative mode, against PCL.
class RandomEquivalence : public ::testing::TestWithParam<int> {};

TEST_P(RandomEquivalence, MatchesPcl) {
  std::mt19937 rng(1234 + GetParam());
  const DisparityEncoding encodings[] = {DisparityEncoding::kU8, DisparityEncoding::kU16,
                                         DisparityEncoding::kF32};
  const ColorEncoding colours[] = {ColorEncoding::kBGR8, ColorEncoding::kRGB8,
                                   ColorEncoding::kRGBA8, ColorEncoding::kMono8};
  const float leaves[] = {0.005f, 0.01f, 0.03f, 0.1f, 0.5f};
  int pcl_gave_up = 0;
  constexpr int kRounds = 6;
  for (int round = 0; round < kRounds; ++round) {
    const DisparityEncoding de = encodings[rng() % 3];
    const ColorEncoding ce = colours[rng() % 4];
    // PCL's organized conversion is defined for even sizes only (odd sizes slip rows).
    const std::uint32_t w = 2 * (1 + rng() % 160), h = 2 * (1 + rng() % 120);
    CameraModel camera = CameraModel::PclCompatible(w, h, 300.0 + rng() % 700);
    double raw_min = 1, raw_max = 255;
    if (de == DisparityEncoding::kU16) {
      camera.disparity_scale = (rng() % 2) ? 1.0 / 16.0 : 1.0;
      camera.disparity_offset = (rng() % 2) ? 0.0 : 0.5;
      raw_max = camera.disparity_scale < 1.0 ? 4000 : 2100;  // includes 0x7FF sometimes
    } else if (de == DisparityEncoding::kF32) {
      camera.disparity_scale = 0.5 + (rng() % 100) / 100.0;
      raw_min = 0.5;
      raw_max = 300;
    }
    std::mt19937 frame_rng(rng());
    testing::TestFrame f = testing::RandomFrame(frame_rng, w, h, de, ce, raw_min, raw_max);
    if (de == DisparityEncoding::kU16 && w > 4) {
      testing::SetSample<std::uint16_t>(f, 1, 0, 0x7FF);  // PCL's other invalid value
    }
    PassThroughParams pass;
    pass.axis = static_cast<Axis>(rng() % 3);
    const float z_scale = static_cast<float>(camera.fx / (raw_max * camera.disparity_scale));
    if (pass.axis == Axis::kZ) {
      pass.min = z_scale * (1.0f + (rng() % 100) / 50.0f);
      pass.max = pass.min + z_scale * (rng() % 200) / 20.0f;
    } else {
      pass.min = -z_scale * (rng() % 100) / 100.0f;
      pass.max = pass.min + z_scale * (rng() % 100) / 50.0f;
    }
    pass.negative = rng() % 4 == 0;
    pass.enabled = rng() % 6 != 0;
    VoxelGridParams voxel;
    voxel.leaf_x = leaves[rng() % 5] * z_scale;
    voxel.leaf_y = (rng() % 2) ? voxel.leaf_x : leaves[rng() % 5] * z_scale;
    voxel.leaf_z = (rng() % 2) ? voxel.leaf_x : leaves[rng() % 5] * z_scale;
    voxel.min_points_per_voxel = rng() % 4;
    pcl_gave_up += ExpectSameAsPcl(f.disparity, f.colour, camera, pass, voxel,
                                   "seed " + std::to_string(GetParam()) + " round " +
                                       std::to_string(round) + " " + std::string(Name(de)) + "/" +
                                       std::string(Name(ce)) + " " + std::to_string(w) + "x" +
                                       std::to_string(h) + " axis " + std::string(Name(pass.axis)));
  }
  // Most rounds must be compared with PCL itself, not only with the brute-force definition.
  EXPECT_LE(pcl_gave_up, kRounds / 2);
}

INSTANTIATE_TEST_SUITE_P(Seeds, RandomEquivalence, ::testing::Range(0, 20));

}  // namespace
}  // namespace cloudcast
