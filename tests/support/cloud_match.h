// The one way the tests say "this cloud is that reference cloud": the same number of points, and
// a one-to-one pairing in which every reference point has its own point of ours within the
// tolerance (position and colour). Used for the PCL equivalence (1e-5 of the norm, colours within
// 1), for Draco replies and files (the position error bound per coordinate, exact colour), and for
// the viewer's and the CLI's files.
//
// The pairing is a proper assignment (a bipartite matching grown by augmenting paths), not a
// greedy nearest-unused pass: where points lie closer together than the tolerance (two voxel
// centroids either side of a voxel face, neighbours moved by Draco's quantization), a greedy pass
// can give a point's only partner to its neighbour and report a mismatch that is not there
// (cloud_match_test.cc has such a case). This one fails only when no pairing exists.
//
// Also here: SamePoints, the same points bit for bit in any order.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <functional>
#include <limits>
#include <string>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "cloudcast/core/point.h"

namespace cloudcast::testing {

// When two points are close enough to be partners. Every bound applies; one left at its default
// imposes nothing.
struct CloudTolerance {
  static constexpr double kNone = std::numeric_limits<double>::infinity();

  // Each of |x - x_ref|, |y - y_ref|, |z - z_ref| at most this (e.g. Draco's error bound).
  double per_coordinate = kNone;
  // The distance |p - p_ref| at most this times |p_ref| (PCL equivalence: 1e-5).
  double relative_distance = kNone;
  // Each of the red, green and blue channels within this; 255 compares no colour. Alpha is never
  // compared (PLY and Draco files carry none).
  int colour = 0;

