// Our Draco encoder (core/src/draco_sequential_encoder.cc) against libdraco 1.5.5 itself: every
// case encodes the same cloud with the same options twice, once through our encoder and once
// with DracoOptions::force_libdraco, and requires the same bytes (and the same EncodeDracoInfo),
// with no tolerance. Also: which encoder ran, and that Debian's draco_decoder and our decoder
// (DecodeDraco, which the client library runs on every reply) read our files.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <new>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/core/point.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/datasets/tsukuba.h"
#include "cloudcast/io/cloud_io.h"
#include "cloudcast/io/image_io.h"
#include "support/program_support.h"
#include "support/test_support.h"

// Every allocation of the test program is counted, to check that a warm encoder allocates
// nothing. The replacements stay out of line: inlined, GCC sees std::free given what it takes
// for the builtin operator new's memory (-Wmismatched-new-delete), which it is not here.
namespace {
std::atomic<long> g_allocations{0};
}  // namespace
__attribute__((noinline)) void* operator new(std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
__attribute__((noinline)) void operator delete(void* p) noexcept { std::free(p); }
__attribute__((noinline)) void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace cloudcast {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// Where two byte strings first differ, with a few bytes of each around it; empty when equal.
std::string FirstDifference(const std::string& ours, const std::string& theirs) {
  if (ours == theirs) return "";
  std::size_t at = 0;
  while (at < ours.size() && at < theirs.size() && ours[at] == theirs[at]) ++at;
  auto hex = [at](const std::string& s) {
    std::ostringstream os;
    const std::size_t from = at >= 4 ? at - 4 : 0;
    for (std::size_t i = from; i < std::min(s.size(), at + 8); ++i) {
      char b[8];
      std::snprintf(b, sizeof b, i == at ? "[%02x]" : " %02x", static_cast<unsigned char>(s[i]));
      os << b;
    }
    return os.str();
  };
  std::ostringstream os;
  os << "ours has " << ours.size() << " bytes, libdraco " << theirs.size()
     << "; first difference at byte " << at << "\n  ours:     " << hex(ours)
     << "\n  libdraco: " << hex(theirs);
  return os.str();
}

std::string Describe(const DracoOptions& o) {
  std::ostringstream os;
  os << "position_bits " << o.position_bits << ", color_bits " << o.color_bits << ", speed "
     << o.encode_speed << "/" << o.decode_speed << ", max_position_error " << o.max_position_error;
  return os.str();
}

// Encodes `cloud` with our encoder and with libdraco; success when both give the same status,
// the same bytes and the same info, and when `expected` (ours unless the case falls back) wrote
// the first.
::testing::AssertionResult SameAsLibdraco(const PointCloud& cloud, DracoOptions options,
                                          std::string* bytes = nullptr,
                                          DracoEncoder expected = DracoEncoder::kCloudcast) {
  std::string ours, theirs;
  DracoEncodeInfo ours_info, theirs_info;
  options.force_libdraco = false;
  const absl::Status ours_status = EncodeDraco(cloud, options, &ours, &ours_info);
  options.force_libdraco = true;
  const absl::Status theirs_status = EncodeDraco(cloud, options, &theirs, &theirs_info);
  const std::string what =
      " (" + std::to_string(cloud.size()) + " points, " + Describe(options) + ")";
  if (ours_status != theirs_status) {
    return ::testing::AssertionFailure()
           << "ours: " << ours_status << ", libdraco: " << theirs_status << what;
  }
  if (!ours_status.ok()) return ::testing::AssertionSuccess();  // the same error
  if (ours_info.encoder != expected) {
    return ::testing::AssertionFailure()
           << (expected == DracoEncoder::kCloudcast ? "our encoder did not run"
                                                    : "our encoder ran where libdraco should")
           << what;
  }
  if (theirs_info.encoder != DracoEncoder::kLibdraco) {
    return ::testing::AssertionFailure() << "force_libdraco did not run libdraco" << what;
  }
  if (const std::string diff = FirstDifference(ours, theirs); !diff.empty()) {
    return ::testing::AssertionFailure() << diff << what;
  }
  if (ours_info.position_bits != theirs_info.position_bits ||
      ours_info.position_error_bound != theirs_info.position_error_bound ||
      ours_info.bytes != theirs_info.bytes || ours_info.bytes != ours.size()) {
    return ::testing::AssertionFailure()
           << "info differs: bits " << ours_info.position_bits << " / " << theirs_info.position_bits
           << ", bound " << ours_info.position_error_bound << " / "
           << theirs_info.position_error_bound << ", bytes " << ours_info.bytes << " / "
           << theirs_info.bytes << what;
  }
  if (bytes != nullptr) *bytes = std::move(ours);
  return ::testing::AssertionSuccess();
}

DracoOptions Options(int bits, int color_bits = 8, float max_error = 0.0f) {
  DracoOptions o;
  o.position_bits = bits;
  o.color_bits = color_bits;
  o.max_position_error = max_error;
  return o;
}

PointCloud Cloud(std::vector<Point> points) {
  PointCloud cloud;
  cloud.ResizeUnorganized(points.size());
  std::copy(points.begin(), points.end(), cloud.points.begin());
  return cloud;
}

// Uniform points in a box with random colours.
PointCloud UniformCloud(std::size_t n, std::uint32_t seed, float side = 4.0f, float offset = 0.0f) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  PointCloud cloud;
  cloud.ResizeUnorganized(n);
  for (Point& p : cloud.points) {
    p = {offset + side * u(rng), offset - 0.5f * side * u(rng),
         offset + 3.0f + 0.25f * side * u(rng), 0xFF000000u | static_cast<std::uint32_t>(rng())};
  }
  return cloud;
}

// The fused chain's output on the built-in synthetic scene (what the service sends without the
// New Tsukuba data).
PointCloud SyntheticChainCloud(std::uint64_t frame_index = 0) {
  SyntheticOptions synthetic;
  synthetic.frame = frame_index;
  const auto frame = SyntheticScene::Default().Render(synthetic);
  EXPECT_TRUE(frame.ok()) << frame.status();
  PipelineOptions options;
  options.camera = frame->camera;
  Pipeline pipeline;
  PointCloud out;
  EXPECT_TRUE(pipeline.Run(options, frame->disparity_view(), frame->colour_view(), &out).ok());
  return out;
}

// ---------------------------------------------------------------------------------------------
// The comparison itself.

TEST(DracoExactCompare, ADifferenceOfOneByteIsReported) {
  const std::string a = "DRACO\x02\x03 some bytes";
  std::string b = a;
  EXPECT_EQ(FirstDifference(a, b), "");
  b[9] ^= 1;
  const std::string diff = FirstDifference(a, b);
  EXPECT_NE(diff.find("first difference at byte 9"), std::string::npos) << diff;
  EXPECT_NE(FirstDifference(a, a + "x").find("at byte " + std::to_string(a.size())),
            std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Which encoder runs.

TEST(DracoExactPath, SpeedTenRunsOursEverythingElseLibdraco) {
  const PointCloud cloud = UniformCloud(500, 1);
  struct Case {
    int encode_speed, decode_speed;
    bool force;
    DracoEncoder expected;
  };
  const Case cases[] = {
      {10, 10, false, DracoEncoder::kCloudcast}, {10, 3, false, DracoEncoder::kCloudcast},
      {0, 10, false, DracoEncoder::kCloudcast},  {10, 10, true, DracoEncoder::kLibdraco},
      {9, 9, false, DracoEncoder::kLibdraco},    {5, 7, false, DracoEncoder::kLibdraco},
      {0, 0, false, DracoEncoder::kLibdraco},
  };
  for (const Case& c : cases) {
    DracoOptions o = Options(11);
    o.encode_speed = c.encode_speed;
    o.decode_speed = c.decode_speed;
    o.force_libdraco = c.force;
    std::string bytes;
    DracoEncodeInfo info;
    ASSERT_TRUE(EncodeDraco(cloud, o, &bytes, &info).ok());
    EXPECT_EQ(info.encoder, c.expected) << Describe(o) << (c.force ? ", forced" : "");
  }
  // Speeds 10 / 3 and 0 / 10 are speed 10 to Draco too: the same bytes.
  for (auto [e, d] : {std::pair{10, 3}, {0, 10}}) {
    DracoOptions o = Options(11);
    o.encode_speed = e;
    o.decode_speed = d;
    EXPECT_TRUE(SameAsLibdraco(cloud, o));
  }
}

TEST(DracoExactPath, RangeTooSmallToScaleFallsBackToLibdraco) {
  // Extents below ~1e-30 overflow Draco's float scale (2^bits - 1) / range; libdraco encodes
  // them anyway, with undefined quantized values, so they are left to it.
  const PointCloud tiny =
      Cloud({Point{0.0f, 0.0f, 0.0f, 0xFF000000u}, Point{1e-40f, 0.0f, 0.0f, 0xFF010203u}});
  EXPECT_TRUE(SameAsLibdraco(tiny, Options(10), nullptr, DracoEncoder::kLibdraco));
  // Just above it, ours.
  const PointCloud small =
      Cloud({Point{0.0f, 0.0f, 0.0f, 0xFF000000u}, Point{1e-20f, 2e-21f, 0.0f, 0xFF010203u}});
  EXPECT_TRUE(SameAsLibdraco(small, Options(30)));
}

TEST(DracoExactPath, EmptyAndAllNaNCloudsRunOurs) {
  PointCloud nan_cloud;
  nan_cloud.points.assign(10, Point{kNaN, 1.0f, 2.0f, 0xFFFFFFFFu});
  for (const PointCloud& cloud : {PointCloud{}, nan_cloud}) {
    std::string bytes;
    DracoEncodeInfo info;
    ASSERT_TRUE(EncodeDraco(cloud, Options(10), &bytes, &info).ok());
    EXPECT_EQ(info.encoder, DracoEncoder::kCloudcast);
    EXPECT_TRUE(SameAsLibdraco(cloud, Options(10)));
    EXPECT_TRUE(SameAsLibdraco(cloud, Options(10, 8, 0.0075f)));
  }
}

TEST(DracoExactPath, WarmEncoderAllocatesNothing) {
  const PointCloud big = UniformCloud(30000, 50, 8.0f), small = SyntheticChainCloud(1);
  PointCloud with_holes = UniformCloud(5000, 51);
  for (std::size_t i = 0; i < with_holes.size(); i += 5) with_holes.points[i].z = kNaN;
  const PointCloud& holes = with_holes;
  std::string bytes;
  DracoOptions options = Options(10, 8, 0.0075f);
  const long cold = g_allocations.load();
  for (const PointCloud* c : {&big, &small, &holes}) {  // warm-up: scratch and output grow
    ASSERT_TRUE(EncodeDraco(*c, options, &bytes).ok());
  }
  // The counter must see allocations at all (the replaced operator new is the one in use).
  ASSERT_GT(g_allocations.load(), cold);
  const long before = g_allocations.load();
  for (int i = 0; i < 3; ++i) {
    for (const PointCloud* c : {&small, &big, &holes, &small}) {
      ASSERT_TRUE(EncodeDraco(*c, options, &bytes).ok());
    }
  }
  EXPECT_EQ(g_allocations.load() - before, 0);
}

// ---------------------------------------------------------------------------------------------
// Synthetic clouds.

TEST(DracoExact, ZeroOneTwoPoints) {
  EXPECT_TRUE(SameAsLibdraco(PointCloud{}, Options(10)));
  const Point a{1.25f, -3.5f, 7.0f, PackRgba(10, 20, 30)};
  const Point b{-2.0f, 0.5f, 9.75f, PackRgba(200, 0, 255)};
  for (int bits : {1, 10, 20, 21, 30}) {
    EXPECT_TRUE(SameAsLibdraco(Cloud({a}), Options(bits)));
    EXPECT_TRUE(SameAsLibdraco(Cloud({a, b}), Options(bits)));
    EXPECT_TRUE(SameAsLibdraco(Cloud({b, a}), Options(bits)));
    EXPECT_TRUE(SameAsLibdraco(Cloud({a, a}), Options(bits)));
  }
}

TEST(DracoExact, MillionPoints) {
  const PointCloud cloud = UniformCloud(1000000, 3, 12.0f);
  for (int bits : {10, 16, 24}) EXPECT_TRUE(SameAsLibdraco(cloud, Options(bits)));
}

TEST(DracoExact, CoincidentPoints) {
  // All equal (range 0: Draco quantizes with range 1), and clouds made of a few repeated points.
  PointCloud same;
  same.points.assign(1000, Point{0.5f, -1.0f, 4.0f, PackRgba(1, 2, 3)});
  for (int bits : {1, 10, 20, 30}) EXPECT_TRUE(SameAsLibdraco(same, Options(bits)));
  std::mt19937 rng(5);
  const PointCloud base = UniformCloud(7, 6);
  PointCloud repeated;
  for (int i = 0; i < 3000; ++i) repeated.points.push_back(base.points[rng() % base.size()]);
  repeated.ResizeUnorganized(repeated.points.size());
  for (int bits : {4, 10, 16, 22}) EXPECT_TRUE(SameAsLibdraco(repeated, Options(bits)));
}

TEST(DracoExact, SingleValueOnOneAxis) {
  for (int axis = 0; axis < 3; ++axis) {
    PointCloud cloud = UniformCloud(2000, 10 + axis);
    for (Point& p : cloud.points) (&p.x)[axis] = 2.5f;
    for (int bits : {1, 10, 21}) EXPECT_TRUE(SameAsLibdraco(cloud, Options(bits))) << axis;
    // Two axes flat: a line.
    for (Point& p : cloud.points) (&p.x)[(axis + 1) % 3] = -1.0f;
    EXPECT_TRUE(SameAsLibdraco(cloud, Options(12))) << axis;
  }
}

TEST(DracoExact, EveryPositionBits) {
  const PointCloud uniform = UniformCloud(3000, 20, 9.0f, -3.0f);
  const PointCloud scene = SyntheticChainCloud();
  for (int bits = 1; bits <= 30; ++bits) {
    EXPECT_TRUE(SameAsLibdraco(uniform, Options(bits)));
    EXPECT_TRUE(SameAsLibdraco(scene, Options(bits)));
  }
}

// The raw scheme's rANS precision follows the number of distinct symbols: 12, 13, 15, 16, 18, 19
// or 20 bits (Draco's max(12, min(20, 3 * bits / 2)) never gives 14 or 17), each with its own
// coder path. Walks along x in 17-bit steps of up to +-d quantization units give about 2d
// distinct symbols, and the flat y and z make the raw scheme win.
TEST(DracoExact, EveryRawPrecision) {
  std::vector<int> seen;
  for (int d : {50, 600, 1200, 2500, 6000, 12000, 20000}) {
    std::mt19937 rng(static_cast<std::uint32_t>(d));
    std::uniform_int_distribution<int> step(-d, d);
    const int top = (1 << 17) - 1;
    PointCloud cloud;
    cloud.ResizeUnorganized(100000);
    int x = top / 2;
    for (Point& p : cloud.points) {
      x += step(rng);
      if (x < 0) x = -x;
      if (x > top) x = 2 * top - x;
      p = {static_cast<float>(x) / top, 0.25f, 0.5f,
           0xFF000000u | static_cast<std::uint32_t>(rng() & 0xFFFFFF)};
    }
    cloud.points[0].x = 0.0f;
    cloud.points[1].x = 1.0f;
    std::string bytes;
    ASSERT_TRUE(SameAsLibdraco(cloud, Options(17), &bytes)) << "d " << d;
    // Bytes 32 and 33: the positions' scheme (1: raw) and its symbol bit length.
    ASSERT_GT(bytes.size(), 34u);
    ASSERT_EQ(bytes[32], 1) << "d " << d << ": not the raw scheme";
    const int bits = static_cast<unsigned char>(bytes[33]);
    seen.push_back(std::clamp(3 * bits / 2, 12, 20));
  }
  EXPECT_EQ(seen, (std::vector<int>{12, 13, 15, 16, 18, 19, 20}));
}

TEST(DracoExact, EveryColourBits) {
  const PointCloud cloud = UniformCloud(5000, 21);
  for (int color_bits = 1; color_bits <= 8; ++color_bits) {
    for (int bits : {10, 24}) EXPECT_TRUE(SameAsLibdraco(cloud, Options(bits, color_bits)));
  }
}

TEST(DracoExact, NonFinitePointsAreDroppedAsLibdracoDrops) {
  PointCloud cloud = UniformCloud(64 * 48, 22);
  cloud.width = 64;
  cloud.height = 48;
  for (std::size_t i = 0; i < cloud.size(); i += 3) cloud.points[i].y = kNaN;
  cloud.points[1].z = std::numeric_limits<float>::infinity();
  EXPECT_TRUE(SameAsLibdraco(cloud, Options(11)));
  EXPECT_TRUE(SameAsLibdraco(cloud, Options(11, 5, 0.001f)));
}

TEST(DracoExact, SignedZeroMinimum) {
  // Draco keeps the first of equal minima: -0.0 then 0.0 writes -0.0, the other order 0.0.
  const Point neg{-0.0f, 1.0f, 1.0f, 0xFF000000u}, pos{0.0f, 2.0f, 3.0f, 0xFF102030u};
  EXPECT_TRUE(SameAsLibdraco(Cloud({neg, pos}), Options(10)));
  EXPECT_TRUE(SameAsLibdraco(Cloud({pos, neg}), Options(10)));
}

// ---------------------------------------------------------------------------------------------
// The New Tsukuba chain outputs: the clouds the service sends.

std::vector<PointCloud> TsukubaChainClouds() {
  std::vector<PointCloud> clouds;
  Pipeline pipeline;
  for (const std::string& id : testing::TsukubaFrameIds()) {
    auto frame = tsukuba::Load(testing::TsukubaDir(), id);
    EXPECT_TRUE(frame.ok()) << frame.status();
    if (!frame.ok()) continue;
    PointCloud cloud;
    EXPECT_TRUE(
        pipeline.Run(PipelineOptions{}, frame->disparity.view(), frame->colour.view(), &cloud)
            .ok());
    clouds.push_back(std::move(cloud));
  }
  return clouds;
}

TEST(DracoExactTsukuba, EveryFrameAtServiceAndOtherSettings) {
  CLOUDCAST_REQUIRE_TSUKUBA();
  const std::vector<PointCloud> clouds = TsukubaChainClouds();
  ASSERT_EQ(clouds.size(), testing::TsukubaFrameIds().size());
  for (std::size_t f = 0; f < clouds.size(); ++f) {
    SCOPED_TRACE("frame " + testing::TsukubaFrameIds()[f]);
    // The service's defaults: 10 bits, raised to keep a quarter of the 3 cm leaf.
    EXPECT_TRUE(SameAsLibdraco(clouds[f], Options(10, 8, 0.0075f)));
    for (int bits : {1, 8, 11, 12, 14, 16, 18, 20, 21, 24, 30}) {
      EXPECT_TRUE(SameAsLibdraco(clouds[f], Options(bits)));
    }
    for (int color_bits : {1, 3, 5, 7}) {
      EXPECT_TRUE(SameAsLibdraco(clouds[f], Options(10, color_bits, 0.0075f)));
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Random clouds: shapes, sizes, extents, colours and options drawn from a seed.

PointCloud RandomCloud(std::mt19937& rng, std::string* what) {
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  const int size_kind = static_cast<int>(rng() % 10);
  const std::size_t n = size_kind == 0  ? 1 + rng() % 4
                        : size_kind < 8 ? 1 + rng() % 3000
                                        : 1 + rng() % 60000;
  // Extents from a millimetre to 10 km, anywhere within 1e4 of the origin.
  const float side = std::pow(10.0f, -3.0f + 7.0f * unit(rng));
  const float offset = (unit(rng) - 0.5f) * std::pow(10.0f, 4.0f * unit(rng));
  const int shape = static_cast<int>(rng() % 5);
  const int colours = static_cast<int>(rng() % 5);
  std::ostringstream os;
  os << n << " points, shape " << shape << ", colours " << colours << ", side " << side
     << ", offset " << offset;
  *what = os.str();
  PointCloud cloud;
  cloud.ResizeUnorganized(n);
  float walk[3] = {offset, offset, offset};
  std::uint8_t rgb[3] = {static_cast<std::uint8_t>(rng()), static_cast<std::uint8_t>(rng()),
                         static_cast<std::uint8_t>(rng())};
  const std::uint32_t palette[4] = {static_cast<std::uint32_t>(rng()),
                                    static_cast<std::uint32_t>(rng()), 0xFF000000u, 0xFFFFFFFFu};
  for (std::size_t i = 0; i < n; ++i) {
    float v[3];
    for (int a = 0; a < 3; ++a) {
      switch (shape) {
        case 0:  // uniform in a box
          v[a] = offset + side * unit(rng);
          break;
        case 1:  // a random walk: small deltas, like a scan
          walk[a] += side * 0.01f * (unit(rng) - 0.5f);
          v[a] = walk[a];
          break;
        case 2:  // a coarse lattice: many repeated values and deltas
          v[a] = offset + side * static_cast<float>(rng() % 8) / 8.0f;
          break;
        case 3:  // clusters with outliers
          v[a] = offset + side * (i % 97 == 0 ? unit(rng) : 0.5f + 0.001f * unit(rng));
          break;
        default:  // flat on the first axis
          v[a] = a == 0 ? offset : offset + side * unit(rng);
          break;
      }
    }
    std::uint32_t rgba = 0;
    switch (colours) {
      case 0:
        rgba = static_cast<std::uint32_t>(rng());
        break;
      case 1:
        rgba = palette[0];
        break;
      case 2:
        rgba = palette[rng() % 4];
        break;
      case 3:  // smooth
        for (std::uint8_t& c : rgb) c = static_cast<std::uint8_t>(c + rng() % 5 - 2);
        rgba = PackRgba(rgb[0], rgb[1], rgb[2]);
        break;
      default:  // a gradient along the cloud
        rgba = PackRgba(static_cast<std::uint8_t>(i), static_cast<std::uint8_t>(i >> 8), 7);
        break;
    }
    cloud.points[i] = {v[0], v[1], v[2], rgba};
  }
  if (rng() % 8 == 0) {  // holes
    for (std::size_t i = rng() % 5; i < n; i += 1 + rng() % 7) cloud.points[i].x = kNaN;
  }
  return cloud;
}

TEST(DracoExactRandom, ManyRoundsOfRandomCloudsAndOptions) {
  const std::uint32_t first_seed = 1000;
  const int rounds = 600;
  for (int round = 0; round < rounds; ++round) {
    const std::uint32_t seed = first_seed + static_cast<std::uint32_t>(round);
    std::mt19937 rng(seed);
    std::string what;
    const PointCloud cloud = RandomCloud(rng, &what);
    DracoOptions o = Options(1 + static_cast<int>(rng() % 30));
    if (rng() % 4 == 0) o.color_bits = 1 + static_cast<int>(rng() % 8);
    if (rng() % 4 == 0) o.max_position_error = std::pow(10.0f, -4.0f + 3.0f * (rng() % 100) / 100);
    if (rng() % 4 == 0) o.decode_speed = static_cast<int>(rng() % 10);
    ASSERT_TRUE(SameAsLibdraco(cloud, o)) << "seed " << seed << ": " << what;
  }
}

// ---------------------------------------------------------------------------------------------
// Our files in other decoders: Debian's draco_decoder, and DecodeDraco (the client library's
// decoder of every reply).

TEST(DracoExactDecoders, DracoDecoderAndOursReadOurFiles) {
  if (std::system("command -v draco_decoder >/dev/null 2>&1") != 0) {
    GTEST_SKIP() << "draco_decoder not installed (Debian package 'draco')";
  }
  const std::string dir = ::testing::TempDir() + "/draco_exact_" + std::to_string(::getpid());
  std::filesystem::create_directories(dir);
  std::vector<std::pair<std::string, PointCloud>> clouds = {
      {"synthetic chain", SyntheticChainCloud(3)},
      {"uniform", UniformCloud(20000, 40, 6.0f, -2.0f)},
      {"one point", Cloud({Point{1.0f, 2.0f, 3.0f, PackRgba(4, 5, 6)}})},
  };
  for (const auto& [name, cloud] : clouds) {
    // Tagged and raw symbol coding, entropy coding off (> 20 bits), fewer colour bits.
    for (const DracoOptions& o : {Options(10), Options(16), Options(24), Options(11, 4)}) {
      SCOPED_TRACE(name + ", " + Describe(o));
      std::string bytes;
      ASSERT_TRUE(SameAsLibdraco(cloud, o, &bytes));
      PointCloud ours;
      ASSERT_TRUE(DecodeDraco(bytes, &ours).ok());
      ASSERT_EQ(ours.size(), cloud.size());
      const std::string drc = dir + "/cloud.drc", ply = dir + "/cloud.ply";
      std::ofstream(drc, std::ios::binary) << bytes;
      const std::string command = "draco_decoder -i " + testing::ShellQuote(drc) + " -o " +
                                  testing::ShellQuote(ply) + " > " +
                                  testing::ShellQuote(dir + "/log.txt") + " 2>&1";
      ASSERT_EQ(std::system(command.c_str()), 0) << testing::ReadText(dir + "/log.txt");
      PointCloud theirs;
      ASSERT_TRUE(LoadCloud(ply, &theirs).ok());
      // Both dequantize with Draco's arithmetic and keep the order: the same floats.
      ASSERT_EQ(theirs.size(), ours.size());
      for (std::size_t i = 0; i < ours.size(); ++i) {
        const Point& a = ours.points[i];
        const Point& b = theirs.points[i];
        ASSERT_TRUE(a.x == b.x && a.y == b.y && a.z == b.z && a.rgba == b.rgba)
            << "point " << i << ": ours " << a.x << " " << a.y << " " << a.z << " " << std::hex
            << a.rgba << ", draco_decoder " << b.x << " " << b.y << " " << b.z << " " << b.rgba;
      }
    }
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace cloudcast
