// The stereo module: parameter checks, our semi-global matcher on pairs with known disparities,
// its SIMD code against its scalar code bit for bit, the OpenCV modes against OpenCV called
// directly, grey conversion, and the rectifier on a synthetic calibration.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <string>
#include <vector>

#include "cloudcast/core/filters.h"
#include "cloudcast/stereo/evaluation.h"
#include "cloudcast/stereo/grey.h"
#include "cloudcast/stereo/matcher.h"
#include "cloudcast/stereo/rectifier.h"
#include "speckle.h"  // stereo/src: the speckle filter, against cv::filterSpeckles
#include "support/stereo_support.h"

namespace cloudcast::stereo {
namespace {

using cloudcast::testing::GreyOf;
using cloudcast::testing::MatOf;
using cloudcast::testing::ShiftedPair;
using cloudcast::testing::Texture;
using ::testing::HasSubstr;

std::unique_ptr<Matcher> Make(const StereoParams& p, SimdLevel simd = SimdLevel::kAuto) {
  auto m = MakeMatcher(p, simd);
  EXPECT_TRUE(m.ok()) << m.status();
  return m.ok() ? *std::move(m) : nullptr;
}

DisparityMap16 Match(Matcher& m, const GreyImage& left, const GreyImage& right) {
  DisparityMap16 out;
  const absl::Status s = m.Compute(left.view(), right.view(), &out);
  EXPECT_TRUE(s.ok()) << s;
  return out;
}

std::vector<SimdLevel> SimdLevelsHere() {
  std::vector<SimdLevel> levels;
  for (SimdLevel l : {SimdLevel::kAvx2, SimdLevel::kAvx512}) {
    if (CpuSupports(l)) levels.push_back(l);
  }
  return levels;
}

// ---- parameters ---------------------------------------------------------------------------------

TEST(StereoParams, DefaultsAreValidForEveryKind) {
  for (StereoMatcher k :
       {StereoMatcher::kSgm, StereoMatcher::kOpenCvSgbm, StereoMatcher::kOpenCvSgbm3Way,
        StereoMatcher::kOpenCvHH, StereoMatcher::kOpenCvBm}) {
    StereoParams p;
    p.matcher = k;
    EXPECT_TRUE(p.Validate().ok()) << Name(k) << ": " << p.Validate();
  }
}

TEST(StereoParams, ErrorsNameTheField) {
  struct Case {
    const char* expect;
    void (*set)(StereoParams*);
  };
  const Case cases[] = {
      {"config.stereo.num_disparities is 100; it must be a positive multiple of 16",
       [](StereoParams* p) { p->num_disparities = 100; }},
      {"config.stereo.num_disparities is 0", [](StereoParams* p) { p->num_disparities = 0; }},
      {"config.stereo.num_disparities is 4096", [](StereoParams* p) { p->num_disparities = 4096; }},
      {"config.stereo.min_disparity is 2000", [](StereoParams* p) { p->min_disparity = 2000; }},
      {"config.stereo.block_size is 4; it must be odd", [](StereoParams* p) { p->block_size = 4; }},
      {"config.stereo.block_size is 9; the sgm matcher's census window is 3, 5 or 7",
       [](StereoParams* p) { p->block_size = 9; }},
      {"config.stereo.block_size is 3; OpenCV's StereoBM (bm) needs >= 5",
       [](StereoParams* p) {
         p->matcher = StereoMatcher::kOpenCvBm;
         p->block_size = 3;
       }},
      {"config.stereo.p2 is 40", [](StereoParams* p) { p->p2 = 40; }},
      {"config.stereo.p2 is 2",
       [](StereoParams* p) {
         p->p1 = 3;
         p->p2 = 2;
       }},
      {"config.stereo.p1 is 19", [](StereoParams* p) { p->p1 = 19; }},
      {"config.stereo.p1 is -1",
       [](StereoParams* p) {
         p->matcher = StereoMatcher::kOpenCvSgbm;
         p->p1 = -1;
       }},
      {"config.stereo.uniqueness_ratio is 100", [](StereoParams* p) { p->uniqueness_ratio = 100; }},
      {"config.stereo.speckle_window_size is -1",
       [](StereoParams* p) { p->speckle_window_size = -1; }},
      {"config.stereo.speckle_range is -2", [](StereoParams* p) { p->speckle_range = -2; }},
      {"config.stereo.disp12_max_diff is 5000", [](StereoParams* p) { p->disp12_max_diff = 5000; }},
      {"config.stereo.paths is 6; it must be 4 or 8", [](StereoParams* p) { p->paths = 6; }},
  };
  for (const Case& c : cases) {
    StereoParams p;
    c.set(&p);
    const absl::Status s = p.Validate("config.stereo");
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << c.expect << ": " << s;
    EXPECT_THAT(std::string(s.message()), HasSubstr(c.expect));
  }
}

TEST(StereoParams, MakeMatcherRefusesInvalidParams) {
  StereoParams p;
  p.num_disparities = 20;
  auto m = MakeMatcher(p);
  ASSERT_FALSE(m.ok());
  EXPECT_THAT(std::string(m.status().message()), HasSubstr("stereo.num_disparities is 20"));
}

TEST(StereoParams, NamesRoundTrip) {
  for (StereoMatcher k :
       {StereoMatcher::kSgm, StereoMatcher::kOpenCvSgbm, StereoMatcher::kOpenCvSgbm3Way,
        StereoMatcher::kOpenCvHH, StereoMatcher::kOpenCvBm}) {
    StereoMatcher back{};
    ASSERT_TRUE(ParseStereoMatcher(Name(k), &back)) << Name(k);
    EXPECT_EQ(back, k);
  }
  EXPECT_EQ(Name(StereoMatcher::kOpenCvSgbm3Way), "sgbm-3way");
  StereoMatcher k;
  EXPECT_FALSE(ParseStereoMatcher("sgbm3way", &k));
  for (SimdLevel l : {SimdLevel::kAuto, SimdLevel::kScalar, SimdLevel::kAvx2, SimdLevel::kAvx512}) {
    SimdLevel back{};
    ASSERT_TRUE(ParseSimdLevel(Name(l), &back));
    EXPECT_EQ(back, l);
  }
}

TEST(StereoParams, EffectivePenalties) {
  StereoParams p;
  EXPECT_EQ(p.EffectiveP1(), 5);
  EXPECT_EQ(p.EffectiveP2(), 19);
  p.matcher = StereoMatcher::kOpenCvSgbm;
  EXPECT_EQ(p.EffectiveP1(), 8 * 25);
  EXPECT_EQ(p.EffectiveP2(), 32 * 25);
  p.p1 = 7;
  EXPECT_EQ(p.EffectiveP1(), 7);
}

// ---- inputs -------------------------------------------------------------------------------------

TEST(Matcher, ComputeRefusesWhatItCannotMatch) {
  const GreyImage grey = GreyOf(Texture(64, 32, 1));
  const GreyImage small = GreyOf(Texture(60, 32, 1));
  OwnedColor bgr;
  bgr.width = 64;
  bgr.height = 32;
  bgr.encoding = ColorEncoding::kBGR8;
  bgr.pixels.assign(64 * 32 * 3, 7);
  for (StereoMatcher k : {StereoMatcher::kSgm, StereoMatcher::kOpenCvSgbm}) {
    StereoParams p;
    p.matcher = k;
    p.num_disparities = 16;
    auto m = Make(p);
    DisparityMap16 out;
    absl::Status s = m->Compute(bgr.view(), grey.view(), &out);
    EXPECT_THAT(std::string(s.message()),
                HasSubstr("left.encoding is bgr8; the matchers take mono8"));
    s = m->Compute(grey.view(), small.view(), &out);
    EXPECT_THAT(std::string(s.message()), HasSubstr("right is 60x32 but left is 64x32"));
    ColorView broken = grey.view();
    broken.size_bytes = 10;
    s = m->Compute(grey.view(), broken, &out);
    EXPECT_THAT(std::string(s.message()), HasSubstr("right.data holds 10 bytes"));
  }
}

TEST(Matcher, RefusesAFrameWhoseCostsWouldNotFitItsLimit) {
  // 4096 x 4096 x 128 bytes is 2 GiB, over kMaxCostVolumeBytes.
  GreyImage big;
  big.width = big.height = 4096;
  big.encoding = ColorEncoding::kMono8;
  big.pixels.assign(std::size_t{4096} * 4096, 0);
  auto m = Make(StereoParams{});
  DisparityMap16 out;
  const absl::Status s = m->Compute(big.view(), big.view(), &out);
  EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted) << s;
  EXPECT_THAT(std::string(s.message()), HasSubstr("left is 4096x4096"));
}

// ---- accuracy on pairs with known disparities ---------------------------------------------------

// Pixels of `map` away from the image's left columns (where the right image does not see the
// scene) and from the bands' edges: share with a match, the largest and the mean |error| among
// them. (The parabola through census costs is not exact: even a whole-pixel shift comes out
// within about +-5/16 px, a half-pixel one within about +-11/16 px, as with OpenCV's SGBM.)
struct BandResult {
  double density = 0;
  double worst = 0;
  double mean = 0;
};
BandResult Check(const DisparityMap16& map, const testing::SyntheticPair& pair, int skip_left) {
  BandResult r;
  std::size_t n = 0, matched = 0;
  for (std::uint32_t y = 4; y + 4 < map.height; ++y) {
    const double d = pair.row_disparity[y];
    if (pair.row_disparity[y - 4] != d || pair.row_disparity[y + 4] != d) continue;
    for (std::uint32_t x = skip_left; x + 4 < map.width; ++x) {
      ++n;
      if (map.at(x, y) == 0) continue;
      ++matched;
      const double e = std::fabs(map.at(x, y) / 16.0 - d);
      r.worst = std::max(r.worst, e);
      r.mean += e;
    }
  }
  r.density = n == 0 ? 0 : static_cast<double>(matched) / n;
  r.mean = matched == 0 ? 0 : r.mean / matched;
  return r;
}

TEST(SgmMatcher, ShiftedTexturesComeOutAtTheirDisparities) {
  // Bands of whole and half-pixel disparities.
  const auto pair = ShiftedPair(320, 200, {12, 30, 30.5, 47, 63.25}, 7);
  for (int paths : {4, 8}) {
    StereoParams p;
    p.num_disparities = 64;
    p.paths = paths;
    auto m = Make(p);
    const DisparityMap16 map = Match(*m, pair.left, pair.right);
    const BandResult r = Check(map, pair, 64);
    EXPECT_GT(r.density, 0.97) << paths << " paths";
    EXPECT_LE(r.worst, 0.75) << paths << " paths: sub-pixel error";
    EXPECT_LE(r.mean, 0.25) << paths << " paths: sub-pixel error";
  }
}

TEST(SgmMatcher, WholePixelShiftsAreExactWithinTheParabola) {
  const auto pair = ShiftedPair(256, 96, {20}, 3);
  auto m = Make(StereoParams{});
  const DisparityMap16 map = Match(*m, pair.left, pair.right);
  const BandResult r = Check(map, pair, 24);
  EXPECT_GT(r.density, 0.99);
  EXPECT_LE(r.worst, 6.0 / 16);  // rounds to the shift everywhere
  EXPECT_LE(r.mean, 2.0 / 16);
}

TEST(SgmMatcher, MinDisparityShiftsTheRangeAndTheOutputHoldsTheDisparityItself) {
  const auto pair = ShiftedPair(256, 96, {40}, 5);
  StereoParams p;
  p.min_disparity = 32;
  p.num_disparities = 16;  // [32, 48)
  auto m = Make(p);
  const DisparityMap16 map = Match(*m, pair.left, pair.right);
  const BandResult r = Check(map, pair, 48);
  EXPECT_GT(r.density, 0.99);
  EXPECT_LE(r.worst, 6.0 / 16);
  // Left of column 32 every disparity of the range looks past the right image's edge.
  for (std::uint32_t y = 0; y < map.height; ++y) {
    for (std::uint32_t x = 0; x < 32; ++x) ASSERT_EQ(map.at(x, y), 0) << x << "," << y;
  }
  // [0, 16): 40 is out of reach, and nothing comes out beyond the range.
  p.min_disparity = 0;
  const DisparityMap16 out = Match(*Make(p), pair.left, pair.right);
  for (std::uint16_t v : out.values) ASSERT_LT(v, 16 * 16);
}

TEST(SgmMatcher, TheCorePipelineReadsItsOutput) {
  // A plane at disparity 25 px: z = fx * baseline / 25 for every matched pixel.
  const auto pair = ShiftedPair(200, 120, {25}, 11);
  auto m = Make(StereoParams{});
  const DisparityMap16 map = Match(*m, pair.left, pair.right);
  CameraModel camera;
  camera.fx = camera.fy = 615;
  camera.cx = 100;
  camera.cy = 60;
  camera.baseline = 0.1;
  camera = ForMatcherOutput(camera);
  ASSERT_TRUE(camera.Validate().ok());
  OwnedColor colour;
  colour.width = 200;
  colour.height = 120;
  colour.encoding = ColorEncoding::kMono8;
  colour.pixels = pair.left.pixels;
  PointCloud cloud;
  ASSERT_TRUE(ConvertToOrganized(camera, map.view(), colour.view(), &cloud).ok());
  std::size_t finite = 0;
  for (std::uint32_t y = 0; y < 120; ++y) {
    for (std::uint32_t x = 30; x < 196; ++x) {
      const Point& pt = cloud.points[y * 200 + x];
      if (!std::isfinite(pt.z)) continue;
      ++finite;
      ASSERT_NEAR(pt.z, 615 * 0.1 / 25, 615 * 0.1 / 25 * 0.02);  // d within 6/16 of 25
    }
  }
  EXPECT_GT(finite, 120u * 160u);
}

// ---- SIMD against scalar ------------------------------------------------------------------------

struct Variant {
  int width, height;
  int min_disparity, num_disparities, block_size, paths, uniqueness, disp12, speckle;
};

// Pairs that exercise every edge: narrow images (fewer columns than disparities), odd sizes,
// disparity counts that are not a multiple of the vector length, negative and positive
// min_disparity, every census window, both path counts, the checks on and off.
const Variant kVariants[] = {
    {160, 90, 0, 64, 5, 8, 10, 1, 100},   {161, 91, 0, 48, 5, 4, 10, 1, 100},
    {97, 61, 0, 144, 5, 8, 10, 1, 0},     {40, 33, 0, 64, 5, 8, 0, -1, 0},
    {128, 64, -8, 32, 3, 8, 15, 2, 50},   {128, 64, 5, 80, 7, 4, 50, 0, 100},
    {130, 70, -20, 64, 7, 8, 10, 1, 100}, {64, 40, 16, 16, 3, 4, 5, 1, 10},
    {200, 50, 0, 192, 5, 8, 10, 1, 100},  {33, 17, 0, 256, 5, 8, 10, 1, 100},
};

TEST(SgmMatcher, SimdEqualsScalarBitForBit) {
  const std::vector<SimdLevel> levels = SimdLevelsHere();
  if (levels.empty()) GTEST_SKIP() << "this CPU has neither AVX2 nor AVX-512BW";
  int compared = 0;
  for (const Variant& v : kVariants) {
    for (std::uint32_t seed : {1u, 2u}) {
      // A textured scene with two disparity bands, plus noise so that costs tie and differ.
      auto pair =
          ShiftedPair(v.width, v.height, {v.min_disparity + 3.0, v.min_disparity + 11.5}, seed);
      std::mt19937 rng(seed);
      for (std::uint8_t& px : pair.right.pixels) px = static_cast<std::uint8_t>(px + rng() % 5);
      StereoParams p;
      p.min_disparity = v.min_disparity;
      p.num_disparities = v.num_disparities;
      p.block_size = v.block_size;
      p.paths = v.paths;
      p.uniqueness_ratio = v.uniqueness;
      p.disp12_max_diff = v.disp12;
      p.speckle_window_size = v.speckle;
      const DisparityMap16 want = Match(*Make(p, SimdLevel::kScalar), pair.left, pair.right);
      for (SimdLevel level : levels) {
        const DisparityMap16 got = Match(*Make(p, level), pair.left, pair.right);
        ASSERT_EQ(got.values.size(), want.values.size());
        std::size_t differ = 0, first = 0;
        for (std::size_t i = 0; i < want.values.size(); ++i) {
          if (got.values[i] != want.values[i] && differ++ == 0) first = i;
        }
        EXPECT_EQ(differ, 0u) << Name(level) << " " << v.width << "x" << v.height << " d ["
                              << v.min_disparity << ", " << v.min_disparity + v.num_disparities
                              << ") block " << v.block_size << " paths " << v.paths
                              << ": first at pixel " << first << " (" << got.values[first] << " vs "
                              << want.values[first] << ")";
        ++compared;
      }
    }
  }
  EXPECT_GT(compared, 0);
}

TEST(SgmMatcher, SimdEqualsScalarOnNewTsukuba) {
  testing::GreyPair pair;
  if (!testing::LoadTsukubaGrey("01200", &pair)) GTEST_SKIP() << "New Tsukuba data not found";
  const std::vector<SimdLevel> levels = SimdLevelsHere();
  if (levels.empty()) GTEST_SKIP() << "this CPU has neither AVX2 nor AVX-512BW";
  // Its right half (disparities up to 146: some beyond the range), as views with the full
  // frame's stride: the scalar code is slow.
  auto half = [](const GreyImage& g) {
    GreyView v = g.view();
    v.data = g.pixels.data() + 320;
    v.size_bytes -= 320;
    v.width = 320;
    return v;
  };
  for (int paths : {4, 8}) {
    StereoParams p;
    p.paths = paths;
    DisparityMap16 want, got;
    ASSERT_TRUE(
        Make(p, SimdLevel::kScalar)->Compute(half(pair.left), half(pair.right), &want).ok());
    for (SimdLevel level : levels) {
      ASSERT_TRUE(Make(p, level)->Compute(half(pair.left), half(pair.right), &got).ok());
      EXPECT_TRUE(got.values == want.values) << Name(level) << ", " << paths << " paths";
    }
  }
}

TEST(SgmMatcher, ScratchKeptBetweenFramesOfAnySizeChangesNothing) {
  const auto big = ShiftedPair(300, 160, {9, 21.5}, 4);
  const auto small = ShiftedPair(70, 30, {6}, 5);
  StereoParams p;
  p.num_disparities = 48;
  const DisparityMap16 big_fresh = Match(*Make(p), big.left, big.right);
  const DisparityMap16 small_fresh = Match(*Make(p), small.left, small.right);
  auto m = Make(p);
  for (int round = 0; round < 2; ++round) {
    EXPECT_TRUE(Match(*m, big.left, big.right).values == big_fresh.values);
    EXPECT_TRUE(Match(*m, small.left, small.right).values == small_fresh.values);
  }
}

TEST(SgmMatcher, ReadsRowsInPieces) {
  const auto pair = ShiftedPair(120, 40, {10}, 8);
  auto m = Make(StereoParams{});
  const DisparityMap16 want = Match(*m, pair.left, pair.right);
  // The same rows at scattered places, as the server reads them from network buffers.
  std::vector<std::vector<std::uint8_t>> pieces;
  std::vector<const std::uint8_t*> rows_left, rows_right;
  for (std::uint32_t y = 0; y < 40; ++y) {
    pieces.emplace_back(pair.left.pixels.begin() + y * 120,
                        pair.left.pixels.begin() + (y + 1) * 120);
    pieces.back().push_back(0);
    pieces.emplace_back(pair.right.pixels.begin() + y * 120,
                        pair.right.pixels.begin() + (y + 1) * 120);
    pieces.back().push_back(0);
  }
  for (std::uint32_t y = 0; y < 40; ++y) {
    rows_left.push_back(pieces[2 * y].data());
    rows_right.push_back(pieces[2 * y + 1].data());
  }
  GreyView l = pair.left.view(), r = pair.right.view();
  l.rows = rows_left.data();
  r.rows = rows_right.data();
  DisparityMap16 got;
  ASSERT_TRUE(m->Compute(l, r, &got).ok());
  EXPECT_TRUE(got.values == want.values);
}

// ---- speckle filter
// ------------------------------------------------------------------------------

// Our filter and cv::filterSpeckles (newVal 0) on one map: equal, value for value.
void ExpectSpecklesLikeOpenCv(const std::vector<std::uint16_t>& map, int width, int height,
                              int max_size, int max_diff, const char* what) {
  std::vector<std::uint16_t> ours = map;
  SpeckleFilter filter;
  filter.Apply(ours.data(), width, height, max_size, max_diff);
  cv::Mat theirs(height, width, CV_16SC1);
  std::memcpy(theirs.data, map.data(), map.size() * 2);
  cv::filterSpeckles(theirs, 0, max_size, max_diff);
  std::size_t differ = 0, removed = 0;
  for (std::size_t i = 0; i < map.size(); ++i) {
    differ += ours[i] != reinterpret_cast<const std::uint16_t*>(theirs.data)[i];
    removed += map[i] != 0 && ours[i] == 0;
  }
  EXPECT_EQ(differ, 0u) << what << " size " << max_size << " diff " << max_diff;
  EXPECT_GT(removed, 0u) << what << ": the filter must have had work";
}

TEST(SpeckleFilter, EqualsOpenCvsFilterSpeckles) {
  std::mt19937 rng(17);
  // Random blobs of random values with holes: regions of every size, touching at every angle.
  for (int round = 0; round < 6; ++round) {
    const int w = 50 + static_cast<int>(rng() % 200), h = 30 + static_cast<int>(rng() % 100);
    std::vector<std::uint16_t> map(static_cast<std::size_t>(w) * h);
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        const int band = ((x / (1 + rng() % 7)) + (y / 3)) % 5;
        map[y * w + x] = rng() % 9 == 0 ? 0 : static_cast<std::uint16_t>(band * 40 + rng() % 40);
      }
    }
    for (int max_diff : {0, 16, 32, 48}) {
      for (int max_size : {1, 4, 20, 100})
        ExpectSpecklesLikeOpenCv(map, w, h, max_size, max_diff, "random");
    }
  }
  // Our matcher's own output before its filter.
  const auto pair = ShiftedPair(240, 160, {8, 21.5, 33}, 12);
  StereoParams p;
  p.num_disparities = 48;
  p.speckle_window_size = 0;
  p.uniqueness_ratio = 0;
  const DisparityMap16 raw = Match(*Make(p), pair.left, pair.right);
  ExpectSpecklesLikeOpenCv(raw.values, 240, 160, 100, 32, "matched");
  testing::GreyPair tsukuba;
  if (testing::LoadTsukubaGrey("00600", &tsukuba)) {
    p.num_disparities = 128;
    const DisparityMap16 real = Match(*Make(p), tsukuba.left, tsukuba.right);
    ExpectSpecklesLikeOpenCv(real.values, 640, 480, 100, 32, "New Tsukuba 00600");
  }
}

