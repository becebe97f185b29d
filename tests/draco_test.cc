// Tests of the Draco codec: error bound, colours, counts, empty and NaN input, automatic bit
// raising, hostile bytes, option checks, and interoperability with Debian's draco tools.
//
// Matching decoded points to the originals: the kd-tree coder (speed < 10) reorders points, so
// every test cloud gets distinct random 24-bit colours; with 8-bit colour they come back exact
// and identify each point. A wrong colour therefore fails the match, and a wrong position fails
// the bound check.
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/point.h"
// Draco itself (linked through cloudcast_core) is used only to craft files in layouts our
// encoder never writes (float or 16-bit colour, no colour, meshes, raw float positions), and as
// the reference decoder for our own dequantization.
#include "draco/attributes/point_attribute.h"
#include "draco/compression/config/compression_shared.h"
#include "draco/compression/decode.h"
#include "draco/compression/expert_encode.h"
#include "draco/mesh/mesh.h"
#include "draco/point_cloud/point_cloud.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "support/sanitizers.h"

namespace cloudcast {
namespace {

using ::testing::HasSubstr;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

// n distinct random colours (alpha 255).
std::vector<std::uint32_t> DistinctColors(std::size_t n, std::mt19937* rng) {
  std::unordered_set<std::uint32_t> seen;
  std::vector<std::uint32_t> colors;
  colors.reserve(n);
  while (colors.size() < n) {
    const std::uint32_t c = 0xFF000000u | ((*rng)() & 0xFFFFFFu);
    if (seen.insert(c).second) colors.push_back(c);
  }
  return colors;
}

// Uniform points in an axis-aligned box (sides differ, so the "one range" rule matters).
PointCloud RandomCloud(std::size_t n, std::uint32_t seed, float side = 4.0f, float offset = 0.0f) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const std::vector<std::uint32_t> colors = DistinctColors(n, &rng);
  PointCloud cloud;
  cloud.ResizeUnorganized(n);
  for (std::size_t i = 0; i < n; ++i) {
    cloud.points[i] = {offset + side * u(rng), offset - 0.5f * side * u(rng),
                       offset + 3.0f + 0.25f * side * u(rng), colors[i]};
  }
  return cloud;
}

// A depth-camera-like scene: a floor, a back wall and a tilted plane, sampled on a 3 cm grid
// with small jitter, in the camera frame (z 3..12 m).
PointCloud PlanesCloud(std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> jitter(-0.004f, 0.004f);
  std::vector<Point> pts;
  const float s = 0.03f;
  for (float x = -2.0f; x < 2.0f; x += s) {
    for (float z = 3.0f; z < 12.0f; z += s * 3) pts.push_back({x + jitter(rng), 1.5f, z, 0});
    for (float y = -1.5f; y < 1.5f; y += s * 2) pts.push_back({x, y + jitter(rng), 11.5f, 0});
    for (float t = 0.0f; t < 2.0f; t += s * 2) {
      pts.push_back({x, -1.0f + 0.5f * t, 5.0f + t + jitter(rng), 0});
    }
  }
  const std::vector<std::uint32_t> colors = DistinctColors(pts.size(), &rng);
  for (std::size_t i = 0; i < pts.size(); ++i) pts[i].rgba = colors[i];
  PointCloud cloud;
  cloud.ResizeUnorganized(pts.size());
  std::copy(pts.begin(), pts.end(), cloud.points.begin());
  return cloud;
}

struct MatchResult {
  bool ok = false;
  std::string why;
  double max_error = 0.0;  // largest per-coordinate difference
};

// Matches every decoded point to the original point with the same (unique) colour.
MatchResult MatchByColor(const PointCloud& original, const PointCloud& decoded) {
  MatchResult r;
  if (original.size() != decoded.size()) {
    r.why = "count " + std::to_string(decoded.size()) + " != " + std::to_string(original.size());
    return r;
  }
  std::unordered_map<std::uint32_t, std::size_t> index;
  for (std::size_t i = 0; i < original.size(); ++i) index[original.points[i].rgba] = i;
  std::vector<bool> used(original.size(), false);
  for (const Point& p : decoded.points) {
    auto it = index.find(p.rgba);
    if (it == index.end()) {
      std::ostringstream msg;
      msg << "decoded colour 0x" << std::hex << p.rgba << " is not an original colour";
      r.why = msg.str();
      return r;
    }
    if (used[it->second]) {
      r.why = "two decoded points have the colour of original point " + std::to_string(it->second);
      return r;
    }
    used[it->second] = true;
    const Point& o = original.points[it->second];
    r.max_error = std::max({r.max_error, std::fabs(double{p.x} - o.x), std::fabs(double{p.y} - o.y),
                            std::fabs(double{p.z} - o.z)});
  }
  r.ok = true;
  return r;
}

// Half a quantization step for Draco's rule: one range (the largest bbox side) for all axes.
double HalfStep(const PointCloud& cloud, int bits) {
  float lo[3] = {kInf, kInf, kInf}, hi[3] = {-kInf, -kInf, -kInf};
  for (const Point& p : cloud.points) {
    const float v[3] = {p.x, p.y, p.z};
    for (int c = 0; c < 3; ++c) {
      lo[c] = std::min(lo[c], v[c]);
      hi[c] = std::max(hi[c], v[c]);
    }
  }
  double range = 0.0;
  for (int c = 0; c < 3; ++c) range = std::max(range, double{hi[c]} - lo[c]);
  return 0.5 * range / static_cast<double>((std::uint32_t{1} << bits) - 1);
}

DracoOptions Options(int speed, int bits, float max_error = 0.0f) {
  DracoOptions o;
  o.encode_speed = o.decode_speed = speed;
  o.position_bits = bits;
  o.max_position_error = max_error;
  return o;
}

// Runs `body` in a forked child (a gtest death test) limited to 2 GB of address space; the
// child exits 0 when `body` returns true. A regression that makes Draco allocate gigabytes (as
// it did: 24 GB for one flipped byte) then fails this test instead of dragging a shared machine
// into the OOM killer. Sanitizers reserve terabytes of address space, so there is no limit then.
template <typename Body>
[[noreturn]] void RunWithMemoryLimit(Body body) {
  if constexpr (!testing::kUnderAnySanitizer) {
    const rlim_t limit = rlim_t{2} << 30;
    rlimit rl{limit, limit};
    if (::setrlimit(RLIMIT_AS, &rl) != 0) std::fprintf(stderr, "setrlimit failed\n");
  }
  const bool ok = body();
  std::fflush(stderr);
  std::_Exit(ok ? 0 : 1);
}

// ---------------------------------------------------------------------------------------------
// Round trips.

struct RoundTripCase {
  int speed;
  int bits;
};

class DracoRoundTrip : public ::testing::TestWithParam<RoundTripCase> {};

TEST_P(DracoRoundTrip, RandomCloudWithinBoundColoursExact) {
  const RoundTripCase c = GetParam();
  const PointCloud cloud = RandomCloud(20000, 100 + c.speed * 31 + c.bits);
  std::string bytes;
  DracoEncodeInfo info;
  ASSERT_TRUE(EncodeDraco(cloud, Options(c.speed, c.bits), &bytes, &info).ok());
  EXPECT_EQ(info.position_bits, c.bits);
  EXPECT_EQ(info.bytes, bytes.size());
  PointCloud decoded;
  ASSERT_TRUE(DecodeDraco(bytes, &decoded).ok());
  EXPECT_EQ(decoded.height, 1u);
  EXPECT_EQ(decoded.width, decoded.size());
  const MatchResult m = MatchByColor(cloud, decoded);
  ASSERT_TRUE(m.ok) << m.why;
  EXPECT_LE(m.max_error, info.position_error_bound);
  // The bound is tight: it is half a step plus float slack, and 20,000 uniform points come
  // within a few percent of the worst case (so a loose bound, e.g. per-axis ranges, fails here).
  const double half = HalfStep(cloud, c.bits);
  EXPECT_GE(info.position_error_bound, half);
  // Float rounding adds a few ulps of the coordinates (about 1e-6 relative to 4 m here).
  EXPECT_LE(info.position_error_bound, half * 1.01 + 4e-6);
  if (c.bits <= 16) {
    EXPECT_GE(m.max_error, 0.9 * half);
  }
}

TEST_P(DracoRoundTrip, PlanesCloudWithinBoundColoursExact) {
  const RoundTripCase c = GetParam();
  const PointCloud cloud = PlanesCloud(7 + c.speed);
  ASSERT_GT(cloud.size(), 5000u);
  std::string bytes;
  DracoEncodeInfo info;
  ASSERT_TRUE(EncodeDraco(cloud, Options(c.speed, c.bits, 0.0075f), &bytes, &info).ok());
  EXPECT_GE(info.position_bits, c.bits);
  EXPECT_LE(info.position_error_bound, 0.0075f);
  PointCloud decoded;
  ASSERT_TRUE(DecodeDraco(bytes, &decoded).ok());
  const MatchResult m = MatchByColor(cloud, decoded);
  ASSERT_TRUE(m.ok) << m.why;
  EXPECT_LE(m.max_error, info.position_error_bound);
  EXPECT_LE(m.max_error, 0.0075);
}

INSTANTIATE_TEST_SUITE_P(SpeedsAndBits, DracoRoundTrip,
                         ::testing::Values(RoundTripCase{10, 11}, RoundTripCase{10, 16},
                                           RoundTripCase{7, 11}, RoundTripCase{5, 8},
                                           RoundTripCase{5, 14}, RoundTripCase{3, 12},
                                           RoundTripCase{0, 11}, RoundTripCase{0, 20},
                                           RoundTripCase{10, 30}, RoundTripCase{5, 30}),
                         [](const ::testing::TestParamInfo<RoundTripCase>& info) {
                           return "speed" + std::to_string(info.param.speed) + "_bits" +
                                  std::to_string(info.param.bits);
                         });

// Far from the origin the float slack dominates at high bit depths; the bound must still hold.
TEST(DracoCodec, BoundHoldsFarFromOriginAtAllBitDepths) {
  for (float offset : {0.0f, 100.0f, -3000.0f}) {
    for (int bits : {1, 4, 12, 20, 23, 24, 26, 30}) {
      const PointCloud cloud = RandomCloud(3000, bits * 7 + 1, 9.0f, offset);
      std::string bytes;
      DracoEncodeInfo info;
      ASSERT_TRUE(EncodeDraco(cloud, Options(bits % 2 ? 10 : 5, bits), &bytes, &info).ok());
      PointCloud decoded;
      ASSERT_TRUE(DecodeDraco(bytes, &decoded).ok());
      const MatchResult m = MatchByColor(cloud, decoded);
      ASSERT_TRUE(m.ok) << m.why;
      EXPECT_LE(m.max_error, info.position_error_bound) << "offset " << offset << " bits " << bits;
    }
  }
}

TEST(DracoCodec, SequentialSpeedKeepsPointOrder) {
  const PointCloud cloud = PlanesCloud(3);
  std::string bytes;
  ASSERT_TRUE(EncodeDraco(cloud, Options(10, 14), &bytes).ok());
  PointCloud decoded;
  ASSERT_TRUE(DecodeDraco(bytes, &decoded).ok());
  ASSERT_EQ(decoded.size(), cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    ASSERT_EQ(decoded.points[i].rgba, cloud.points[i].rgba) << i;
  }
}

TEST(DracoCodec, EncodingIsDeterministicAcrossCalls) {
  // The encoder reuses per-thread buffers; a bigger or NaN-holding cloud in between must not
  // leak into the next frame.
  const PointCloud a = RandomCloud(5000, 1);
  PointCloud b = RandomCloud(20000, 2, 50.0f);
  b.points[17].x = kNaN;
  std::string first, between, second;
  ASSERT_TRUE(EncodeDraco(a, Options(5, 11), &first).ok());
  ASSERT_TRUE(EncodeDraco(b, Options(5, 11), &between).ok());
  ASSERT_TRUE(EncodeDraco(a, Options(5, 11), &second).ok());
  EXPECT_EQ(first, second);
  PointCloud decoded;
  ASSERT_TRUE(DecodeDraco(second, &decoded).ok());
  EXPECT_TRUE(MatchByColor(a, decoded).ok);
}

TEST(DracoCodec, FewerColourBitsGiveCoarseColoursAndFewerBytes) {
  PointCloud cloud = RandomCloud(20000, 5);
  std::string full, coarse;
  DracoOptions o = Options(10, 11);
  ASSERT_TRUE(EncodeDraco(cloud, o, &full).ok());
  o.color_bits = 3;
  ASSERT_TRUE(EncodeDraco(cloud, o, &coarse).ok());
  EXPECT_LT(coarse.size(), full.size() * 9 / 10);
  PointCloud decoded;
  ASSERT_TRUE(DecodeDraco(coarse, &decoded).ok());
  ASSERT_EQ(decoded.size(), cloud.size());  // speed 10 keeps order
  std::unordered_set<int> levels;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const std::uint32_t a = cloud.points[i].rgba, b = decoded.points[i].rgba;
    const int pairs[3][2] = {
        {RedOf(a), RedOf(b)}, {GreenOf(a), GreenOf(b)}, {BlueOf(a), BlueOf(b)}};
    for (const auto& p : pairs) {
      // 8 levels over 0..255: steps of 255/7, so at most half a step off.
      EXPECT_LE(std::abs(p[0] - p[1]), 19) << i;
      levels.insert(p[1]);
    }
    EXPECT_EQ(AlphaOf(b), 255);
  }
  EXPECT_EQ(levels.size(), 8u);
  EXPECT_TRUE(levels.count(0) && levels.count(255));
}

