// One synthetic disparity + colour frame for the tests of the adaptive JPEG coder
// (half_resolution_test, adaptive_jpeg_stream_test).
#pragma once

#include <gtest/gtest.h>

#include <cstdint>

#include "cloudcast/core/camera.h"
#include "cloudcast/sources/frame_source.h"

namespace cloudcast::testing {

// One synthetic disparity + colour frame (16-bit disparity, as a camera's fixed point), and the
// camera it was made with.
struct SyntheticFrame {
  sources::SourceFrame frame;
  CameraModel camera;
};

inline SyntheticFrame MakeSyntheticFrame(std::uint32_t width, std::uint32_t height) {
  sources::SourceSpec spec;
  spec.synthetic_width = width;
  spec.synthetic_height = height;
  spec.synthetic_encoding = DisparityEncoding::kU16;
  auto source = sources::OpenSource(spec, sources::SourceOptions{});
  EXPECT_TRUE(source.ok()) << source.status();
  SyntheticFrame out;
  out.camera = (*source)->info().camera;
  auto got = (*source)->Next(&out.frame);
  EXPECT_TRUE(got.ok() && *got);
  for (auto& m : out.frame.images) m = m.clone();
  return out;
}

}  // namespace cloudcast::testing