// ---- OpenCV's matchers --------------------------------------------------------------------------

TEST(OpenCvMatchers, GiveWhatOpenCvGivesCalledDirectly) {
  const auto pair = ShiftedPair(200, 120, {14, 33}, 9);
  const cv::Mat left = MatOf(pair.left), right = MatOf(pair.right);
  cv::setNumThreads(1);
  for (StereoMatcher k : {StereoMatcher::kOpenCvSgbm, StereoMatcher::kOpenCvSgbm3Way,
                          StereoMatcher::kOpenCvHH, StereoMatcher::kOpenCvBm}) {
    StereoParams p;
    p.matcher = k;
    p.min_disparity = 2;
    p.num_disparities = 48;
    p.block_size = 7;
    const DisparityMap16 got = Match(*Make(p), pair.left, pair.right);
    cv::Mat direct;
    if (k == StereoMatcher::kOpenCvBm) {
      auto bm = cv::StereoBM::create(48, 7);
      bm->setMinDisparity(2);
      bm->setUniquenessRatio(10);
      bm->setSpeckleWindowSize(100);
      bm->setSpeckleRange(2);
      bm->setDisp12MaxDiff(1);
      bm->compute(left, right, direct);
    } else {
      const int mode = k == StereoMatcher::kOpenCvSgbm3Way ? cv::StereoSGBM::MODE_SGBM_3WAY
                       : k == StereoMatcher::kOpenCvHH     ? cv::StereoSGBM::MODE_HH
                                                           : cv::StereoSGBM::MODE_SGBM;
      cv::StereoSGBM::create(2, 48, 7, 8 * 49, 32 * 49, 1, 0, 10, 100, 2, mode)
          ->compute(left, right, direct);
    }
    ASSERT_EQ(direct.type(), CV_16S);
    std::size_t valid = 0;
    for (int y = 0; y < direct.rows; ++y) {
      for (int x = 0; x < direct.cols; ++x) {
        const int v = direct.at<std::int16_t>(y, x);
        // OpenCV's "no match" is (minDisparity - 1) * 16; ours is 0.
        const int want = v < 2 * 16 ? 0 : v;
        valid += want != 0;
        ASSERT_EQ(got.at(x, y), want) << Name(k) << " at " << x << "," << y;
      }
    }
    EXPECT_GT(valid, 1000u) << Name(k);
  }
}