// ---------------------------------------------------------------------------------------------
// Empty, NaN and degenerate clouds.

TEST(DracoCodec, EmptyCloudRoundTrips) {
  for (int speed : {0, 5, 10}) {
    for (float max_error : {0.0f, 0.0075f}) {
      PointCloud empty;
      std::string bytes;
      DracoEncodeInfo info;
      ASSERT_TRUE(EncodeDraco(empty, Options(speed, 11, max_error), &bytes, &info).ok());
      EXPECT_FALSE(bytes.empty());
      EXPECT_EQ(info.bytes, bytes.size());
      EXPECT_EQ(info.position_error_bound, 0.0f);
      PointCloud decoded = RandomCloud(10, 1);  // must be overwritten
      decoded.height = 2;
      ASSERT_TRUE(DecodeDraco(bytes, &decoded).ok());
      EXPECT_TRUE(decoded.empty());
      EXPECT_EQ(decoded.height, 1u);
      EXPECT_EQ(decoded.width, 0u);
    }
  }
}

TEST(DracoCodec, NonFinitePointsAreDropped) {
  PointCloud cloud = RandomCloud(1000, 9);
  const float bad[] = {kNaN, kInf, -kInf};
  std::size_t dropped = 0;
  for (std::size_t i = 0; i < cloud.size(); i += 7) {
    (&cloud.points[i].x)[i % 3] = bad[(i / 7) % 3];
    ++dropped;
  }
  PointCloud finite;
  for (const Point& p : cloud.points) {
    if (std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z)) finite.points.push_back(p);
  }
  ASSERT_EQ(finite.size(), cloud.size() - dropped);
  for (int speed : {5, 10}) {
    std::string bytes;
    DracoEncodeInfo info;
    ASSERT_TRUE(EncodeDraco(cloud, Options(speed, 12), &bytes, &info).ok());
    PointCloud decoded;
    ASSERT_TRUE(DecodeDraco(bytes, &decoded).ok());
    const MatchResult m = MatchByColor(finite, decoded);
    ASSERT_TRUE(m.ok) << m.why;
    EXPECT_LE(m.max_error, info.position_error_bound);
    // The bound comes from the finite points only.
    EXPECT_LE(info.position_error_bound, HalfStep(finite, 12) * 1.01 + 1e-6);
  }
}

