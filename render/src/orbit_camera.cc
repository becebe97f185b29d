#include "orbit_camera.h"

#include <algorithm>
#include <cmath>

namespace cloudcast::render::internal {
namespace {

constexpr float kPi = 3.14159265358979f;
constexpr float kDefaultDistance = 5.0f;
constexpr float kDefaultSceneRadius = 100.0f;
// Radians per pixel of mouse drag: a drag across a 720-pixel window turns about 200 degrees.
constexpr float kOrbitRadiansPerPixel = 0.005f;
// Just short of straight up / down, where yaw would become a roll and the view flip.
constexpr float kMaxPitch = 89.0f * kPi / 180.0f;

float Dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec3 Cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
float TanHalfFovY() { return std::tan(OrbitCamera::kFovYDegrees * kPi / 360.0f); }

}  // namespace

Mat4 Multiply(const Mat4& a, const Mat4& b) {
  Mat4 m{};
  for (int c = 0; c < 4; ++c) {
    for (int r = 0; r < 4; ++r) {
      float s = 0;
      for (int k = 0; k < 4; ++k) s += a[k * 4 + r] * b[c * 4 + k];
      m[c * 4 + r] = s;
    }
  }
  return m;
}

OrbitCamera::OrbitCamera() { Reset(); }

void OrbitCamera::Reset() {
  target_ = {0.0f, 0.0f, kDefaultDistance};
  distance_ = kDefaultDistance;
  yaw_ = pitch_ = 0;
  scene_centre_ = target_;
  scene_radius_ = kDefaultSceneRadius;
}

void OrbitCamera::Frame(const Vec3& lo, const Vec3& hi, float aspect) {
  Vec3 half;
  for (int i = 0; i < 3; ++i) {
    target_[i] = 0.5f * (lo[i] + hi[i]);
    half[i] = 0.5f * std::fabs(hi[i] - lo[i]);
  }
  yaw_ = pitch_ = 0;
  // The near face (depth distance - half z) is the largest in projection: it must fit both
  // half-angles. tan(fov_x / 2) = aspect * tan(fov_y / 2).
  const float tan_y = TanHalfFovY();
  const float tan_x = tan_y * std::max(aspect, 1e-3f);
  const float fit = std::max(half[1] / tan_y, half[0] / tan_x) * 1.05f + half[2];
  const float radius = std::sqrt(Dot(half, half));
  distance_ = fit > 1e-6f ? fit : 1.0f;
  scene_centre_ = target_;
  scene_radius_ = std::max(radius, 1e-3f);
}

void OrbitCamera::Orbit(float dx, float dy) {
  // Dragging right swings the camera to the left around the target, so the scene turns with the
  // mouse; dragging down looks from above.
  yaw_ -= dx * kOrbitRadiansPerPixel;
  pitch_ = std::clamp(pitch_ - dy * kOrbitRadiansPerPixel, -kMaxPitch, kMaxPitch);
}

void OrbitCamera::Pan(float dx, float dy, float viewport_height) {
  const float world_per_pixel = 2.0f * distance_ * TanHalfFovY() / std::max(viewport_height, 1.0f);
  const Vec3 right = Right(), down = Down();
  for (int i = 0; i < 3; ++i) {
    target_[i] -= (right[i] * dx + down[i] * dy) * world_per_pixel;
  }
}

void OrbitCamera::Zoom(float steps) {
  distance_ = std::clamp(distance_ * std::pow(0.9f, steps), 1e-4f, 1e7f);
}

Vec3 OrbitCamera::Forward() const {
  // Positive pitch looks up (towards -y), positive yaw turns towards +x.
  return {std::sin(yaw_) * std::cos(pitch_), -std::sin(pitch_), std::cos(yaw_) * std::cos(pitch_)};
}
Vec3 OrbitCamera::Right() const { return {std::cos(yaw_), 0.0f, -std::sin(yaw_)}; }
// x right, y down, z forward is right-handed, so down = forward x right.
Vec3 OrbitCamera::Down() const { return Cross(Forward(), Right()); }

Vec3 OrbitCamera::Eye() const {
  const Vec3 f = Forward();
  return {target_[0] - distance_ * f[0], target_[1] - distance_ * f[1],
          target_[2] - distance_ * f[2]};
}

Mat4 OrbitCamera::View() const {
  // Rows: eye-space x = right, y = -down (GL's y is up), z = -forward (GL looks along -z).
  const Vec3 r = Right(), d = Down(), f = Forward(), e = Eye();
  const Vec3 rows[3] = {r, {-d[0], -d[1], -d[2]}, {-f[0], -f[1], -f[2]}};
  Mat4 m{};
  for (int row = 0; row < 3; ++row) {
    for (int c = 0; c < 3; ++c) m[c * 4 + row] = rows[row][c];
    m[12 + row] = -Dot(rows[row], e);
  }
  m[15] = 1.0f;
  return m;
}

Mat4 OrbitCamera::Projection(float aspect) const {
  // Near plane at 1% of the distance keeps the depth range (far / near) in the hundreds, which
  // the 24-bit depth buffer resolves easily; the far plane is beyond the whole framed scene.
  const float near_plane = std::max(distance_ * 0.01f, 1e-5f);
  Vec3 offset;
  for (int i = 0; i < 3; ++i) offset[i] = target_[i] - scene_centre_[i];
  const float far_plane =
      distance_ + std::sqrt(Dot(offset, offset)) + 2.0f * scene_radius_ + near_plane;
  const float f = 1.0f / TanHalfFovY();
  Mat4 m{};
  m[0] = f / std::max(aspect, 1e-3f);
  m[5] = f;
  m[10] = (far_plane + near_plane) / (near_plane - far_plane);
  m[11] = -1.0f;
  m[14] = 2.0f * far_plane * near_plane / (near_plane - far_plane);
  return m;
}

}  // namespace cloudcast::render::internal
