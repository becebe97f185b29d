// The viewer's orbit camera, without any GL: a target point, a distance and yaw / pitch angles
// in the point coordinates of cloudcast (the stereo camera frame: x right, y down, z forward).
//
// At yaw = pitch = 0 the camera looks along +z with +x to the right of the screen and +y towards
// the bottom, so a cloud looks like the camera image it came from. OpenGL's eye space has y up
// and looks along -z, hence the view matrix flips y and z (a 180-degree turn about x).
#pragma once

#include <array>

namespace cloudcast::render::internal {

using Vec3 = std::array<float, 3>;
using Mat4 = std::array<float, 16>;  // column-major, element [c * 4 + r]

Mat4 Multiply(const Mat4& a, const Mat4& b);  // a * b

class OrbitCamera {
 public:
  static constexpr float kFovYDegrees = 60.0f;

  // The default view: the eye at the origin looking along +z (target 5 units ahead).
  OrbitCamera();

  // Looks along +z (yaw = pitch = 0) at the centre of the box [lo, hi], from the distance at
  // which the box's near face fits both fields of view (with a 5% margin), which makes the whole
  // box visible. A degenerate box (a single point) gets distance 1.
  void Frame(const Vec3& lo, const Vec3& hi, float aspect);
  // Back to the default view.
  void Reset();

  // Deltas in window pixels; `viewport_height` converts pan pixels to world units at the
  // target's depth so the scene under the cursor follows it.
  void Orbit(float dx, float dy);
  void Pan(float dx, float dy, float viewport_height);
  void Zoom(float steps);

  Mat4 View() const;
  Mat4 Projection(float aspect) const;
  Mat4 ViewProjection(float aspect) const { return Multiply(Projection(aspect), View()); }

  const Vec3& target() const { return target_; }
  float distance() const { return distance_; }
  Vec3 Eye() const;

 private:
  Vec3 Forward() const;
  Vec3 Right() const;
  Vec3 Down() const;

  Vec3 target_;
  float distance_;
  float yaw_ = 0, pitch_ = 0;  // radians
  // The framed scene's bounding sphere: keeps the far plane beyond it however one zooms or pans.
  Vec3 scene_centre_;
  float scene_radius_;
};

}  // namespace cloudcast::render::internal
