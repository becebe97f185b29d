// Tests of cloudcast_render, the OpenGL point cloud renderer, on a real GL 3.3 core context:
// Mesa's llvmpipe in an Xvfb the test starts itself (tests/support/xvfb_support.h). Every check
// reads the rendered pixels back: points land where ViewProjection() says, with their packed colour
// bit for bit, NaN points and stale buffer contents never show, the overlay stays in its corner,
// screenshots are upright, and a cloudcast-process PCD file renders.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "cloudcast/core/point.h"
#include "cloudcast/io/cloud_io.h"
#include "cloudcast/render/renderer.h"
#include "support/test_support.h"
#include "support/xvfb_support.h"

namespace cloudcast::render {
namespace {

namespace fs = std::filesystem;

constexpr int kWidth = 320, kHeight = 240;
constexpr float kPointSize = 9.0f;
// Exact 8-bit values: c / 255 in float converts back to c.
constexpr std::array<std::uint8_t, 3> kBackground = {10, 20, 30};
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

struct Rgb {
  std::uint8_t r, g, b;
  bool operator==(const Rgb& o) const { return r == o.r && g == o.g && b == o.b; }
  bool operator!=(const Rgb& o) const { return !(*this == o); }
};
std::ostream& operator<<(std::ostream& os, const Rgb& c) {
  return os << "(" << int(c.r) << ", " << int(c.g) << ", " << int(c.b) << ")";
}
constexpr Rgb kBg{kBackground[0], kBackground[1], kBackground[2]};
Rgb ColourOf(std::uint32_t rgba) { return {RedOf(rgba), GreenOf(rgba), BlueOf(rgba)}; }

// A read-back frame, top row first.
struct Image {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;
  Rgb At(int x, int y) const {
    const std::size_t i = (static_cast<std::size_t>(y) * width + x) * 3;
    return {rgb[i], rgb[i + 1], rgb[i + 2]};
  }
  bool Inside(int x, int y) const { return x >= 0 && y >= 0 && x < width && y < height; }
  int CountNot(const Rgb& c) const {
    int n = 0;
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) n += At(x, y) != c;
    return n;
  }
  int Count(const Rgb& c) const { return width * height - CountNot(c); }
};

// Where a point lands: window pixel (column, row from the top), or nullopt-like `visible` false
// when it is outside the view.
struct Pixel {
  double x = 0, y = 0;  // continuous window coordinates, y from the top
  bool visible = false;
  int col() const { return static_cast<int>(std::floor(x)); }
  int row() const { return static_cast<int>(std::floor(y)); }
};

Pixel Project(const std::array<float, 16>& m, int width, int height, float px, float py, float pz) {
  double clip[4];
  for (int r = 0; r < 4; ++r) {
    clip[r] = m[0 * 4 + r] * px + m[1 * 4 + r] * py + m[2 * 4 + r] * pz + m[3 * 4 + r];
  }
  Pixel p;
  if (clip[3] <= 0) return p;
  const double nx = clip[0] / clip[3], ny = clip[1] / clip[3], nz = clip[2] / clip[3];
  p.visible = std::fabs(nx) < 1 && std::fabs(ny) < 1 && std::fabs(nz) < 1;
  p.x = (nx + 1) / 2 * width;
  p.y = height - (ny + 1) / 2 * height;  // GL's window y grows upwards
  return p;
}

class RenderTest : public ::testing::Test {
 protected:
  void SetUp() override {
    CLOUDCAST_REQUIRE_DISPLAY();
    renderer_ = Open(kWidth, kHeight);
    ASSERT_NE(renderer_, nullptr);
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::path(::testing::TempDir()) /
           (std::string("cloudcast_render_") + info->name() + "_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    renderer_.reset();
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  static std::unique_ptr<Renderer> Open(int width, int height, float point_size = kPointSize) {
    RendererOptions o;
    o.width = width;
    o.height = height;
    o.visible = false;
    o.point_size = point_size;
    o.background = {kBackground[0] / 255.0f, kBackground[1] / 255.0f, kBackground[2] / 255.0f};
    absl::StatusOr<std::unique_ptr<Renderer>> r = Renderer::Create(o);
    EXPECT_TRUE(r.ok()) << r.status();
    return r.ok() ? *std::move(r) : nullptr;
  }

  Image Render(Renderer& r) {
    r.Draw();
    return Read(r);
  }
  Image Render() { return Render(*renderer_); }
  static Image Read(Renderer& r) {
    Image img;
    absl::StatusOr<std::vector<std::uint8_t>> px = r.ReadPixelsRgb(&img.width, &img.height);
    EXPECT_TRUE(px.ok()) << px.status();
    if (px.ok()) img.rgb = *std::move(px);
    EXPECT_EQ(img.rgb.size(), static_cast<std::size_t>(img.width) * img.height * 3);
    return img;
  }

  Pixel ProjectPoint(const Point& p) const {
    return Project(renderer_->ViewProjection(), renderer_->framebuffer_width(),
                   renderer_->framebuffer_height(), p.x, p.y, p.z);
  }

  // Each point covers a kPointSize square around its projection: the 5x5 pixels around the
  // centre are its colour exactly (a margin for rounding at the square's edge), and every pixel
  // farther than kPointSize from all points is background.
  ::testing::AssertionResult PointsDrawnExactly(const Image& img, const std::vector<Point>& pts) {
    std::vector<Pixel> px;
    for (const Point& p : pts) {
      const Pixel q = ProjectPoint(p);
      if (!q.visible) {
        return ::testing::AssertionFailure()
               << "test setup: point (" << p.x << ", " << p.y << ", " << p.z << ") is off screen";
      }
      px.push_back(q);
    }
    for (std::size_t i = 0; i < pts.size(); ++i) {
      const Rgb want = ColourOf(pts[i].rgba);
      for (int dy = -2; dy <= 2; ++dy) {
        for (int dx = -2; dx <= 2; ++dx) {
          const int x = px[i].col() + dx, y = px[i].row() + dy;
          if (!img.Inside(x, y)) continue;
          if (img.At(x, y) != want) {
            return ::testing::AssertionFailure()
                   << "point " << i << " (" << pts[i].x << ", " << pts[i].y << ", " << pts[i].z
                   << ") projects to pixel (" << px[i].col() << ", " << px[i].row() << "); at ("
                   << x << ", " << y << ") expected " << want << ", got " << img.At(x, y);
          }
        }
      }
    }
    for (int y = 0; y < img.height; ++y) {
      for (int x = 0; x < img.width; ++x) {
        bool near = false;
        for (const Pixel& q : px) {
          near = near ||
                 (std::fabs(x + 0.5 - q.x) <= kPointSize && std::fabs(y + 0.5 - q.y) <= kPointSize);
        }
        if (!near && img.At(x, y) != kBg) {
          return ::testing::AssertionFailure()
                 << "pixel (" << x << ", " << y << ") away from every point is " << img.At(x, y)
                 << ", not the background " << kBg;
        }
      }
    }
    return ::testing::AssertionSuccess();
  }

  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  std::unique_ptr<Renderer> renderer_;
  fs::path dir_;
};

// A box from behind the origin to beyond z = 5: framing it puts the eye well behind the origin.
constexpr Bounds3 kAroundOrigin{{-4.0f, -3.0f, -1.0f}, {4.0f, 3.0f, 6.0f}};

// Five well separated points with distinct colours, 5 units in front of the camera.
std::vector<Point> FivePoints() {
  return {Point{0.0f, 0.0f, 5.0f, PackRgba(255, 0, 0)},
          Point{-1.5f, -1.0f, 5.0f, PackRgba(0, 255, 0)},
          Point{1.5f, -1.0f, 6.0f, PackRgba(0, 0, 255)},
          Point{-1.5f, 1.0f, 4.0f, PackRgba(255, 255, 0)},
          Point{1.2f, 1.2f, 5.5f, PackRgba(0, 255, 255)}};
}

TEST_F(RenderTest, EmptyFrameIsBackground) {
  const Image img = Render();
  EXPECT_EQ(img.width, kWidth);
  EXPECT_EQ(img.height, kHeight);
  EXPECT_EQ(img.CountNot(kBg), 0) << "an empty cloud must leave only the background";
}

TEST_F(RenderTest, DefaultViewLooksLikeTheCameraImage) {
  // Camera frame: x right, y down. Up-left of the optical axis must appear top-left.
  const std::vector<Point> pts = {Point{-1.0f, -1.0f, 5.0f, PackRgba(255, 0, 0)},
                                  Point{1.0f, 1.0f, 5.0f, PackRgba(0, 255, 0)}};
  renderer_->Upload(pts.data(), pts.size());
  const Image img = Render();
  int red_x = 0, red_y = 0, red_n = 0, green_x = 0, green_y = 0, green_n = 0;
  for (int y = 0; y < img.height; ++y) {
    for (int x = 0; x < img.width; ++x) {
      if (img.At(x, y) == Rgb{255, 0, 0}) red_x += x, red_y += y, ++red_n;
      if (img.At(x, y) == Rgb{0, 255, 0}) green_x += x, green_y += y, ++green_n;
    }
  }
  ASSERT_EQ(red_n, 81) << "a 9-pixel point covers 9x9 pixels";
  ASSERT_EQ(green_n, 81);
  EXPECT_LT(red_x / red_n, kWidth / 2);
  EXPECT_LT(red_y / red_n, kHeight / 2) << "y down in the camera frame must be down on screen";
  EXPECT_GT(green_x / green_n, kWidth / 2);
  EXPECT_GT(green_y / green_n, kHeight / 2);
  // The default view is the camera's: the optical axis hits the image centre.
  const Pixel centre = Project(renderer_->ViewProjection(), kWidth, kHeight, 0, 0, 7);
  EXPECT_NEAR(centre.x, kWidth / 2.0, 1e-3);
  EXPECT_NEAR(centre.y, kHeight / 2.0, 1e-3);
  EXPECT_TRUE(PointsDrawnExactly(img, pts));
}

TEST_F(RenderTest, PointsLandWhereViewProjectionSaysForEveryCameraMove) {
  const std::vector<Point> pts = FivePoints();
  renderer_->Upload(pts.data(), pts.size());
  EXPECT_TRUE(PointsDrawnExactly(Render(), pts)) << "default view";

  renderer_->ResetViewToCloud(pts.data(), pts.size());
  EXPECT_TRUE(PointsDrawnExactly(Render(), pts)) << "after ResetViewToCloud";

  const auto before = renderer_->ViewProjection();
  renderer_->Orbit(40, -25);
  EXPECT_NE(renderer_->ViewProjection(), before) << "orbit must move the camera";
  EXPECT_TRUE(PointsDrawnExactly(Render(), pts)) << "after Orbit";

  renderer_->Pan(15, 10);
  EXPECT_TRUE(PointsDrawnExactly(Render(), pts)) << "after Pan";

  renderer_->Zoom(-2);  // out: zooming in would push points off the small view
  EXPECT_TRUE(PointsDrawnExactly(Render(), pts)) << "after Zoom";

  // 'r' returns to the framed view exactly.
  EXPECT_TRUE(renderer_->HandleCharacter('r'));
  renderer_->ResetViewToCloud(pts.data(), pts.size());
  const auto framed = renderer_->ViewProjection();
  renderer_->Orbit(100, 50);
  renderer_->HandleCharacter('r');
  EXPECT_EQ(renderer_->ViewProjection(), framed);
}

TEST_F(RenderTest, PanFollowsTheMouseAndZoomMagnifies) {
  const std::vector<Point> pts = FivePoints();
  renderer_->ResetViewToCloud(pts.data(), pts.size());
  const Pixel before = ProjectPoint(pts[0]);
  renderer_->Pan(20, -10);  // mouse right and up: the scene follows it
  const Pixel after = ProjectPoint(pts[0]);
  // The red point is at the target's depth only roughly (the box centre), so allow some slack.
  EXPECT_NEAR(after.x - before.x, 20, 4);
  EXPECT_NEAR(after.y - before.y, -10, 3);

  renderer_->ResetViewToCloud(pts.data(), pts.size());
  const Pixel a0 = ProjectPoint(pts[1]), b0 = ProjectPoint(pts[2]);
  renderer_->Zoom(3);
  const Pixel a1 = ProjectPoint(pts[1]), b1 = ProjectPoint(pts[2]);
  EXPECT_GT(std::hypot(a1.x - b1.x, a1.y - b1.y), 1.2 * std::hypot(a0.x - b0.x, a0.y - b0.y))
      << "zooming in must spread the points apart";
}

TEST_F(RenderTest, ResetViewFramesTheWholeBoxTightly) {
  const Bounds3 b{{-2.0f, -1.0f, 4.0f}, {3.0f, 2.0f, 9.0f}};
  renderer_->Orbit(300, 200);
  renderer_->ResetView(b);
  double widest = 0;
  for (int i = 0; i < 8; ++i) {
    const float x = (i & 1) ? b.max[0] : b.min[0], y = (i & 2) ? b.max[1] : b.min[1],
                z = (i & 4) ? b.max[2] : b.min[2];
    const Pixel p = Project(renderer_->ViewProjection(), kWidth, kHeight, x, y, z);
    EXPECT_TRUE(p.visible) << "corner (" << x << ", " << y << ", " << z << ") is off screen";
    widest = std::max({widest, std::fabs(p.x - kWidth / 2.0) / (kWidth / 2.0),
                       std::fabs(p.y - kHeight / 2.0) / (kHeight / 2.0)});
  }
  EXPECT_GT(widest, 0.85) << "the box should fill the view, not float in the middle";
  // The centre of the box is at the centre of the view.
  const Pixel c = Project(renderer_->ViewProjection(), kWidth, kHeight, 0.5f, 0.5f, 6.5f);
  EXPECT_NEAR(c.x, kWidth / 2.0, 1e-2);
  EXPECT_NEAR(c.y, kHeight / 2.0, 1e-2);

  // ResetViewToCloud ignores NaN points: same view as the finite points' bounds.
  std::vector<Point> cloud = {Point{b.min[0], b.min[1], b.min[2], 0}, Point{kNaN, kNaN, kNaN, 0},
                              Point{b.max[0], b.max[1], b.max[2], 0},
                              Point{100.0f, kNaN, 1000.0f, 0}};
  const auto framed = renderer_->ViewProjection();
  renderer_->Orbit(30, 30);
  renderer_->ResetViewToCloud(cloud.data(), cloud.size());
  EXPECT_EQ(renderer_->ViewProjection(), framed);
}

TEST_F(RenderTest, PackedColourRoundTripsEveryChannelValue) {
  // 256 points on a 16x16 grid: point i has red i, green i + 85, blue i + 170 (mod 256), so each
  // channel takes every value 0..255; alpha varies too and must not matter.
  std::vector<Point> pts;
  for (int i = 0; i < 256; ++i) {
    const int col = i % 16, row = i / 16;
    pts.push_back(
        Point{-3.0f + col * 0.4f, -2.4f + row * 0.32f, 5.0f,
              PackRgba(static_cast<std::uint8_t>(i), static_cast<std::uint8_t>(i + 85),
                       static_cast<std::uint8_t>(i + 170), static_cast<std::uint8_t>(i * 37))});
  }
  renderer_->Upload(pts.data(), pts.size());
  const Image img = Render();
  int exact = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const Pixel p = ProjectPoint(pts[i]);
    ASSERT_TRUE(p.visible) << "point " << i;
    const Rgb got = img.At(p.col(), p.row()), want = ColourOf(pts[i].rgba);
    EXPECT_EQ(got, want) << "point " << i << " with rgba 0x" << std::hex << pts[i].rgba;
    exact += got == want;
  }
  EXPECT_EQ(exact, 256);
  // Channel order: a pure red word 0xFFFF0000 is red on screen (not blue, as a BGRA misread
  // would give).
  const Point red{0, 0, 5, 0xFFFF0000u};
  renderer_->Upload(&red, 1);
  const Pixel p = ProjectPoint(red);
  EXPECT_EQ(Render().At(p.col(), p.row()), (Rgb{255, 0, 0}));
}

TEST_F(RenderTest, NonFinitePointsAreNotDrawn) {
  // Bright non-finite points around one finite point: only its 9x9 square may show.
  std::vector<Point> pts = {
      Point{kNaN, 0.0f, 5.0f, PackRgba(255, 255, 255)},
      Point{0.0f, kNaN, 5.0f, PackRgba(255, 255, 255)},
      Point{0.0f, 0.0f, kNaN, PackRgba(255, 255, 255)},
      Point{kNaN, kNaN, kNaN, PackRgba(255, 0, 255)},
      Point{kInf, 0.0f, 5.0f, PackRgba(255, 255, 255)},
      Point{0.0f, -kInf, 5.0f, PackRgba(255, 255, 255)},
      Point{0.0f, 0.0f, kInf, PackRgba(255, 255, 255)},
      Point{1.0f, 1.0f, 5.0f, PackRgba(200, 100, 50)},
  };
  // An organized-cloud-like block: many NaN holes between a few valid points.
  for (int i = 0; i < 1000; ++i) pts.push_back(Point{kNaN, kNaN, kNaN, PackRgba(255, 255, 255)});
  // Look at the origin from afar, so a NaN read as 0 (at the origin, or at (0, 0, 5)) would
  // show instead of being clipped at the eye.
  renderer_->ResetView(kAroundOrigin);
  renderer_->Upload(pts.data(), pts.size());
  const Image img = Render();
  EXPECT_EQ(img.Count(Rgb{200, 100, 50}), 81);
  EXPECT_EQ(img.CountNot(kBg), 81) << "something other than the finite point was drawn";
  EXPECT_TRUE(PointsDrawnExactly(img, {pts[7]}));
}

TEST_F(RenderTest, NearerPointsHideFartherOnes) {
  // Same ray, drawn far first and near last, then the reverse: the near one wins both times.
  const Point near{0.0f, 0.0f, 4.0f, PackRgba(255, 0, 0)};
  const Point far{0.0f, 0.0f, 8.0f, PackRgba(0, 0, 255)};
  for (const auto& order : {std::vector<Point>{far, near}, std::vector<Point>{near, far}}) {
    renderer_->Upload(order.data(), order.size());
    const Image img = Render();
    const Pixel p = ProjectPoint(near);
    EXPECT_EQ(img.At(p.col(), p.row()), (Rgb{255, 0, 0}));
    EXPECT_EQ(img.Count(Rgb{0, 0, 255}), 0) << "the far point is exactly behind the near one";
  }
}

TEST_F(RenderTest, SmallerUploadReplacesBiggerOneAndBufferIsReused) {
  // A big red cloud filling the view...
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<Point> big(20000);
  for (Point& p : big) p = Point{u(rng) * 4.0f, u(rng) * 3.0f, 5.0f, PackRgba(255, 0, 0)};
  // The origin in view: stale or zeroed buffer contents past the new count would show there.
  renderer_->ResetView(kAroundOrigin);
  renderer_->Upload(big.data(), big.size());
  EXPECT_EQ(renderer_->point_count(), big.size());
  const std::size_t capacity = renderer_->gpu_buffer_bytes();
  EXPECT_GE(capacity, big.size() * sizeof(Point));
  EXPECT_GT(Render().Count(Rgb{255, 0, 0}), kWidth * kHeight / 8);

  // ...then three green points: no red may remain, and the buffer is reused, not reallocated.
  const std::vector<Point> small = {Point{-1.0f, 0.0f, 5.0f, PackRgba(0, 255, 0)},
                                    Point{0.0f, 0.0f, 5.0f, PackRgba(0, 255, 0)},
                                    Point{1.0f, 0.0f, 5.0f, PackRgba(0, 255, 0)}};
  renderer_->Upload(small.data(), small.size());
  EXPECT_EQ(renderer_->gpu_buffer_bytes(), capacity);
  Image img = Render();
  EXPECT_EQ(img.Count(Rgb{255, 0, 0}), 0) << "points of the previous, bigger upload remain";
  EXPECT_EQ(img.Count(Rgb{0, 255, 0}), 3 * 81);
  EXPECT_EQ(img.CountNot(kBg), 3 * 81) << "something beyond the 3 uploaded points was drawn";
  EXPECT_TRUE(PointsDrawnExactly(img, small));

  // Nothing at all.
  renderer_->Upload(nullptr, 0);
  EXPECT_EQ(Render().CountNot(kBg), 0);

  // Growing past the capacity: every new point is drawn (checked by colour on a grid).
  std::vector<Point> bigger;
  for (int i = 0; i < 40000; ++i) {
    bigger.push_back(Point{u(rng) * 4.0f, u(rng) * 3.0f, 5.5f, PackRgba(0, 0, 255)});
  }
  bigger.push_back(Point{0.0f, 0.0f, 3.0f, PackRgba(255, 255, 0)});  // the very last point
  renderer_->Upload(bigger.data(), bigger.size());
  EXPECT_GE(renderer_->gpu_buffer_bytes(), bigger.size() * sizeof(Point));
  img = Render();
  const Pixel last = ProjectPoint(bigger.back());
  EXPECT_EQ(img.At(last.col(), last.row()), (Rgb{255, 255, 0})) << "the last point is missing";
  EXPECT_EQ(img.Count(Rgb{0, 255, 0}), 0);
}

TEST_F(RenderTest, OverlayTextChangesOnlyTheTopLeftCorner) {
  std::vector<Point> pts = FivePoints();
  renderer_->Upload(pts.data(), pts.size());
  const Image plain = Render();
  const std::string text = "fps 30.0  16186 pts";
  renderer_->SetOverlayText(text);
  const Image with_text = Render();
  // The box: 6 px margin, 4 px padding, 16x16 pixel glyphs.
  const int box_x1 = 6 + 4 + 16 * static_cast<int>(text.size()) + 4, box_y1 = 6 + 4 + 16 + 4;
  int changed = 0, ink = 0;
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x) {
      if (plain.At(x, y) == with_text.At(x, y)) continue;
      ++changed;
      ASSERT_TRUE(x < box_x1 && y < box_y1)
          << "the overlay changed pixel (" << x << ", " << y << ") outside its corner";
      ink += with_text.At(x, y).r > 200;
    }
  }
  EXPECT_GT(changed, (box_x1 - 6) * (box_y1 - 6) / 2) << "the dark box is missing";
  EXPECT_GT(ink, 200) << "the glyphs are missing";
  // The box darkens the background under it.
  const Rgb boxed = with_text.At(7, 7);
  EXPECT_LT(boxed.b, kBg.b);