// ---- grey ---------------------------------------------------------------------------------------

TEST(Grey, ConvertsLikeOpenCv) {
  const cv::Mat bgr = [] {
    cv::Mat m(37, 53, CV_8UC3);
    cv::randu(m, 0, 256);
    return m;
  }();
  struct Case {
    ColorEncoding encoding;
    int code;  // bgr -> this encoding
  };
  for (Case c : {Case{ColorEncoding::kBGR8, -1}, Case{ColorEncoding::kRGB8, cv::COLOR_BGR2RGB},
                 Case{ColorEncoding::kRGBA8, cv::COLOR_BGR2RGBA}}) {
    cv::Mat src;
    if (c.code >= 0) {
      cv::cvtColor(bgr, src, c.code);
    } else {
      src = bgr;
    }
    ColorView v;
    v.data = src.data;
    v.size_bytes = src.total() * src.elemSize();
    v.width = 53;
    v.height = 37;
    v.stride_bytes = src.step;
    v.encoding = c.encoding;
    auto grey = ToGrey(v);
    ASSERT_TRUE(grey.ok()) << grey.status();
    cv::Mat want;
    cv::cvtColor(bgr, want, cv::COLOR_BGR2GRAY);
    EXPECT_EQ(cv::norm(MatOf(*grey), want, cv::NORM_INF), 0) << Name(c.encoding);
    EXPECT_EQ(grey->encoding, ColorEncoding::kMono8);
  }
  cv::Mat g;
  cv::cvtColor(bgr, g, cv::COLOR_BGR2GRAY);
  const GreyImage mono = GreyOf(g);
  auto copy = ToGrey(mono.view());
  ASSERT_TRUE(copy.ok());
  EXPECT_EQ(copy->pixels, mono.pixels);
  ColorView broken = mono.view();
  broken.stride_bytes = 3;
  EXPECT_THAT(std::string(ToGrey(broken, "left").status().message()),
              HasSubstr("left.stride_bytes is 3"));
}

