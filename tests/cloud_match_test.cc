// The cloud matcher every comparison of clouds goes through (support/cloud_match.h): it accepts a
// cloud exactly when a one-to-one pairing within the tolerance exists, including where points lie
// closer together than the tolerance, which the greedy matchers it replaced got wrong.
#include "support/cloud_match.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "cloudcast/core/point.h"

namespace cloudcast::testing {
namespace {

PointCloud Cloud(const std::vector<Point>& points) {
  PointCloud cloud;
  cloud.points.assign(points.begin(), points.end());
  cloud.width = static_cast<std::uint32_t>(points.size());
  cloud.height = 1;
  return cloud;
}

const std::uint32_t kGrey = PackRgba(128, 128, 128);

// What the four matchers of the tests did before: each reference point in turn takes the nearest
// point of ours not yet taken, if it lies within `bound` per coordinate.
bool GreedyNearestUnused(const PointCloud& reference, const PointCloud& ours, double bound) {
  if (reference.size() != ours.size()) return false;
  std::vector<bool> used(ours.size(), false);
  for (const Point& p : reference.points) {
    std::size_t best = ours.size();
    double best_gap = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < ours.size(); ++i) {
      const Point& q = ours.points[i];
      const double gap = std::max({std::fabs(double(p.x) - q.x), std::fabs(double(p.y) - q.y),
                                   std::fabs(double(p.z) - q.z)});
      if (!used[i] && gap <= bound && gap < best_gap) {
        best = i;
        best_gap = gap;
      }
    }
    if (best == ours.size()) return false;
    used[best] = true;
  }
  return true;
}

// Two reference points 1.6 apart, ours moved by at most 0.9 each (bound 1): the first reference
// point's nearest is the second one's only partner.
TEST(CloudMatchTest, PairsPointsTheGreedyPassCannot) {
  const PointCloud reference = Cloud({{0.0f, 0, 5, kGrey}, {1.6f, 0, 5, kGrey}});
  const PointCloud ours = Cloud({{-0.9f, 0, 5, kGrey}, {0.7f, 0, 5, kGrey}});
  EXPECT_FALSE(GreedyNearestUnused(reference, ours, 1.0)) << "the case no longer shows the flaw";
  EXPECT_TRUE(CloudsMatch(reference, ours, CloudTolerance::PerCoordinate(1.0)));
  // Relative distance and colour bounds take the same path.
  EXPECT_TRUE(CloudsMatch(reference, ours, {CloudTolerance::kNone, 0.19, 0}));
}

TEST(CloudMatchTest, FailsWhenNoPairingExists) {
  const PointCloud reference = Cloud({{0.0f, 0, 0, kGrey}, {0.5f, 0, 0, kGrey}});
  // Each reference point has a partner within the bound, but it is the same one.
  const ::testing::AssertionResult shared =
      CloudsMatch(reference, Cloud({{0.25f, 0, 0, kGrey}, {3.0f, 0, 0, kGrey}}),
                  CloudTolerance::PerCoordinate(1));
  EXPECT_FALSE(shared);
  EXPECT_NE(std::string(shared.message()).find("needed by another"), std::string::npos)
      << shared.message();
  // The same where the other candidate is near enough but of another colour.
  const PointCloud recoloured = Cloud({{0.25f, 0, 0, kGrey}, {0.26f, 0, 0, PackRgba(0, 0, 0)}});
  EXPECT_FALSE(CloudsMatch(reference, recoloured, CloudTolerance::PerCoordinate(1)));
  EXPECT_TRUE(CloudsMatch(reference, recoloured, CloudTolerance::DracoBound(1, false)));
  // A reference point with nothing near.
  const ::testing::AssertionResult none = CloudsMatch(
      Cloud({{0.0f, 0, 0, kGrey}, {3.0f, 0, 0, kGrey}}),
      Cloud({{0.25f, 0, 0, kGrey}, {4.5f, 0, 0, kGrey}}), CloudTolerance::PerCoordinate(1));
  EXPECT_FALSE(none);
  EXPECT_NE(std::string(none.message()).find("no point of ours within"), std::string::npos)
      << none.message();
}

TEST(CloudMatchTest, CountsPositionsAndColoursAreChecked) {
  const PointCloud one = Cloud({{1, 2, 3, PackRgba(10, 20, 30)}});
  EXPECT_FALSE(CloudsMatch(one, Cloud({}), CloudTolerance::PerCoordinate(1)));
  EXPECT_TRUE(CloudsMatch(Cloud({}), Cloud({}), CloudTolerance::PerCoordinate(0)));
  // Per coordinate: 0.5 off on every axis is within 0.5, not within 0.4.
  const PointCloud moved = Cloud({{1.5f, 2.5f, 3.5f, PackRgba(10, 20, 30)}});
  EXPECT_TRUE(CloudsMatch(one, moved, CloudTolerance::PerCoordinate(0.5)));
  EXPECT_FALSE(CloudsMatch(one, moved, CloudTolerance::PerCoordinate(0.4)));
  // Relative distance is Euclidean: 0.5 on each axis is 0.866 away, |p| = 3.742.
  EXPECT_TRUE(CloudsMatch(one, moved, {CloudTolerance::kNone, 0.87 / 3.742, 0}));
  EXPECT_FALSE(CloudsMatch(one, moved, {CloudTolerance::kNone, 0.86 / 3.742, 0}));
  // Colour: per channel, alpha ignored; 255 compares none.
  const PointCloud recoloured = Cloud({{1, 2, 3, PackRgba(11, 19, 30, 0)}});
  EXPECT_FALSE(CloudsMatch(one, recoloured, CloudTolerance::PerCoordinate(0, 0)));
  EXPECT_TRUE(CloudsMatch(one, recoloured, CloudTolerance::PerCoordinate(0, 1)));
  const PointCloud white = Cloud({{1, 2, 3, PackRgba(255, 255, 255)}});
  EXPECT_FALSE(CloudsMatch(one, white, CloudTolerance::PerCoordinate(0, 1)));
  EXPECT_TRUE(CloudsMatch(one, white, CloudTolerance::DracoBound(0, /*compare_colour=*/false)));
  // Not finite: refused, not mis-hashed.
  const float nan = std::numeric_limits<float>::quiet_NaN();
  EXPECT_FALSE(CloudsMatch(one, Cloud({{nan, 2, 3, 0}}), CloudTolerance::PerCoordinate(1)));
}

// A dense shuffled lattice, every point moved by up to the bound in a random direction, with
// spacing below the bound: every point has several candidates, and only an assignment pairs
// them all. Moving one point past the bound must then fail.
TEST(CloudMatchTest, DenseCloudsCloserThanTheBound) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> jitter(-1.0f, 1.0f);
  const float spacing = 0.004f, bound = 0.0075f;
  std::vector<Point> reference, ours;
  for (int x = 0; x < 30; ++x) {
    for (int y = 0; y < 30; ++y) {
      for (int z = 0; z < 4; ++z) {
        const Point p{x * spacing, y * spacing, 3 + z * spacing, kGrey};
        reference.push_back(p);
        ours.push_back(Point{p.x + bound * 0.99f * jitter(rng), p.y + bound * 0.99f * jitter(rng),
                             p.z + bound * 0.99f * jitter(rng), kGrey});
      }
    }
  }
  std::shuffle(ours.begin(), ours.end(), rng);
  EXPECT_TRUE(CloudsMatch(Cloud(reference), Cloud(ours), CloudTolerance::PerCoordinate(bound)));
  // The ordering matters not: the same with the roles of the lists swapped round.
  std::shuffle(reference.begin(), reference.end(), rng);
  EXPECT_TRUE(CloudsMatch(Cloud(reference), Cloud(ours), CloudTolerance::PerCoordinate(bound)));
  // A point at the lattice's corner moved out of everyone's reach.
  ours.front().x = -1.0f;
  EXPECT_FALSE(CloudsMatch(Cloud(reference), Cloud(ours), CloudTolerance::PerCoordinate(bound)));
}

TEST(CloudMatchTest, SamePointsIsExactInAnyOrder) {
  const PointCloud a = Cloud({{1, 2, 3, PackRgba(1, 2, 3, 4)}, {4, 5, 6, PackRgba(7, 8, 9)}});
  const PointCloud b = Cloud({{4, 5, 6, PackRgba(7, 8, 9)}, {1, 2, 3, PackRgba(1, 2, 3, 4)}});
  EXPECT_TRUE(SamePoints(a, b));
  const PointCloud c = Cloud({{4, 5, 6, PackRgba(7, 8, 9)}, {1, 2, 3, PackRgba(1, 2, 3, 255)}});
  EXPECT_FALSE(SamePoints(a, c));
  EXPECT_TRUE(SamePoints(a, c, /*compare_alpha=*/false));
  EXPECT_FALSE(SamePoints(
      a, Cloud({{1, 2, 3.0000005f, PackRgba(1, 2, 3, 4)}, {4, 5, 6, PackRgba(7, 8, 9)}})));
}

}  // namespace
}  // namespace cloudcast::testing
