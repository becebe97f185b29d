#include "cloudcast/datasets/middlebury.h"

#include <filesystem>

namespace cloudcast::middlebury {
namespace {

OwnedColor Halve(const OwnedColor& c) {
  const std::size_t bpp = BytesPerPixel(c.encoding);
  OwnedColor h;
  h.width = c.width / 2;
  h.height = c.height / 2;
  h.encoding = c.encoding;
  h.pixels.resize(static_cast<std::size_t>(h.width) * h.height * bpp);
  const std::size_t stride = static_cast<std::size_t>(c.width) * bpp;
  for (std::uint32_t y = 0; y < h.height; ++y) {
    const std::uint8_t* a = c.pixels.data() + 2 * y * stride;
    const std::uint8_t* b = a + stride;
    std::uint8_t* out = h.pixels.data() + static_cast<std::size_t>(y) * h.width * bpp;
    for (std::uint32_t x = 0; x < h.width; ++x) {
      for (std::size_t ch = 0; ch < bpp; ++ch) {
        const std::size_t i = 2 * x * bpp + ch;
        out[x * bpp + ch] =
            static_cast<std::uint8_t>((a[i] + a[i + bpp] + b[i] + b[i + bpp] + 2) / 4);
      }
    }
  }
  return h;
}

OwnedDisparity HalveTruth(const OwnedDisparity& t) {
  OwnedDisparity h;
  h.width = t.width / 2;
  h.height = t.height / 2;
  h.encoding = t.encoding;
  h.pixels.resize(static_cast<std::size_t>(h.width) * h.height);
  for (std::uint32_t y = 0; y < h.height; ++y) {
    for (std::uint32_t x = 0; x < h.width; ++x) {
      const std::uint8_t v = t.pixels[static_cast<std::size_t>(2 * y) * t.width + 2 * x];
      h.pixels[static_cast<std::size_t>(y) * h.width + x] = static_cast<std::uint8_t>((v + 1) / 2);
    }
  }
  return h;
}

}  // namespace

std::string AloeDir() { return "/usr/share/doc/opencv-doc/examples/data"; }

bool AloePresent(const std::string& dir) {
  return std::filesystem::exists(dir + "/aloeL.jpg") &&
         std::filesystem::exists(dir + "/aloeR.jpg") &&
         std::filesystem::exists(dir + "/aloeGT.png");
}

absl::StatusOr<StereoFrame> LoadAloe(const std::string& dir, bool half) {
  auto left = LoadColor(dir + "/aloeL.jpg");
  if (!left.ok()) return left.status();
  auto right = LoadColor(dir + "/aloeR.jpg");
  if (!right.ok()) return right.status();
  auto truth = LoadDisparity(dir + "/aloeGT.png");
  if (!truth.ok()) return truth.status();
  if (truth->encoding != DisparityEncoding::kU8) {
    return absl::InvalidArgumentError(dir + "/aloeGT.png is not an 8-bit disparity map");
  }
  StereoFrame f{"aloe", *std::move(left), *std::move(right), *std::move(truth)};
  if (half) {
    f.left = Halve(f.left);
    f.right = Halve(f.right);
    f.truth = HalveTruth(f.truth);
  }
  return f;
}

}  // namespace cloudcast::middlebury