TEST(DracoCodec, OrganizedCloudWithHolesDecodesUnorganized) {
  PointCloud cloud = RandomCloud(64 * 48, 4);
  cloud.width = 64;
  cloud.height = 48;
  std::size_t finite = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    if (i % 3 == 0) {
      cloud.points[i] = {kNaN, kNaN, kNaN, 0};
    } else {
      ++finite;
    }
  }
  std::string bytes;
  ASSERT_TRUE(EncodeDraco(cloud, Options(5, 11), &bytes).ok());
  PointCloud decoded;
  ASSERT_TRUE(DecodeDraco(bytes, &decoded).ok());
  EXPECT_EQ(decoded.size(), finite);
  EXPECT_EQ(decoded.height, 1u);
  EXPECT_EQ(decoded.width, finite);
}

TEST(DracoCodec, AllNaNCloudEncodesAsEmpty) {
  PointCloud cloud;
  cloud.points.assign(100, Point{kNaN, 0.0f, 1.0f, 0xFFFFFFFFu});
  std::string bytes;
  ASSERT_TRUE(EncodeDraco(cloud, Options(5, 11, 0.0075f), &bytes).ok());
  PointCloud decoded;
  ASSERT_TRUE(DecodeDraco(bytes, &decoded).ok());
  EXPECT_TRUE(decoded.empty());
}

