// The portable extent scan (core/src/draco_scan.cc, what EncodeDraco starts from on arm64) against
// the SSE2 one (draco_sequential_encoder.cc): the same extent, bit for bit, on clouds with holes,
// infinities, signed zeros, equal values and every colour.
#include <gtest/gtest.h>

#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "cloudcast/core/point.h"
#include "draco_sequential_encoder.h"

namespace cloudcast::internal {
namespace {

void ExpectSameExtent(const std::vector<Point>& points) {
  const DracoCloudExtent sse = ScanForDraco(points.data(), points.size());
  const DracoCloudExtent portable = ScanForDracoPortable(points.data(), points.size());
  ASSERT_EQ(portable.finite, sse.finite);
  // Bits, not values: -0.0 and 0.0 must come out as the first one seen, as Draco writes them.
  EXPECT_EQ(std::memcmp(portable.lo, sse.lo, sizeof sse.lo), 0);
  EXPECT_EQ(std::memcmp(portable.hi, sse.hi, sizeof sse.hi), 0);
  EXPECT_EQ(portable.color_lo, sse.color_lo);
  EXPECT_EQ(portable.color_hi, sse.color_hi);
}

TEST(DracoScan, PortableScanEqualsTheSse2One) {
  std::mt19937 rng(20261206);
  std::uniform_real_distribution<float> coordinate(-20.0f, 20.0f);
  std::uniform_int_distribution<int> pick(0, 15);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  for (int round = 0; round < 200; ++round) {
    SCOPED_TRACE(round);
    std::vector<Point> points(1 + rng() % 2000);
    for (Point& p : points) {
      float v[3];
      for (float& f : v) {
        switch (pick(rng)) {
          case 0: f = nan; break;
          case 1: f = round % 2 ? inf : -inf; break;
          case 2: f = 0.0f; break;
          case 3: f = -0.0f; break;
          case 4: f = 1.5f; break;  // equal values
          default: f = coordinate(rng);
        }
      }
      p = Point{v[0], v[1], v[2], static_cast<std::uint32_t>(rng())};
    }
    ExpectSameExtent(points);
  }
}

TEST(DracoScan, EdgeCloudsGiveTheSameExtent) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  ExpectSameExtent({{nan, 0, 0, 0}, {0, nan, 0, 0}});                  // no finite point
  ExpectSameExtent({{-0.0f, 0.0f, -0.0f, 0xFF000000}, {0.0f, -0.0f, 0.0f, 0xFFFFFFFF}});
  ExpectSameExtent({{1, 2, 3, 0x00102030}});                           // one point
  std::vector<Point> all_finite(37, Point{-1.0f, 2.0f, 3.0f, 0xFF7F7F7F});
  all_finite[20] = Point{4.0f, -5.0f, 6.0f, 0xFF000001};
  ExpectSameExtent(all_finite);                                         // the SSE2 common case
}

}  // namespace
}  // namespace cloudcast::internal
