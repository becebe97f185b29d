// The one point layout of cloudcast: 16 bytes, xyz as floats plus packed colour.
//
// The colour word uses PCL's bit layout (0xAARRGGBB as a little-endian uint32, so the bytes in
// memory are B, G, R, A). One point is a quarter of a cache line and goes to the GPU as it is.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <utility>
#include <vector>

namespace cloudcast {

struct Point {
  float x;
  float y;
  float z;
  std::uint32_t rgba;  // 0xAARRGGBB, PCL's packing
};
static_assert(sizeof(Point) == 16, "Point must stay 16 bytes: it is uploaded to the GPU as is");

constexpr std::uint32_t PackRgba(std::uint8_t r, std::uint8_t g, std::uint8_t b,
                                 std::uint8_t a = 255) {
  return (std::uint32_t{a} << 24) | (std::uint32_t{r} << 16) | (std::uint32_t{g} << 8) |
         std::uint32_t{b};
}
constexpr std::uint8_t RedOf(std::uint32_t rgba) { return (rgba >> 16) & 0xFF; }
constexpr std::uint8_t GreenOf(std::uint32_t rgba) { return (rgba >> 8) & 0xFF; }
constexpr std::uint8_t BlueOf(std::uint32_t rgba) { return rgba & 0xFF; }
constexpr std::uint8_t AlphaOf(std::uint32_t rgba) { return rgba >> 24; }

// An allocator that leaves new elements uninitialised: growing a point buffer that is about to be
// overwritten must not cost a memset of the whole frame.
template <typename T>
struct DefaultInitAllocator : std::allocator<T> {
  template <typename U>
  struct rebind {
    using other = DefaultInitAllocator<U>;
  };
  using std::allocator<T>::allocator;
  template <typename U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;
  }
  template <typename U, typename... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};
using PointVector = std::vector<Point, DefaultInitAllocator<Point>>;

// A cloud of Points. Organized clouds (height > 1) keep one point per pixel, row-major, with
// NaN coordinates (and colour 0) where the pixel had no valid disparity; unorganized clouds have
// height 1 and hold only finite points.
struct PointCloud {
  PointVector points;
  std::uint32_t width = 0;
  std::uint32_t height = 0;

  std::size_t size() const { return points.size(); }
  bool empty() const { return points.empty(); }
  bool organized() const { return height > 1; }
  // Makes this an unorganized cloud of n points (contents unspecified); keeps the capacity.
  void ResizeUnorganized(std::size_t n) {
    points.resize(n);
    width = static_cast<std::uint32_t>(n);
    height = 1;
  }
};

}  // namespace cloudcast