TEST(DracoCodec, SinglePointAndIdenticalPointsDecodeExactly) {
  for (std::size_t n : {1u, 50u}) {
    for (int speed : {5, 10}) {
      PointCloud cloud;
      cloud.points.assign(n, Point{1.25f, -3.5f, 7.0f, PackRgba(10, 20, 30)});
      std::string bytes;
      DracoEncodeInfo info;
      ASSERT_TRUE(EncodeDraco(cloud, Options(speed, 11, 0.0075f), &bytes, &info).ok());
      EXPECT_EQ(info.position_error_bound, 0.0f);
      PointCloud decoded;
      ASSERT_TRUE(DecodeDraco(bytes, &decoded).ok());
      ASSERT_EQ(decoded.size(), n);
      for (const Point& p : decoded.points) {
        EXPECT_EQ(p.x, 1.25f);
        EXPECT_EQ(p.y, -3.5f);
        EXPECT_EQ(p.z, 7.0f);
        EXPECT_EQ(p.rgba, PackRgba(10, 20, 30));
      }
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Bits chosen from max_position_error.

TEST(DracoCodec, BitsRaisedForLargeExtent) {
  // 100 m extent, 7.5 mm: 100 / (2 * (2^b - 1)) <= 0.0075 needs 2^b - 1 >= 6667, so b = 13.
  PointCloud cloud = RandomCloud(20000, 11, 10.0f);
  cloud.points[0].x = -50.0f;
  cloud.points[1].x = 50.0f;
  for (int speed : {5, 10}) {
    std::string bytes;
    DracoEncodeInfo info;
    ASSERT_TRUE(EncodeDraco(cloud, Options(speed, 11, 0.0075f), &bytes, &info).ok());
    EXPECT_EQ(info.position_bits, 13);
    EXPECT_LE(info.position_error_bound, 0.0075f);
    EXPECT_GT(HalfStep(cloud, 12), 0.0075);  // 12 bits would not have been enough
    PointCloud decoded;
    ASSERT_TRUE(DecodeDraco(bytes, &decoded).ok());
    const MatchResult m = MatchByColor(cloud, decoded);
    ASSERT_TRUE(m.ok) << m.why;
    EXPECT_LE(m.max_error, info.position_error_bound);
    EXPECT_LE(m.max_error, 0.0075);
  }
}

TEST(DracoCodec, BitsNeverLoweredAndOnlyRaisedWhenNeeded) {
  const PointCloud cloud = RandomCloud(2000, 12, 4.0f);  // largest side 4 m
  DracoEncodeInfo info;
  std::string bytes;
  // 11 bits give 4 / 4094 = 0.98 mm, well under 7.5 mm: unchanged.
  ASSERT_TRUE(EncodeDraco(cloud, Options(10, 11, 0.0075f), &bytes, &info).ok());
  EXPECT_EQ(info.position_bits, 11);
  ASSERT_TRUE(EncodeDraco(cloud, Options(10, 16, 0.0075f), &bytes, &info).ok());
  EXPECT_EQ(info.position_bits, 16);
  // 0.1 mm on 4 m needs 2^b - 1 >= 20000: 15 bits.
  ASSERT_TRUE(EncodeDraco(cloud, Options(10, 1, 0.0001f), &bytes, &info).ok());
  EXPECT_EQ(info.position_bits, 15);
  EXPECT_LE(info.position_error_bound, 0.0001f);
}

TEST(DracoCodec, UnreachableErrorIsAnError) {
  PointCloud cloud = RandomCloud(100, 13, 1000.0f);
  std::string bytes;
  const absl::Status s = EncodeDraco(cloud, Options(10, 11, 1e-7f), &bytes);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("max_position_error"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("30"), std::string::npos) << s.message();
}

// Encodes and decodes `cloud` at speed 10 with 21, 24 and 30 bits; false on any failure.
bool HighBitsRoundTrip(const PointCloud& cloud) {
  for (int bits : {21, 24, 30}) {
    std::string bytes;
    DracoEncodeInfo info;
    const absl::Status s = EncodeDraco(cloud, Options(10, bits), &bytes, &info);
    PointCloud decoded;
    if (!s.ok() || !DecodeDraco(bytes, &decoded).ok()) {
      std::fprintf(stderr, "bits %d: %s\n", bits, s.ToString().c_str());
      return false;
    }
    const MatchResult m = MatchByColor(cloud, decoded);
    if (!m.ok || m.max_error > info.position_error_bound) {
      std::fprintf(stderr, "bits %d: %s max error %g\n", bits, m.why.c_str(), m.max_error);
      return false;
    }
  }
  return true;
}

TEST(DracoCodec, HighBitsAtSequentialSpeedStayCheap) {
  // Draco's sequential entropy coder alone would need a 4 GB table at 30 bits.
  const PointCloud cloud = RandomCloud(20000, 14, 4.0f);
  EXPECT_EXIT(RunWithMemoryLimit([&] { return HighBitsRoundTrip(cloud); }),
              ::testing::ExitedWithCode(0), "");
}

// ---------------------------------------------------------------------------------------------
// Options.

TEST(DracoOptions, DefaultsAreValid) { EXPECT_TRUE(DracoOptions{}.Validate().ok()); }

TEST(DracoOptions, BadValuesNameTheField) {
  struct Case {
    const char* field;
    void (*set)(DracoOptions*);
  };
  const Case cases[] = {
      {"draco.position_bits is 0; it must be in [1, 30]",
       [](DracoOptions* o) { o->position_bits = 0; }},
      {"draco.position_bits", [](DracoOptions* o) { o->position_bits = 31; }},
      {"draco.color_bits is 9; it must be in [1, 8]", [](DracoOptions* o) { o->color_bits = 9; }},
      {"draco.color_bits", [](DracoOptions* o) { o->color_bits = 0; }},
      {"draco.encode_speed", [](DracoOptions* o) { o->encode_speed = -1; }},
      {"draco.encode_speed", [](DracoOptions* o) { o->encode_speed = 11; }},
      {"draco.decode_speed", [](DracoOptions* o) { o->decode_speed = 11; }},
      {"draco.max_position_error", [](DracoOptions* o) { o->max_position_error = -0.001f; }},
      {"draco.max_position_error", [](DracoOptions* o) { o->max_position_error = kNaN; }},
      {"draco.max_position_error", [](DracoOptions* o) { o->max_position_error = kInf; }},
  };
  const PointCloud cloud = RandomCloud(10, 1);
  for (const Case& c : cases) {
    DracoOptions o;
    c.set(&o);
    const absl::Status s = o.Validate();
    ASSERT_FALSE(s.ok()) << c.field;
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(s.message().find(c.field), std::string::npos) << s.message();
    std::string bytes = "untouched";
    const absl::Status e = EncodeDraco(cloud, o, &bytes);
    EXPECT_FALSE(e.ok()) << c.field;
    EXPECT_NE(e.message().find(c.field), std::string::npos) << e.message();
    EXPECT_EQ(bytes, "untouched");
  }
}

// ---------------------------------------------------------------------------------------------
// Hostile bytes: errors, never crashes.

std::vector<std::string> SampleEncodings() {
  std::vector<std::string> out;
  const PointCloud cloud = PlanesCloud(21);
  for (int speed : {0, 5, 7, 10}) {
    std::string bytes;
    EXPECT_TRUE(EncodeDraco(cloud, Options(speed, 11), &bytes).ok());
    out.push_back(bytes);
  }
  return out;
}

TEST(DracoDecode, GarbageIsAnError) {
  PointCloud out;
  EXPECT_FALSE(DecodeDraco("", &out).ok());
  EXPECT_FALSE(DecodeDraco("DRACO", &out).ok());
  EXPECT_FALSE(DecodeDraco("not a draco file at all, just text", &out).ok());
  std::mt19937 rng(5);
  for (int i = 0; i < 200; ++i) {
    std::string junk(1 + rng() % 4096, '\0');
    for (char& c : junk) c = static_cast<char>(rng());
    EXPECT_FALSE(DecodeDraco(junk, &out).ok());
  }
}

// A POSITION attribute of type DT_BOOL holding bytes other than 0 and 1: Draco's ConvertValue
// reads them as C++ bools (undefined behaviour, which UBSan reports in Draco's header). Found by
// fuzz/draco_decode_fuzzer.cc; the reproducer is fuzz/corpus/draco_decode/regression_bool_position.
TEST(DracoDecode, BooleanPositionsAreRefused) {
  const std::string bytes(
      "\x44\x52\x41\x43\x4f\x02\x03\x00\x00\x00\x00\x01\x00\x00\x00\x01\x02\x00\x0b"
      "\x03\x00\x00\x03\x03\x02\x01\x01\x00\x00\x00\x01\x02\x00\x09\x03\xfc\xff\x02"
      "\x03\x00\x00\x01\x01\x00\x03",
      45);
  PointCloud out;
  const absl::Status s = DecodeDraco(bytes, &out);
  EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss) << s;
  EXPECT_NE(s.message().find("POSITION"), std::string_view::npos) << s;
  EXPECT_TRUE(out.empty());
}

TEST(DracoDecode, BadHeaderIsAnError) {
  for (const std::string& good : SampleEncodings()) {
    PointCloud out;
    ASSERT_TRUE(DecodeDraco(good, &out).ok());
    std::string bad = good;
    bad[0] = 'X';  // magic "DRACO"
    EXPECT_FALSE(DecodeDraco(bad, &out).ok());
    bad = good;
    bad[5] = 99;  // major version
    EXPECT_FALSE(DecodeDraco(bad, &out).ok());
    bad = good;
    bad[7] = 9;  // geometry type
    EXPECT_FALSE(DecodeDraco(bad, &out).ok());
  }
}

TEST(DracoDecode, TruncationIsAnError) {
  // Every length through the headers and attribute descriptors, then every 97th byte, and the
  // last 64 (all ~120,000 prefixes would take 20 s).
  for (const std::string& good : SampleEncodings()) {
    for (std::size_t len = 0; len < good.size();
         len += (len < 512 || len + 64 >= good.size() ? 1 : 97)) {
      PointCloud out;
      EXPECT_FALSE(DecodeDraco(std::string_view(good).substr(0, len), &out).ok())
          << "prefix of " << len << " of " << good.size() << " bytes decoded";
    }
  }
}

// Flips 1..4 random bytes of each encoding many times; false (with a note on stderr) if a
// decode that succeeds yields an invalid cloud, or if no corruption was ever detected.
bool CorruptionsDecodeSafely(const std::vector<std::string>& encodings) {
  std::mt19937 rng(17);
  int errors = 0, successes = 0;
  for (const std::string& good : encodings) {
    for (int trial = 0; trial < 500; ++trial) {
      std::string bad = good;
      const int flips = 1 + rng() % 4;
      for (int f = 0; f < flips; ++f) {
        // Half the trials hit the first 64 bytes: header, counts, attribute descriptors.
        const std::size_t at =
            trial % 2 ? rng() % std::min<std::size_t>(64, bad.size()) : rng() % bad.size();
        bad[at] = static_cast<char>(bad[at] ^ (1 + rng() % 255));
      }
      PointCloud out;
      if (!DecodeDraco(bad, &out).ok()) {
        ++errors;
        continue;
      }
      ++successes;
      if (out.height != 1 || out.width != out.size()) {
        std::fprintf(stderr, "trial %d: not an unorganized cloud\n", trial);
        return false;
      }
      for (const Point& p : out.points) {
        if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z) ||
            AlphaOf(p.rgba) != 255) {
          std::fprintf(stderr, "trial %d: non-finite point or alpha != 255\n", trial);
          return false;
        }
      }
    }
  }
  std::fprintf(stderr, "corrupted inputs: %d errors, %d decoded\n", errors, successes);
  return errors > 0;
}

