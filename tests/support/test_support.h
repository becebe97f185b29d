// Shared test helpers: where the New Tsukuba data is, random frames, a brute-force voxel grid,
// bit-for-bit cloud equality; and (support/cloud_match.h) the one cloud matcher.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "cloudcast/core/filters.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/point.h"
#include "cloudcast/datasets/tsukuba.h"
#include "support/cloud_match.h"

namespace cloudcast::testing {

// The New Tsukuba sample: $CLOUDCAST_DATA, else ../shared/data/new_tsukuba (see tsukuba.h).
inline std::string TsukubaDir() { return tsukuba::DefaultDir(); }
inline const std::vector<std::string>& TsukubaFrameIds() { return tsukuba::FrameIds(); }
inline std::string TsukubaDisparityPath(const std::string& id) {
  return tsukuba::DisparityPath(TsukubaDir(), id);
}
inline std::string TsukubaColourPath(const std::string& id) {
  return tsukuba::ColourPath(TsukubaDir(), id);
}
inline bool HaveTsukuba() { return tsukuba::Present(TsukubaDir()); }
#define CLOUDCAST_REQUIRE_TSUKUBA()                                                          \
  do {                                                                                       \
    if (!::cloudcast::testing::HaveTsukuba()) {                                              \
      GTEST_SKIP() << "New Tsukuba data not found at " << ::cloudcast::testing::TsukubaDir() \
                   << " (set CLOUDCAST_DATA to the folder holding groundtruth/ and "         \
                      "illumination/); this test needs the real frames";                     \
    }                                                                                        \
  } while (0)

// A frame that owns its bytes, with views over them. Rows may be padded (stride > row bytes).
struct TestFrame {
  std::vector<std::uint8_t> disparity_bytes, colour_bytes;
  DisparityView disparity;
  ColorView colour;
};

inline TestFrame MakeFrame(std::uint32_t w, std::uint32_t h, DisparityEncoding de, ColorEncoding ce,
                           std::size_t row_padding = 0) {
  TestFrame f;
  const std::size_t dstride = w * BytesPerPixel(de) + row_padding * BytesPerPixel(de);
  const std::size_t cstride = w * BytesPerPixel(ce) + row_padding;
  f.disparity_bytes.assign(dstride * h, 0);
  f.colour_bytes.assign(cstride * h, 0);
  f.disparity =
      DisparityView{f.disparity_bytes.data(), f.disparity_bytes.size(), w, h, dstride, de};
  f.colour = ColorView{f.colour_bytes.data(), f.colour_bytes.size(), w, h, cstride, ce};
  return f;
}

template <typename T>
inline void SetSample(TestFrame& f, std::uint32_t u, std::uint32_t v, T value) {
  std::memcpy(f.disparity_bytes.data() + v * f.disparity.stride_bytes + u * sizeof(T), &value,
              sizeof(T));
}

// Random frame: a smooth tilted surface (so voxels hold many points) with random holes (zeros),
// random spikes and random colours. `raw_max` bounds the raw disparity value.
inline TestFrame RandomFrame(std::mt19937& rng, std::uint32_t w, std::uint32_t h,
                             DisparityEncoding de, ColorEncoding ce, double raw_min, double raw_max,
                             double hole_rate = 0.05) {
  TestFrame f = MakeFrame(w, h, de, ce, /*row_padding=*/rng() % 3);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double a = unit(rng), b = unit(rng);
  for (std::uint32_t v = 0; v < h; ++v) {
    for (std::uint32_t u = 0; u < w; ++u) {
      double t = raw_min + (raw_max - raw_min) *
                               (0.5 * (a * u / w + b * v / h) + 0.25 * unit(rng) * unit(rng));
      if (unit(rng) < 0.02) t = raw_min + (raw_max - raw_min) * unit(rng);  // spikes
      if (unit(rng) < hole_rate) t = 0;
      switch (de) {
        case DisparityEncoding::kU8:
          SetSample<std::uint8_t>(f, u, v, static_cast<std::uint8_t>(std::lround(t)));
          break;
        case DisparityEncoding::kU16:
          SetSample<std::uint16_t>(f, u, v, static_cast<std::uint16_t>(std::lround(t)));
          break;
        case DisparityEncoding::kF32:
          SetSample<float>(f, u, v, static_cast<float>(t));
          break;
      }
    }
  }
  for (std::size_t i = 0; i < f.colour_bytes.size(); ++i) {
    f.colour_bytes[i] = static_cast<std::uint8_t>(rng());
  }
  return f;
}

// Voxel grid by the definition: std::map of float-computed floor(v * (1/leaf)) indices, double
// sums. Independent of the hashing and key packing under test. Voxels come out ordered by their
// (x, y, z) indices, or with `pcl_order` by (z, y, x), which is PCL's order.
inline PointCloud BruteForceVoxelGrid(const PointCloud& in, const VoxelGridParams& p,
                                      bool pcl_order = false) {
  struct Sum {
    double x = 0, y = 0, z = 0;
    std::uint64_t n = 0, r = 0, g = 0, b = 0, a = 0;
  };
  const float inv[3] = {1.0f / p.leaf_x, 1.0f / p.leaf_y, 1.0f / p.leaf_z};
  std::map<std::tuple<std::int64_t, std::int64_t, std::int64_t>, Sum> voxels;
  for (const Point& q : in.points) {
    if (!std::isfinite(q.x) || !std::isfinite(q.y) || !std::isfinite(q.z)) continue;
    auto idx = [&](float v, float i) {
      return static_cast<std::int64_t>(std::floor(static_cast<double>(v * i)));
    };
    const std::int64_t ix = idx(q.x, inv[0]), iy = idx(q.y, inv[1]), iz = idx(q.z, inv[2]);
    Sum& s = pcl_order ? voxels[{iz, iy, ix}] : voxels[{ix, iy, iz}];
    s.x += q.x;
    s.y += q.y;
    s.z += q.z;
    ++s.n;
    s.r += RedOf(q.rgba);
    s.g += GreenOf(q.rgba);
    s.b += BlueOf(q.rgba);
    s.a += AlphaOf(q.rgba);
  }
  PointCloud out;
  for (const auto& [key, s] : voxels) {
    if (s.n < p.min_points_per_voxel) continue;
    const double n = static_cast<double>(s.n);
    out.points.push_back(Point{static_cast<float>(s.x / n), static_cast<float>(s.y / n),
                               static_cast<float>(s.z / n),
                               PackRgba(s.r / s.n, s.g / s.n, s.b / s.n, s.a / s.n)});
  }
  out.width = static_cast<std::uint32_t>(out.size());
  out.height = 1;
  return out;
}

// Bit-for-bit equality of two clouds' points in order (NaN equals NaN). Width and height are not
// compared: PCL's OrganizedConversion push_back()s its points, which leaves it w*h x 1.
inline ::testing::AssertionResult CloudsIdentical(const PointCloud& a, const PointCloud& b) {
  if (a.size() != b.size()) {
    return ::testing::AssertionFailure()
           << "shapes differ: " << a.width << "x" << a.height << " (" << a.size() << ") vs "
           << b.width << "x" << b.height << " (" << b.size() << ")";
  }
  for (std::size_t i = 0; i < a.size(); ++i) {
    const Point& p = a.points[i];
    const Point& q = b.points[i];
    auto same = [](float x, float y) { return (std::isnan(x) && std::isnan(y)) || x == y; };
    if (!same(p.x, q.x) || !same(p.y, q.y) || !same(p.z, q.z) || p.rgba != q.rgba) {
      return ::testing::AssertionFailure()
             << "point " << i << " differs: (" << p.x << ", " << p.y << ", " << p.z << ", "
             << std::hex << p.rgba << std::dec << ") vs (" << q.x << ", " << q.y << ", " << q.z
             << ", " << std::hex << q.rgba << ")";
    }
  }
  return ::testing::AssertionSuccess();
}

}  // namespace cloudcast::testing