  // Glyph shape and orientation: 'F' alone, compared with its 8x8 bitmap at 2x.
  renderer_->Upload(nullptr, 0);
  renderer_->SetOverlayText("F");
  const Image f = Render();
  static const std::uint8_t kF[8] = {0x7F, 0x46, 0x16, 0x1E, 0x16, 0x06, 0x0F, 0x00};
  for (int row = 0; row < 16; ++row) {
    for (int col = 0; col < 16; ++col) {
      const bool want_ink = (kF[row / 2] >> (col / 2)) & 1;
      const bool is_ink = f.At(10 + col, 10 + row).r > 200;
      EXPECT_EQ(is_ink, want_ink) << "'F' pixel (" << col << ", " << row << ")";
    }
  }

  // Clearing the text restores the frame exactly.
  renderer_->Upload(pts.data(), pts.size());
  renderer_->SetOverlayText("");
  const Image cleared = Render();
  EXPECT_EQ(cleared.rgb, plain.rgb);
}

TEST_F(RenderTest, ScreenshotIsUprightAndMatchesTheFrame) {
  const std::vector<Point> pts = {Point{0.0f, -2.0f, 5.0f, PackRgba(255, 0, 0)},   // top
                                  Point{-2.5f, 2.0f, 5.0f, PackRgba(0, 0, 255)}};  // bottom-left
  renderer_->Upload(pts.data(), pts.size());
  renderer_->Draw();
  renderer_->Swap();  // the back buffer is undefined now: the screenshot must re-draw
  const std::string png = Path("shot.png");
  ASSERT_TRUE(renderer_->SaveScreenshot(png).ok());
  const cv::Mat bgr = cv::imread(png, cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(bgr.empty()) << "no PNG at " << png;
  ASSERT_EQ(bgr.type(), CV_8UC3);
  EXPECT_EQ(bgr.cols, renderer_->framebuffer_width());
  EXPECT_EQ(bgr.rows, renderer_->framebuffer_height());
  auto at = [&](int x, int y) {
    const cv::Vec3b v = bgr.at<cv::Vec3b>(y, x);
    return Rgb{v[2], v[1], v[0]};
  };
  const Pixel top = ProjectPoint(pts[0]), bottom = ProjectPoint(pts[1]);
  ASSERT_LT(top.y, kHeight / 3.0);
  ASSERT_GT(bottom.y, 2 * kHeight / 3.0);
  EXPECT_EQ(at(top.col(), top.row()), (Rgb{255, 0, 0})) << "red point not at the top of the PNG";
  EXPECT_EQ(at(bottom.col(), bottom.row()), (Rgb{0, 0, 255}));
  EXPECT_EQ(at(0, 0), kBg);
  // Pixel for pixel the frame ReadPixelsRgb gives.
  const Image img = Read(*renderer_);
  for (int y = 0; y < img.height; ++y) {
    for (int x = 0; x < img.width; ++x) ASSERT_EQ(at(x, y), img.At(x, y)) << x << ", " << y;
  }

  // After a Swap the back buffer is undefined (llvmpipe happens to keep it): a read-back draws
  // the current state again rather than returning whatever the buffer holds.
  renderer_->Draw();
  renderer_->Swap();
  const Point moved{1.0f, 0.0f, 5.0f, PackRgba(0, 255, 0)};
  renderer_->Upload(&moved, 1);
  const Image redrawn = Read(*renderer_);
  EXPECT_EQ(redrawn.Count(Rgb{0, 255, 0}), 81) << "the read-back after Swap did not re-draw";
  EXPECT_EQ(redrawn.Count(Rgb{255, 0, 0}), 0);
  renderer_->Upload(pts.data(), pts.size());

  // The 's' key writes to the pattern with a counter.
  renderer_->SetScreenshotPath(Path("key-%d.png"));
  EXPECT_TRUE(renderer_->HandleCharacter('s'));
  EXPECT_TRUE(renderer_->HandleCharacter('s'));
  EXPECT_TRUE(renderer_->last_screenshot_status().ok()) << renderer_->last_screenshot_status();
  EXPECT_TRUE(fs::exists(Path("key-0.png")));
  EXPECT_TRUE(fs::exists(Path("key-1.png")));
  EXPECT_EQ(renderer_->last_screenshot_path(), Path("key-1.png"));

  // A path OpenCV cannot write is an error, not a crash.
  EXPECT_FALSE(renderer_->SaveScreenshot(Path("missing-dir/x.png")).ok());
  EXPECT_FALSE(renderer_->SaveScreenshot(Path("no-extension")).ok());
}

TEST_F(RenderTest, KeysChangePointSizePauseAndClose) {
  EXPECT_FLOAT_EQ(renderer_->point_size(), kPointSize);
  EXPECT_TRUE(renderer_->HandleCharacter('+'));
  EXPECT_FLOAT_EQ(renderer_->point_size(), kPointSize + 1);
  const Point p{0.0f, 0.0f, 5.0f, PackRgba(0, 255, 0)};
  renderer_->Upload(&p, 1);
  EXPECT_EQ(Render().Count(Rgb{0, 255, 0}), 10 * 10) << "the new size must be drawn";
  for (int i = 0; i < 30; ++i) renderer_->HandleCharacter('-');
  EXPECT_FLOAT_EQ(renderer_->point_size(), 1.0f) << "point size is clamped at 1";
  EXPECT_EQ(Render().Count(Rgb{0, 255, 0}), 1);

  EXPECT_FALSE(renderer_->paused());
  EXPECT_TRUE(renderer_->HandleCharacter(' '));
  EXPECT_TRUE(renderer_->paused());
  renderer_->HandleCharacter(' ');
  EXPECT_FALSE(renderer_->paused());

  EXPECT_FALSE(renderer_->HandleCharacter('x'));
  EXPECT_FALSE(renderer_->ShouldClose());
  renderer_->Swap();  // event polling must not close a hidden window on its own
  EXPECT_FALSE(renderer_->ShouldClose());
  EXPECT_TRUE(renderer_->HandleCharacter('q'));
  EXPECT_TRUE(renderer_->ShouldClose());
}

TEST_F(RenderTest, TwoRenderersKeepTheirOwnClouds) {
  std::unique_ptr<Renderer> second = Open(200, 150);
  ASSERT_NE(second, nullptr);
  const Point a{0.0f, 0.0f, 5.0f, PackRgba(255, 0, 0)};
  const Point b{0.0f, 0.0f, 5.0f, PackRgba(0, 0, 255)};
  renderer_->Upload(&a, 1);
  second->Upload(&b, 1);
  const Image one = Render(*renderer_), two = Render(*second);
  EXPECT_EQ(one.Count(Rgb{255, 0, 0}), 81);
  EXPECT_EQ(one.Count(Rgb{0, 0, 255}), 0);
  EXPECT_EQ(two.width, 200);
  EXPECT_EQ(two.Count(Rgb{0, 0, 255}), 81);
  EXPECT_EQ(two.Count(Rgb{255, 0, 0}), 0);
}

// A PCD file the real cloudcast-process wrote (New Tsukuba frame 00001 with the paper's
// parameters, or the synthetic scene without the data) loads and renders into a real picture.
TEST_F(RenderTest, ProcessCliPcdRenders) {
  const std::string binary = std::string(CLOUDCAST_BIN_DIR) + "/cloudcast-process";
  ASSERT_TRUE(fs::exists(binary)) << binary << " is missing: build cloudcast-process";
  const std::string pcd = Path("frame.pcd");
  std::string command = "'" + binary + "'";
  if (cloudcast::testing::HaveTsukuba()) {
    command += " --colour '" + cloudcast::testing::TsukubaColourPath("00001") + "' --disparity '" +
               cloudcast::testing::TsukubaDisparityPath("00001") + "'";
  } else {
    command += " --synthetic 640x480";
  }
  command += " --quiet --out '" + pcd + "' >/dev/null 2>'" + Path("stderr.txt") + "'";
  const int status = std::system(command.c_str());
  ASSERT_TRUE(status != -1 && WIFEXITED(status) && WEXITSTATUS(status) == 0)
      << command << " failed (status " << status << ")";

  PointCloud cloud;
  ASSERT_TRUE(LoadCloud(pcd, &cloud).ok());
  ASSERT_GT(cloud.size(), 1000u);

  std::unique_ptr<Renderer> r = Open(640, 480, 2.0f);
  ASSERT_NE(r, nullptr);
  r->Upload(cloud.points.data(), cloud.size());
  r->ResetViewToCloud(cloud.points.data(), cloud.size());
  const Image img = Render(*r);
  const int drawn = img.CountNot(kBg);
  EXPECT_GT(drawn, img.width * img.height / 10) << "only " << drawn << " non-background pixels";
  std::set<std::uint32_t> colours;
  for (int y = 0; y < img.height; ++y) {
    for (int x = 0; x < img.width; ++x) {
      const Rgb c = img.At(x, y);
      colours.insert(PackRgba(c.r, c.g, c.b));
    }
  }
  EXPECT_GT(colours.size(), 500u) << "the cloud's colours should show, not a flat fill";
  // Every drawn colour is one of the cloud's colours (or the background).
  std::set<std::uint32_t> cloud_colours;
  for (const Point& p : cloud.points) cloud_colours.insert(p.rgba | 0xFF000000u);
  int foreign = 0;
  for (std::uint32_t c : colours)
    foreign += c != PackRgba(kBg.r, kBg.g, kBg.b) && !cloud_colours.count(c);
  EXPECT_EQ(foreign, 0) << "colours drawn that no point has";
}

// Without an X display Create fails with a Status, not a crash.
TEST(RenderCreateTest, NoDisplayIsAnError) {
  const char* saved = std::getenv("DISPLAY");
  const std::string restore = saved != nullptr ? saved : "";
  ::setenv("DISPLAY", ":65000", 1);  // nothing listens there
  absl::StatusOr<std::unique_ptr<Renderer>> r = Renderer::Create(RendererOptions{});
  if (restore.empty()) {
    ::unsetenv("DISPLAY");
  } else {
    ::setenv("DISPLAY", restore.c_str(), 1);
  }
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), absl::StatusCode::kFailedPrecondition) << r.status();
  EXPECT_NE(r.status().message().find("Xvfb"), std::string::npos) << r.status();

  RendererOptions bad;
  bad.width = 0;
  EXPECT_EQ(Renderer::Create(bad).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace cloudcast::render