TEST(DracoDecode, RandomCorruptionNeverCrashes) {
  // Flipped payload bytes may still decode (into other points): allowed, as long as the call
  // returns and a success yields a sane cloud.
  const std::vector<std::string> encodings = SampleEncodings();
  EXPECT_EXIT(RunWithMemoryLimit([&] { return CorruptionsDecodeSafely(encodings); }),
              ::testing::ExitedWithCode(0), "");
}

// The point count sits right after the 11-byte header in Draco 2.2 point clouds (both coders).
std::string WithPointCount(std::string bytes, std::uint32_t count) {
  for (int i = 0; i < 4; ++i) bytes[11 + i] = static_cast<char>(count >> (8 * i));
  return bytes;
}

TEST(DracoDecode, HugePointCountIsRefusedCheaply) {
  const PointCloud cloud = RandomCloud(3000, 8);
  for (int speed : {5, 10}) {
    std::string good;
    ASSERT_TRUE(EncodeDraco(cloud, Options(speed, 11), &good).ok());
    ASSERT_EQ(WithPointCount(good, 3000), good) << "the point count is not where expected";
    for (std::uint32_t count : {0x7FFFFFFFu, (1u << 24) + 1, 1u << 21}) {
      const std::string bad = WithPointCount(good, count);
      EXPECT_EXIT(RunWithMemoryLimit([&] {
                    PointCloud out;
                    const absl::Status s = DecodeDraco(bad, &out);
                    std::fprintf(stderr, "%s\n", s.ToString().c_str());
                    return !s.ok() && s.message().find("claims") != std::string::npos;
                  }),
                  ::testing::ExitedWithCode(0), "")
          << "speed " << speed << " count " << count;
    }
    // A count within the caps but wrong runs out of data.
    PointCloud out;
    EXPECT_FALSE(DecodeDraco(WithPointCount(good, 3001), &out).ok());
  }
}

