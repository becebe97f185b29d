// The client library's Draco decoder: what a robot does with a reply's `draco` bytes
// (client.cc's DecodeInto -> DecodeDraco), into a cloud kept from reply to reply as
// Result::cloud is. Also what cloudcast-process and LoadCloud read .drc files with.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string_view>

#include "cloudcast/core/draco_codec.h"

using namespace cloudcast;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static PointCloud* cloud = new PointCloud;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  if (!DecodeDraco(bytes, cloud).ok()) return 0;
  // The documented result: an unorganized cloud of finite points.
  if (cloud->height != 1 && !cloud->empty()) {
    std::fprintf(stderr, "decoded cloud is organized (%u x %u)\n", cloud->width, cloud->height);
    std::abort();
  }
  for (const Point& p : cloud->points) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
      std::fprintf(stderr, "decoded cloud holds a non-finite point\n");
      std::abort();
    }
  }
  return 0;
}