// ---- rectifier ----------------------------------------------------------------------------------

cv::Mat Rotation(double degrees, cv::Vec3d axis) {
  cv::Mat r;
  cv::Rodrigues(cv::Mat(axis / cv::norm(axis) * (degrees * CV_PI / 180)), r);
  return r;
}

StereoCalibration Calibration(const cv::Mat& k1, const cv::Mat& k2, const cv::Mat& r,
                              const cv::Mat& t, int width, int height) {
  StereoCalibration c;
  for (int i = 0; i < 9; ++i) {
    c.left_k[i] = k1.at<double>(i / 3, i % 3);
    c.right_k[i] = k2.at<double>(i / 3, i % 3);
    c.r[i] = r.at<double>(i / 3, i % 3);
  }
  for (int i = 0; i < 3; ++i) c.t[i] = t.at<double>(i);
  c.width = width;
  c.height = height;
  return c;
}

TEST(Rectifier, UndoesASyntheticRotationAndOffsetSoThePairMatchesAgain) {
  // A rectified pair of a fronto-parallel textured plane at disparity 24 px (f = 400, baseline
  // 0.1: z = 1.667). Each camera is then turned by 2 degrees about an axis, opposite ways (so
  // stereoRectify's half-way frame is the original one), and the right camera's principal point
  // moved by 9 px: the raw images are the rectified ones warped by K_raw * R * K^-1.
  const int w = 320, h = 240;
  const double f = 400, d0 = 24;
  const auto pair = ShiftedPair(w, h, {d0}, 21);
  const cv::Mat k = (cv::Mat_<double>(3, 3) << f, 0, 160, 0, f, 120, 0, 0, 1);
  cv::Mat k2 = k.clone();
  k2.at<double>(0, 2) += 9;
  const cv::Vec3d axis(0.3, 1.0, 0.4);
  const cv::Mat rl = Rotation(2, axis), rr = Rotation(-2, axis);
  cv::Mat raw_left, raw_right;
  cv::warpPerspective(MatOf(pair.left), raw_left, k * rl * k.inv(), cv::Size(w, h),
                      cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  cv::warpPerspective(MatOf(pair.right), raw_right, k2 * rr * k.inv(), cv::Size(w, h),
                      cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  // OpenCV's convention: X_right = R X_left + T, the right camera 0.1 to the right.
  const cv::Mat r = rr * rl.t();
  const cv::Mat t = -rr * (cv::Mat_<double>(3, 1) << 0.1, 0, 0);
  auto rect = Rectifier::Make(Calibration(k, k2, r, t, w, h));
  ASSERT_TRUE(rect.ok()) << rect.status();
  EXPECT_NEAR(rect->camera().baseline, 0.1, 1e-9);
  const RectifiedCamera& cam = rect->camera();

  const GreyImage raw_l = GreyOf(raw_left), raw_r = GreyOf(raw_right);
  OwnedColor out_l, out_r;
  ASSERT_TRUE(rect->Rectify(raw_l.view(), raw_r.view(), &out_l, &out_r).ok());
  EXPECT_EQ(out_l.encoding, ColorEncoding::kMono8);

  // Rectified again, the plane is at one disparity: d0 scaled by the new focal length.
  StereoParams p;
  p.num_disparities = 64;
  auto m = Make(p);
  const DisparityMap16 rectified = Match(*m, out_l, out_r);
  const DisparityMap16 unrectified = Match(*m, raw_l, raw_r);
  const double want = d0 * cam.fx / f;
  auto score = [&](const DisparityMap16& map) {
    std::size_t n = 0, good = 0;
    for (std::uint32_t y = 40; y < 200; ++y) {
      for (std::uint32_t x = 80; x < 280; ++x) {
        ++n;
        good += map.at(x, y) != 0 && std::fabs(map.at(x, y) / 16.0 - want) <= 0.5;
      }
    }
    return static_cast<double>(good) / n;
  };
  EXPECT_GT(score(rectified), 0.95) << "want " << want << " px";
  EXPECT_LT(score(unrectified), 0.5) << "the raw pair must need the rectification";
  // Its camera reads the disparity back as the plane's depth.
  const double z = cam.fx * cam.baseline / want;
  EXPECT_NEAR(z, f * 0.1 / d0, 1e-9);
  EXPECT_EQ(cam.ToCameraModel().disparity_scale, 1.0 / 16);
}

TEST(Rectifier, ColourImagesStayColour) {
  const cv::Mat k = (cv::Mat_<double>(3, 3) << 300, 0, 80, 0, 300, 60, 0, 0, 1);
  const cv::Mat t = (cv::Mat_<double>(3, 1) << -0.2, 0, 0);
  StereoCalibration c = Calibration(k, k, cv::Mat::eye(3, 3, CV_64F), t, 160, 120);
  c.left_d = {0.05, -0.01, 0, 0, 0};
  auto rect = Rectifier::Make(c);
  ASSERT_TRUE(rect.ok()) << rect.status();
  OwnedColor bgr;
  bgr.width = 160;
  bgr.height = 120;
  bgr.encoding = ColorEncoding::kBGR8;
  bgr.pixels.assign(160 * 120 * 3, 0);
  for (std::size_t i = 0; i < bgr.pixels.size(); i += 3) bgr.pixels[i + 2] = 200;  // red
  OwnedColor l, r;
  ASSERT_TRUE(rect->Rectify(bgr.view(), bgr.view(), &l, &r).ok());
  EXPECT_EQ(l.encoding, ColorEncoding::kBGR8);
  const std::size_t centre = (60 * 160 + 80) * 3;
  EXPECT_EQ(l.pixels[centre + 2], 200);
  EXPECT_EQ(l.pixels[centre], 0);
}

TEST(Rectifier, ErrorsNameTheField) {
  const cv::Mat k = (cv::Mat_<double>(3, 3) << 300, 0, 80, 0, 300, 60, 0, 0, 1);
  const cv::Mat t = (cv::Mat_<double>(3, 1) << -0.2, 0, 0);
  const StereoCalibration good = Calibration(k, k, cv::Mat::eye(3, 3, CV_64F), t, 160, 120);
  ASSERT_TRUE(good.Validate().ok());
  struct Case {
    const char* expect;
    void (*set)(StereoCalibration*);
  };
  const Case cases[] = {
      {"calibration.left_k[0] (fx) must be finite and in (0, 1e9]",
       [](StereoCalibration* c) { c->left_k[0] = 0; }},
      {"calibration.right_k[4] (fy)", [](StereoCalibration* c) { c->right_k[4] = -1; }},
      {"calibration.left_k must be a camera matrix",
       [](StereoCalibration* c) { c->left_k[8] = 2; }},
      {"calibration.right_d holds 3 coefficients; OpenCV takes 0, 4, 5, 8, 12 or 14",
       [](StereoCalibration* c) {
         c->right_d = {0, 0, 0};
       }},
      {"calibration.left_d[1] must be finite",
       [](StereoCalibration* c) {
         c->left_d = {0, NAN, 0, 0};
       }},
      {"calibration.r is not a rotation", [](StereoCalibration* c) { c->r[0] = 2; }},
      {"calibration.r is not a rotation", [](StereoCalibration* c) { c->r[0] = -1; }},
      {"calibration.t is 0",
       [](StereoCalibration* c) {
         c->t = {0, 0, 0};
       }},
      {"calibration.width", [](StereoCalibration* c) { c->width = 0; }},
  };
  for (const Case& c : cases) {
    StereoCalibration cal = good;
    c.set(&cal);
    const absl::Status s = cal.Validate();
    EXPECT_FALSE(s.ok()) << c.expect;
    EXPECT_THAT(std::string(s.message()), HasSubstr(c.expect));
    EXPECT_FALSE(Rectifier::Make(cal).ok());
  }
  StereoCalibration stacked = good;
  stacked.t = {0, -0.2, 0};
  EXPECT_THAT(std::string(Rectifier::Make(stacked).status().message()),
              HasSubstr("one above the other"));
  StereoCalibration swapped = good;
  swapped.t = {0.2, 0, 0};
  EXPECT_THAT(std::string(Rectifier::Make(swapped).status().message()), HasSubstr("swap them"));
  RectifierOptions options;
  options.alpha = 2;
  EXPECT_THAT(std::string(Rectifier::Make(good, options).status().message()),
              HasSubstr("rectifier.alpha is 2"));
  auto rect = Rectifier::Make(good);
  ASSERT_TRUE(rect.ok());
  const GreyImage small = GreyOf(Texture(100, 120, 1));
  OwnedColor a, b;
  EXPECT_THAT(std::string(rect->Rectify(small.view(), small.view(), &a, &b).message()),
              HasSubstr("left is 100x120; the calibration is for 160x120"));
}

// ---- scoring ------------------------------------------------------------------------------------

TEST(DisparityScore, CountsErrorsAgainstTheTruthAndTheTruthPlusOne) {
  DisparityMap16 map;
  map.width = 4;
  map.height = 1;
  map.values = {16 * 10, 16 * 11, 0, 16 * 14 + 8};  // 10, 11, none, 14.5
  OwnedDisparity truth;
  truth.width = 4;
  truth.height = 1;
  truth.encoding = DisparityEncoding::kU8;
  truth.pixels = {10, 10, 10, 12};
  DisparityScore s;
  ASSERT_TRUE(s.Add(map, truth.view()).ok());
  EXPECT_EQ(s.known(), 4u);
  EXPECT_EQ(s.matched(), 3u);
  EXPECT_NEAR(s.Density(), 0.75, 1e-12);
  EXPECT_NEAR(s.Bad(1, 0), 100.0 / 3, 1e-9);    // 14.5 vs 12
  EXPECT_NEAR(s.Bad(0.5, 0), 200.0 / 3, 1e-9);  // 11 vs 10 too
  EXPECT_NEAR(s.Bad(1, 1), 100.0 / 3, 1e-9);    // 10 vs 11 is 1: not bad; 14.5 vs 13 is
  EXPECT_NEAR(s.BadCountingMisses(1, 0), 50, 1e-9);
  EXPECT_NEAR(s.MedianError(), 1, 1e-12);
}

}  // namespace
}  // namespace cloudcast::stereo