// ---------------------------------------------------------------------------------------------
// Files in layouts our encoder does not write.

std::string EncodeWithDraco(const draco::PointCloud& pc, int speed = 10, int position_bits = 0) {
  draco::ExpertEncoder encoder(pc);
  encoder.SetSpeedOptions(speed, speed);
  if (position_bits > 0) {
    const int pos = pc.GetNamedAttributeId(draco::GeometryAttribute::POSITION);
    encoder.SetAttributeQuantization(pos, position_bits);
  }
  draco::EncoderBuffer buffer;
  const draco::Status s = encoder.EncodeToBuffer(&buffer);
  EXPECT_TRUE(s.ok()) << s.error_msg();
  return std::string(buffer.data(), buffer.size());
}

template <typename T>
int AddAttribute(draco::PointCloud* pc, draco::GeometryAttribute::Type type, int components,
                 draco::DataType data_type, bool normalized, const std::vector<T>& values) {
  auto att = std::make_unique<draco::PointAttribute>();
  att->Init(type, components, data_type, normalized, values.size() / components);
  std::memcpy(att->GetAddress(draco::AttributeValueIndex(0)), values.data(),
              values.size() * sizeof(T));
  return pc->AddAttribute(std::move(att));
}

TEST(DracoDecode, ColourTypesAndMissingColour) {
  const std::vector<float> xyz = {0, 0, 1, 1, 0, 1, 0, 1, 2, 1, 1, 3};
  struct Case {
    const char* name;
    std::uint32_t expected[4];
    std::function<void(draco::PointCloud*)> add_color;
  };
  const Case cases[] = {
      {"none", {0xFFFFFFFF, 0xFFFFFFFF, 0xFFFFFFFF, 0xFFFFFFFF}, [](draco::PointCloud*) {}},
      {"float01",
       {PackRgba(255, 0, 0), PackRgba(0, 128, 0), PackRgba(0, 0, 255), PackRgba(255, 255, 255)},
       [](draco::PointCloud* pc) {
         AddAttribute<float>(pc, draco::GeometryAttribute::COLOR, 3, draco::DT_FLOAT32, false,
                             {1, 0, 0, 0, 0.5f, 0, 0, 0, 1, 1, 1, 1});
       }},
      {"uint16",
       {PackRgba(255, 0, 0), PackRgba(0, 128, 0), PackRgba(0, 0, 255), PackRgba(1, 2, 3)},
       [](draco::PointCloud* pc) {
         AddAttribute<std::uint16_t>(pc, draco::GeometryAttribute::COLOR, 3, draco::DT_UINT16, true,
                                     {65535, 0, 0, 0, 32896, 0, 0, 0, 65535, 257, 514, 771});
       }},
      {"rgba8",
       {PackRgba(1, 2, 3), PackRgba(4, 5, 6), PackRgba(7, 8, 9), PackRgba(10, 11, 12)},
       [](draco::PointCloud* pc) {
         AddAttribute<std::uint8_t>(pc, draco::GeometryAttribute::COLOR, 4, draco::DT_UINT8, true,
                                    {1, 2, 3, 0, 4, 5, 6, 9, 7, 8, 9, 200, 10, 11, 12, 255});
       }},
  };
  for (const Case& c : cases) {
    draco::PointCloud pc;
    pc.set_num_points(4);
    AddAttribute<float>(&pc, draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32, false, xyz);
    c.add_color(&pc);
    PointCloud out;
    // Speed 10 and unquantized: sequential, order and values kept.
    ASSERT_TRUE(DecodeDraco(EncodeWithDraco(pc), &out).ok()) << c.name;
    ASSERT_EQ(out.size(), 4u) << c.name;
    for (int i = 0; i < 4; ++i) {
      EXPECT_EQ(out.points[i].x, xyz[3 * i]) << c.name;
      EXPECT_EQ(out.points[i].y, xyz[3 * i + 1]) << c.name;
      EXPECT_EQ(out.points[i].z, xyz[3 * i + 2]) << c.name;
      EXPECT_EQ(out.points[i].rgba, c.expected[i]) << c.name << " point " << i;
    }
  }
}

TEST(DracoDecode, UnquantizedNonFinitePositionsAreDropped) {
  draco::PointCloud pc;
  pc.set_num_points(3);
  AddAttribute<float>(&pc, draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32, false,
                      {0, 0, 1, kNaN, 0, 1, 2, 2, 2});
  PointCloud out;
  ASSERT_TRUE(DecodeDraco(EncodeWithDraco(pc), &out).ok());
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out.points[1].x, 2.0f);
}

TEST(DracoDecode, MissingPositionIsAnError) {
  draco::PointCloud pc;
  pc.set_num_points(2);
  AddAttribute<std::uint8_t>(&pc, draco::GeometryAttribute::COLOR, 3, draco::DT_UINT8, true,
                             {1, 2, 3, 4, 5, 6});
  PointCloud out;
  const absl::Status s = DecodeDraco(EncodeWithDraco(pc), &out);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("POSITION"), std::string::npos) << s.message();
}