  // The PCL equivalence criterion (README: "within 1e-5 of its norm, colours within 1").
  static CloudTolerance Equivalence(int colour = 1) { return {kNone, 1e-5, colour}; }
  // Within `bound` per coordinate.
  static CloudTolerance PerCoordinate(double bound, int colour = 0) {
    return {bound, kNone, colour};
  }
  // Within the position_error_bound a Draco reply (or the CLI's report) gives: the bound is
  // computed in double from float ranges, so a float rounding is allowed on top.
  static CloudTolerance DracoBound(double bound, bool compare_colour = true) {
    return {bound * (1 + 1e-6) + 1e-7, kNone, compare_colour ? 0 : 255};
  }
};

namespace cloud_match_internal {

inline bool Finite(const Point& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

inline double Norm(const Point& p) {
  return std::sqrt(double(p.x) * p.x + double(p.y) * p.y + double(p.z) * p.z);
}

// The largest per-coordinate offset a partner of `p` may have.
inline double SearchRadius(const Point& p, const CloudTolerance& t) {
  return std::min(t.per_coordinate, t.relative_distance * std::max(Norm(p), 1e-12));
}

inline int ChannelGap(const Point& p, const Point& q) {
  auto gap = [](std::uint8_t a, std::uint8_t b) { return std::abs(int(a) - int(b)); };
  return std::max({gap(RedOf(p.rgba), RedOf(q.rgba)), gap(GreenOf(p.rgba), GreenOf(q.rgba)),
                   gap(BlueOf(p.rgba), BlueOf(q.rgba))});
}

inline double CoordinateGap(const Point& p, const Point& q) {
  return std::max(
      {std::fabs(double(p.x) - q.x), std::fabs(double(p.y) - q.y), std::fabs(double(p.z) - q.z)});
}

inline double Distance(const Point& p, const Point& q) {
  const double dx = double(p.x) - q.x, dy = double(p.y) - q.y, dz = double(p.z) - q.z;
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

inline bool Close(const Point& ref, const Point& q, const CloudTolerance& t) {
  return CoordinateGap(ref, q) <= t.per_coordinate &&
         Distance(ref, q) <= t.relative_distance * std::max(Norm(ref), 1e-12) &&
         ChannelGap(ref, q) <= t.colour;
}

inline std::string Describe(const Point& p) {
  char text[128];
  std::snprintf(text, sizeof(text), "(%.9g, %.9g, %.9g, rgb %06x)", p.x, p.y, p.z,
                p.rgba & 0xFFFFFFu);
  return text;
}

using Cell = std::tuple<std::int64_t, std::int64_t, std::int64_t>;
struct CellHash {
  std::size_t operator()(const Cell& c) const {
    // Unsigned: cells of far-off points overflow a signed product (UBSan found it).
    const auto u = [](std::int64_t v) { return static_cast<std::uint64_t>(v); };
    return std::hash<std::uint64_t>()(u(std::get<0>(c)) * 73856093u ^
                                      u(std::get<1>(c)) * 19349663u ^
                                      u(std::get<2>(c)) * 83492791u);
  }
};

}  // namespace cloud_match_internal

// `ours` holds `reference`'s points within `tolerance`: the same count, and a one-to-one pairing
// of close points (see the file comment). Order does not matter.
inline ::testing::AssertionResult CloudsMatch(const PointCloud& reference, const PointCloud& ours,
                                              const CloudTolerance& tolerance) {
  namespace in = cloud_match_internal;
  constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
  if (reference.size() != ours.size()) {
    return ::testing::AssertionFailure()
           << "point counts differ: reference " << reference.size() << ", ours " << ours.size();
  }
  const std::size_t n = reference.size();
  if (n == 0) return ::testing::AssertionSuccess();
  if (n >= kNone) return ::testing::AssertionFailure() << "too many points: " << n;
  // The search grid: a cell at least as wide as any point's search radius, so that a partner
  // lies in the point's cell or one of its 26 neighbours.
  double radius = 0, extent = 0;
  for (const PointCloud* cloud : {&reference, &ours}) {
    for (std::size_t i = 0; i < n; ++i) {
      const Point& p = cloud->points[i];
      if (!in::Finite(p)) {
        return ::testing::AssertionFailure()
               << (cloud == &reference ? "reference" : "our") << " point " << i
               << " is not finite: " << in::Describe(p);
      }
      extent = std::max(
          {extent, std::fabs(double(p.x)), std::fabs(double(p.y)), std::fabs(double(p.z))});
      if (cloud == &reference) radius = std::max(radius, in::SearchRadius(p, tolerance));
    }
  }
  if (!std::isfinite(radius)) {
    return ::testing::AssertionFailure() << "the tolerance bounds no distance";
  }
  // Margins keep floor() of a partner's coordinate within one cell despite rounding; the extent
  // term keeps cell indices far inside int64.
  const double cell = std::max({radius * 1.001, extent * 1e-12, 1e-12});
  auto cell_of = [cell](const Point& p) {
    auto c = [cell](float v) { return static_cast<std::int64_t>(std::floor(double(v) / cell)); };
    return in::Cell(c(p.x), c(p.y), c(p.z));
  };
  std::unordered_map<in::Cell, std::vector<std::uint32_t>, in::CellHash> grid;
  grid.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    grid[cell_of(ours.points[i])].push_back(static_cast<std::uint32_t>(i));
  }

  // Each reference point's candidates, nearest first (compressed rows).
  std::vector<std::size_t> first(n + 1, 0);
  std::vector<std::uint32_t> candidates;
  std::vector<std::pair<double, std::uint32_t>> scratch;
  for (std::size_t r = 0; r < n; ++r) {
    const Point& p = reference.points[r];
    const auto [cx, cy, cz] = cell_of(p);
    scratch.clear();
    double nearest = std::numeric_limits<double>::infinity();
    std::uint32_t nearest_index = kNone;
    for (int k = 0; k < 27; ++k) {
      const auto it = grid.find(in::Cell(cx + k % 3 - 1, cy + k / 3 % 3 - 1, cz + k / 9 - 1));
      if (it == grid.end()) continue;
      for (std::uint32_t i : it->second) {
        const Point& q = ours.points[i];
        const double gap = in::CoordinateGap(p, q);
        if (gap < nearest) {
          nearest = gap;
          nearest_index = i;
        }
        if (in::Close(p, q, tolerance)) scratch.emplace_back(gap, i);
      }
    }
    if (scratch.empty()) {
      ::testing::AssertionResult failure = ::testing::AssertionFailure();
      failure << "reference point " << r << " " << in::Describe(p)
              << " has no point of ours within the tolerance (per coordinate "
              << tolerance.per_coordinate << ", relative distance " << tolerance.relative_distance
              << ", colour " << tolerance.colour << ")";
      if (nearest_index != kNone) {
        const Point& q = ours.points[nearest_index];
        failure << "; the nearest is " << nearest_index << " " << in::Describe(q) << ", "
                << in::CoordinateGap(p, q) << " away per coordinate (distance "
                << in::Distance(p, q) << "), colour channels up to " << in::ChannelGap(p, q)
                << " apart";
      }
      return failure;
    }
    std::sort(scratch.begin(), scratch.end());
    for (const auto& [gap, i] : scratch) candidates.push_back(i);
    first[r + 1] = candidates.size();
  }

  // Nearest free candidate first; then an augmenting path (breadth first) for every reference
  // point left without a partner.
  std::vector<std::uint32_t> partner_of_ours(n, kNone), partner_of_reference(n, kNone);
  for (std::size_t r = 0; r < n; ++r) {
    for (std::size_t k = first[r]; k < first[r + 1]; ++k) {
      if (partner_of_ours[candidates[k]] == kNone) {
        partner_of_ours[candidates[k]] = static_cast<std::uint32_t>(r);
        partner_of_reference[r] = candidates[k];
        break;
      }
    }
  }
  std::vector<std::uint32_t> seen(n, kNone), reached_from(n, kNone);
  std::deque<std::uint32_t> queue;
  for (std::uint32_t root = 0; root < n; ++root) {
    if (partner_of_reference[root] != kNone) continue;
    queue.assign(1, root);
    bool augmented = false;
    while (!queue.empty() && !augmented) {
      const std::uint32_t r = queue.front();
      queue.pop_front();
      for (std::size_t k = first[r]; k < first[r + 1] && !augmented; ++k) {
        const std::uint32_t i = candidates[k];
        if (seen[i] == root) continue;
        seen[i] = root;
        reached_from[i] = r;
        if (partner_of_ours[i] != kNone) {
          queue.push_back(partner_of_ours[i]);
          continue;
        }
        // Flip the path: each reference point on it takes the point of ours it reached.
        for (std::uint32_t at = i;;) {
          const std::uint32_t from = reached_from[at];
          const std::uint32_t previous = partner_of_reference[from];
          partner_of_reference[from] = at;
          partner_of_ours[at] = from;
          if (from == root) break;
          at = previous;
        }
        augmented = true;
      }
    }
    if (!augmented) {
      return ::testing::AssertionFailure()
             << "reference point " << root << " " << in::Describe(reference.points[root]) << " has "
             << first[root + 1] - first[root]
             << " point(s) of ours within the tolerance, but no pairing gives it one: every "
                "candidate is needed by another reference point";
    }
  }
  return ::testing::AssertionSuccess();
}

// CloudsMatch's criterion point by point in order: the same number of points, and point i of
// ours close to the reference's point i (for a voxel grid in PCL's own key order).
inline ::testing::AssertionResult CloudsMatchInOrder(const PointCloud& reference,
                                                     const PointCloud& ours,
                                                     const CloudTolerance& tolerance) {
  if (reference.size() != ours.size()) {
    return ::testing::AssertionFailure()
           << "point counts differ: reference " << reference.size() << ", ours " << ours.size();
  }
  namespace in = cloud_match_internal;
  for (std::size_t i = 0; i < reference.size(); ++i) {
    if (!in::Close(reference.points[i], ours.points[i], tolerance)) {
      return ::testing::AssertionFailure() << "point " << i << " differs: reference "
                                           << in::Describe(reference.points[i]) << ", ours "
                                           << in::Describe(ours.points[i]);
    }
  }
  return ::testing::AssertionSuccess();
}

// The same points, bit for bit, in any order (NaNs and signed zeros included); `compare_alpha`
// off for formats without alpha.
inline ::testing::AssertionResult SamePoints(const PointCloud& expected, const PointCloud& actual,
                                             bool compare_alpha = true) {
  auto bits = [](float f) {
    std::uint32_t b;
    std::memcpy(&b, &f, 4);
    return b;
  };
  auto canonical = [&](const PointCloud& cloud) {
    std::vector<Point> v(cloud.points.begin(), cloud.points.end());
    for (Point& p : v) {
      if (!compare_alpha) p.rgba |= 0xFF000000u;
    }
    std::sort(v.begin(), v.end(), [&](const Point& a, const Point& b) {
      return std::make_tuple(bits(a.x), bits(a.y), bits(a.z), a.rgba) <
             std::make_tuple(bits(b.x), bits(b.y), bits(b.z), b.rgba);
    });
    return v;
  };
  const std::vector<Point> a = canonical(expected), b = canonical(actual);
  if (a.size() != b.size()) {
    return ::testing::AssertionFailure() << "expected " << a.size() << " points, got " << b.size();
  }
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (bits(a[i].x) != bits(b[i].x) || bits(a[i].y) != bits(b[i].y) ||
        bits(a[i].z) != bits(b[i].z) || a[i].rgba != b[i].rgba) {
      return ::testing::AssertionFailure()
             << "sorted point " << i << ": expected (" << a[i].x << ", " << a[i].y << ", " << a[i].z
             << ", " << std::hex << a[i].rgba << std::dec << ") got (" << b[i].x << ", " << b[i].y
             << ", " << b[i].z << ", " << std::hex << b[i].rgba << ")";
    }
  }
  return ::testing::AssertionSuccess();
}

}  // namespace cloudcast::testing