// Found by the cloud-readers fuzzer: a 42-byte kd-tree file of the legacy bitstream 2.0 that
// libdraco took 33 s over, and in the fuzz build decoded into 1.4 billion points sharing their
// values (DecodeDraco then asked for a 22 GB cloud). Refused from its header now.
TEST(DracoDecode, LegacyBitstreamsAreRefusedFromTheHeader) {
  const unsigned char bytes[] = {
      0x44, 0x52, 0x41, 0x43, 0x4f, 0x02, 0x00, 0x00, 0x01, 0x00, 0x00, 0x14, 0xce, 0x00,
      0x00, 0x02, 0x01, 0x00, 0x09, 0x03, 0x00, 0x00, 0x02, 0x02, 0x03, 0x01, 0x01, 0x02,
      0x01, 0x01, 0x01, 0x01, 0x00, 0x00, 0x00, 0x65, 0x6c, 0x65, 0x6d, 0x65, 0x6e, 0x74};
  PointCloud out;
  const absl::Status s =
      DecodeDraco(std::string_view(reinterpret_cast<const char*>(bytes), sizeof(bytes)), &out);
  EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss) << s;
  EXPECT_THAT(std::string(s.message()), HasSubstr("bitstream version 2.0 predates 2.2")) << s;
  EXPECT_EQ(out.size(), 0u);
}

// Found by the draco-decode fuzzer: a 69-byte kd-tree cloud of bitstream 2.2 (254 points) whose
// legacy attribute decoding made libdraco allocate and zero 6.8 GB, past the point and attribute
// caps. Refused from its header now (kd-tree clouds are read from bitstream 2.3 on).
TEST(DracoDecode, LegacyKdTreeCloudsAreRefusedFromTheHeader) {
  // fuzz/corpus/draco_decode/kdtree_v22_allocation_bomb
  const unsigned char bytes[] = {
      0x44, 0x52, 0x41, 0x43, 0x4f, 0x02, 0x02, 0x00, 0x01, 0x00, 0x00, 0xfe, 0x00, 0x00,
      0x00, 0x01, 0x02, 0x00, 0x09, 0x03, 0x00, 0x00, 0x02, 0x02, 0x03, 0x01, 0x01, 0x01,
      0x00, 0x01, 0x01, 0x01, 0x22, 0x00, 0x26, 0x01, 0x01, 0x00, 0x01, 0x01, 0x00, 0x01,
      0x01, 0x00, 0x01, 0x01, 0x00, 0x01, 0x01, 0x01, 0x01, 0x00, 0x01, 0x01, 0x00, 0x01,
      0x03, 0x45, 0x00, 0x00, 0x01, 0x00, 0x80, 0x01, 0x00, 0x01, 0x01, 0x00, 0xf8,
  };
  PointCloud out;
  const absl::Status s =
      DecodeDraco(std::string_view(reinterpret_cast<const char*>(bytes), sizeof(bytes)), &out);
  EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss) << s;
  EXPECT_THAT(std::string(s.message()), HasSubstr("kd-tree cloud of bitstream version 2.2")) << s;
  EXPECT_EQ(out.size(), 0u);
}

TEST(DracoDecode, MeshDecodesAsPoints) {
  // A tetrahedron: 4 vertices shared by 4 consistently oriented faces (with inconsistent
  // orientation Edgebreaker splits the vertices, legitimately giving more points).
  draco::Mesh mesh;
  mesh.set_num_points(4);
  AddAttribute<float>(&mesh, draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32, false,
                      {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1});
  AddAttribute<std::uint8_t>(&mesh, draco::GeometryAttribute::COLOR, 3, draco::DT_UINT8, true,
                             {255, 0, 0, 0, 255, 0, 0, 0, 255, 9, 9, 9});
  using F = draco::Mesh::Face;
  for (F f : {F{draco::PointIndex(0), draco::PointIndex(2), draco::PointIndex(1)},
              F{draco::PointIndex(0), draco::PointIndex(1), draco::PointIndex(3)},
              F{draco::PointIndex(0), draco::PointIndex(3), draco::PointIndex(2)},
              F{draco::PointIndex(1), draco::PointIndex(2), draco::PointIndex(3)}}) {
    mesh.AddFace(f);
  }
  {
    draco::ExpertEncoder encoder(mesh);
    encoder.SetEncodingMethod(draco::MESH_SEQUENTIAL_ENCODING);
    encoder.SetAttributeQuantization(0, 14);
    draco::EncoderBuffer buffer;
    ASSERT_TRUE(encoder.EncodeToBuffer(&buffer).ok());
    PointCloud out;
    ASSERT_TRUE(DecodeDraco(std::string_view(buffer.data(), buffer.size()), &out).ok());
    ASSERT_EQ(out.size(), 4u);
    std::vector<std::uint32_t> colors;
    for (const Point& p : out.points) {
      colors.push_back(p.rgba);
      EXPECT_NEAR(p.x + p.y + p.z, p.rgba == PackRgba(255, 0, 0) ? 0.0f : 1.0f, 1e-4f);
    }
    std::sort(colors.begin(), colors.end());
    std::vector<std::uint32_t> want = {PackRgba(255, 0, 0), PackRgba(0, 255, 0),
                                       PackRgba(0, 0, 255), PackRgba(9, 9, 9)};
    std::sort(want.begin(), want.end());
    EXPECT_EQ(colors, want);
  }
  // libdraco's Edgebreaker decoder is kept away from untrusted bytes (see DecodeCapped): the
  // same mesh coded with it is refused with a message that says how to re-encode it.
  draco::ExpertEncoder encoder(mesh);
  encoder.SetEncodingMethod(draco::MESH_EDGEBREAKER_ENCODING);
  draco::EncoderBuffer buffer;
  ASSERT_TRUE(encoder.EncodeToBuffer(&buffer).ok());
  PointCloud out;
  const absl::Status s = DecodeDraco(std::string_view(buffer.data(), buffer.size()), &out);
  EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss) << s;
  EXPECT_THAT(std::string(s.message()), HasSubstr("Edgebreaker-coded meshes are not read"));
  EXPECT_THAT(std::string(s.message()), HasSubstr("-point_cloud"));
}


// ---------------------------------------------------------------------------------------------
// Debian's draco tools (package `draco`).

std::string FindTool(const std::string& name) {
  const char* path = std::getenv("PATH");
  std::stringstream dirs(path ? path : "/usr/bin");
  std::string dir;
  while (std::getline(dirs, dir, ':')) {
    const std::string candidate = dir + "/" + name;
    if (!dir.empty() && ::access(candidate.c_str(), X_OK) == 0) return candidate;
  }
  return "";
}

class TempDir {
 public:
  TempDir() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "draco_test_XXXXXX").string();
    path_ = ::mkdtemp(tmpl.data()) ? tmpl : "";
  }
  ~TempDir() {
    std::error_code ec;
    if (!path_.empty()) std::filesystem::remove_all(path_, ec);
  }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

TEST(DracoTools, DecodesFileMadeByDracoEncoder) {
  const std::string tool = FindTool("draco_encoder");
  if (tool.empty()) GTEST_SKIP() << "draco_encoder not found; install Debian package `draco`";
  TempDir dir;
  ASSERT_FALSE(dir.path().empty());
  const PointCloud cloud = PlanesCloud(31);
  {
    std::ofstream ply(dir.path() + "/in.ply");
    ply << "ply\nformat ascii 1.0\nelement vertex " << cloud.size()
        << "\nproperty float x\nproperty float y\nproperty float z\n"
           "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n";
    ply.precision(9);
    for (const Point& p : cloud.points) {
      ply << p.x << ' ' << p.y << ' ' << p.z << ' ' << int{RedOf(p.rgba)} << ' '
          << int{GreenOf(p.rgba)} << ' ' << int{BlueOf(p.rgba)} << '\n';
    }
  }
  for (const char* level : {"0", "7", "10"}) {
    const std::string drc = dir.path() + "/out" + level + ".drc";
    const std::string cmd = tool + " -point_cloud -qp 14 -cl " + level + " -i " + dir.path() +
                            "/in.ply -o " + drc + " > " + dir.path() + "/log.txt 2>&1";
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd << "\n" << ReadFile(dir.path() + "/log.txt");
    PointCloud decoded;
    const absl::Status s = DecodeDraco(ReadFile(drc), &decoded);
    ASSERT_TRUE(s.ok()) << s;
    const MatchResult m = MatchByColor(cloud, decoded);
    ASSERT_TRUE(m.ok) << "level " << level << ": " << m.why;
    EXPECT_LE(m.max_error, HalfStep(cloud, 14) * 1.01 + 1e-5) << "level " << level;
  }
}

TEST(DracoTools, DracoDecoderReadsOurFiles) {
  const std::string tool = FindTool("draco_decoder");
  if (tool.empty()) GTEST_SKIP() << "draco_decoder not found; install Debian package `draco`";
  TempDir dir;
  ASSERT_FALSE(dir.path().empty());
  const PointCloud cloud = PlanesCloud(41);
  for (int speed : {0, 10}) {
    std::string bytes;
    // 24 bits at speed 10 stores raw values (no built-in entropy coding): also standard Draco.
    ASSERT_TRUE(EncodeDraco(cloud, Options(speed, speed == 10 ? 24 : 11), &bytes).ok());
    const std::string drc = dir.path() + "/ours.drc", ply = dir.path() + "/ours.ply";
    std::ofstream(drc, std::ios::binary) << bytes;
    const std::string cmd =
        tool + " -i " + drc + " -o " + ply + " > " + dir.path() + "/log.txt 2>&1";
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd << "\n" << ReadFile(dir.path() + "/log.txt");
    const std::string out = ReadFile(ply);
    EXPECT_NE(out.find("element vertex " + std::to_string(cloud.size()) + "\n"), std::string::npos)
        << out.substr(0, 300);
    EXPECT_NE(out.find("property uchar red"), std::string::npos) << out.substr(0, 300);
  }
}


// DecodeDraco dequantizes sequentially coded positions itself (draco_decode.cc: the same floats
// on every architecture; Debian's arm64 libdraco fuses the multiply-add). On this machine it must
// give exactly libdraco's floats, at every bit depth, for our encoder's files and libdraco's
// (sequential and kd-tree). arm64_client_test compares arm64 with it.
TEST(DracoDecode, PositionsAreLibdracosFloatsBitForBit) {
  const auto libdraco_positions = [](const std::string& bytes, std::vector<float>* xyz) {
    draco::DecoderBuffer buffer;
    buffer.Init(bytes.data(), bytes.size());
    draco::Decoder decoder;
    auto decoded = decoder.DecodePointCloudFromBuffer(&buffer);
    if (!decoded.ok()) return false;
    const draco::PointAttribute* position =
        decoded.value()->GetNamedAttribute(draco::GeometryAttribute::POSITION);
    const auto n = static_cast<int>(decoded.value()->num_points());
    xyz->resize(3 * static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) {
      if (!position->ConvertValue<float>(position->mapped_index(draco::PointIndex(i)), 3,
                                         xyz->data() + 3 * i)) {
        return false;
      }
    }
    return true;
  };
  const PointCloud cloud = RandomCloud(5000, 77, 12.0f, -3.0f);
  for (int speed : {0, 7, 10}) {
    for (int bits : {1, 8, 11, 14, 20, 24, 30}) {
      std::string bytes;
      ASSERT_TRUE(EncodeDraco(cloud, Options(speed, bits), &bytes).ok());
      PointCloud ours;
      ASSERT_TRUE(DecodeDraco(bytes, &ours).ok());
      std::vector<float> theirs;
      ASSERT_TRUE(libdraco_positions(bytes, &theirs)) << "speed " << speed << " bits " << bits;
      ASSERT_EQ(theirs.size(), 3 * ours.size());
      for (std::size_t i = 0; i < ours.size(); ++i) {
        const Point& p = ours.points[i];
        ASSERT_EQ(std::memcmp(&p.x, &theirs[3 * i], 3 * sizeof(float)), 0)
            << "speed " << speed << " bits " << bits << " point " << i << ": " << p.x << " "
            << p.y << " " << p.z << " against " << theirs[3 * i] << " " << theirs[3 * i + 1]
            << " " << theirs[3 * i + 2];
      }
    }
  }
}

}  // namespace
}  // namespace cloudcast
