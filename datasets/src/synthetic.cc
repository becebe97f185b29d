#include "cloudcast/datasets/synthetic.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "absl/strings/str_cat.h"
#include "cloudcast/core/limits.h"

namespace cloudcast {

namespace {

// ---------------------------------------------------------------------------------------------
// Small double-precision vector algebra. The whole renderer runs in double so that a rendered
// depth puts its pixel's ray on the surface to ~1e-15 relative; float only appears when the
// result is encoded.

struct Vec3 {
  double x = 0, y = 0, z = 0;
};
Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
Vec3 operator*(double s, Vec3 a) { return {s * a.x, s * a.y, s * a.z}; }
double Dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
double Norm(Vec3 a) { return std::sqrt(Dot(a, a)); }
Vec3 Normalized(Vec3 a) { return (1.0 / Norm(a)) * a; }
Vec3 Cross(Vec3 a, Vec3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
double Component(Vec3 a, int i) { return i == 0 ? a.x : (i == 1 ? a.y : a.z); }

// A rotation stored by its columns: the images of the local x, y and z axes in the parent frame.
struct Rot3 {
  Vec3 c0{1, 0, 0}, c1{0, 1, 0}, c2{0, 0, 1};
  Vec3 Apply(Vec3 v) const { return v.x * c0 + v.y * c1 + v.z * c2; }  // local -> parent
  Vec3 ApplyInverse(Vec3 v) const { return {Dot(c0, v), Dot(c1, v), Dot(c2, v)}; }
};
// this^T * other: maps other's local frame into this one's local frame.
Rot3 InverseTimes(const Rot3& a, const Rot3& b) {
  return {a.ApplyInverse(b.c0), a.ApplyInverse(b.c1), a.ApplyInverse(b.c2)};
}

// Rodrigues: rotation by `angle` radians about `axis`.
Rot3 AxisAngle(Vec3 axis, double angle) {
  const Vec3 k = Normalized(axis);
  const double c = std::cos(angle), s = std::sin(angle), t = 1.0 - c;
  auto column = [&](Vec3 e) {  // R e = e c + (k x e) s + k (k . e) t
    return c * e + s * Cross(k, e) + (t * Dot(k, e)) * k;
  };
  return {column({1, 0, 0}), column({0, 1, 0}), column({0, 0, 1})};
}

// ---------------------------------------------------------------------------------------------
// The world frame is the camera frame at rest: x right, y DOWN, z forward (right-handed, like
// camera.h). The floor is the plane y = 0, so a point `h` above the floor has y = -h.

Vec3 At(double x, double height, double z) { return {x, -height, z}; }

struct Rgb {
  double r = 0, g = 0, b = 0;  // 0..1
};
Rgb Mix(Rgb a, Rgb b, double t) {
  return {a.r + (b.r - a.r) * t, a.g + (b.g - a.g) * t, a.b + (b.b - a.b) * t};
}

enum class Pattern : std::uint8_t {
  kChecker,   // squares of side `scale` alternating a/b
  kStripes,   // stripes of width `scale` across the first surface coordinate
  kGradient,  // a smooth ramp a -> b across `scale` units, repeating as a triangle wave
  kRings,     // stripes on the second coordinate whose colour drifts along the first
};

struct Texture {
  Pattern pattern = Pattern::kChecker;
  Rgb a, b;
  double scale = 1.0;
};

enum class ShapeKind : std::uint8_t {
  kRect,    // the local z = 0 plane, |x| <= half.x, |y| <= half.y
  kBox,     // |x| <= half.x, |y| <= half.y, |z| <= half.z
  kSphere,  // |q| = half.x
};

// One period of the camera path, in frames (12 s at 30 fps). Any uint64 frame is valid.
constexpr std::uint64_t kPathPeriod = 360;
constexpr double kPi = 3.14159265358979323846;

// A raw value PCL's preset treats as "no measurement" (Kinect's 0x7FF); a real disparity that
// would encode to it is moved to the neighbouring code so it does not vanish on conversion.
constexpr double kPclInvalidRaw = 2047.0;

struct CameraPose {
  Vec3 position;        // world
  Rot3 world_from_cam;  // columns: camera right, down, forward in world
};

// A slow periodic orbit: the camera sways left/right, dollies a little, bobs and keeps turning
// toward the middle of the scene, always looking slightly down at the floor.
CameraPose PoseForFrame(std::uint64_t frame) {
  const double phase =
      2.0 * kPi * static_cast<double>(frame % kPathPeriod) / static_cast<double>(kPathPeriod);
  CameraPose pose;
  // The nearest floor seen is at z = height / ((v_max - cy) / fy * cos(pitch) + sin(pitch)),
  // at least 1.47 / 0.552 = 2.66 here, so at 640 px kU8 disparities (615 / z) stay below 255.
  pose.position = At(1.2 * std::sin(phase), 1.55 + 0.08 * std::sin(2.0 * phase),
                     0.35 * (1.0 - std::cos(phase)));
  const double yaw = -0.09 * std::sin(phase);          // radians, + turns right (toward +x)
  const double pitch = 0.15 + 0.02 * std::cos(phase);  // radians, + looks down (toward +y)
  const Vec3 forward = {std::sin(yaw) * std::cos(pitch), std::sin(pitch),
                        std::cos(yaw) * std::cos(pitch)};
  const Vec3 right = {std::cos(yaw), 0.0, -std::sin(yaw)};
  const Vec3 down = Cross(forward, right);  // right x down = forward (right-handed)
  pose.world_from_cam = {right, down, forward};
  return pose;
}

// Per-pixel work is done in each shape's local frame; these hold one shape seen from one pose.
struct PosedShape {
  ShapeKind kind;
  Vec3 half;
  Rot3 local_from_cam;  // a camera-frame direction d maps to local_from_cam.Apply(d)
  Vec3 origin;          // the camera centre in local coordinates
  // Conservative pixel window of the shape (from its bounding sphere); outside it, no test.
  std::int64_t u_min, u_max, v_min, v_max;
  int index;  // into shapes_
};

// Colour as BGR8 with round-to-nearest.
void StoreBgr(Rgb c, std::uint8_t* out) {
  auto q = [](double v) {
    return static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0, 1.0) * 255.0));
  };
  out[0] = q(c.b);
  out[1] = q(c.g);
  out[2] = q(c.r);
}

double Fract(double v) { return v - std::floor(v); }

}  // namespace

// ---------------------------------------------------------------------------------------------

struct SyntheticScene::Shape {
  ShapeKind kind;
  Vec3 centre;  // world
  Rot3 world_from_local;
  Vec3 half;  // half extents; a sphere's radius is half.x
  Texture texture;
};

SyntheticScene::SyntheticScene() = default;
SyntheticScene::~SyntheticScene() = default;
SyntheticScene::SyntheticScene(const SyntheticScene&) = default;
SyntheticScene& SyntheticScene::operator=(const SyntheticScene&) = default;

SyntheticScene SyntheticScene::Default() {
  SyntheticScene scene;
  auto add = [&scene](ShapeKind kind, Vec3 centre, Rot3 rot, Vec3 half, Texture tex) {
    scene.shapes_.push_back(Shape{kind, centre, rot, half, tex});
  };
  const Rot3 identity;
  const Vec3 up = {0, -1, 0};

  // Floor: the y = 0 plane from z = -6 to z = 14 (it ends at the wall). Local x = world x,
  // local y = world z, local z = world y (the normal).
  add(ShapeKind::kRect, At(0, 0, 4), Rot3{{1, 0, 0}, {0, 0, 1}, {0, 1, 0}}, {14, 10, 0},
      {Pattern::kChecker, {0.80, 0.72, 0.55}, {0.35, 0.24, 0.16}, 1.0});
  // Back wall at z = 14, 4 high: at every frame its depth (about 12.5..14.5) lies beyond the
  // paper's passthrough maximum of 12. Above it the rays hit nothing (disparity 0).
  add(ShapeKind::kRect, At(0, 2.0, 14), identity, {14, 2.0, 0},
      {Pattern::kStripes, {0.25, 0.45, 0.85}, {0.90, 0.90, 0.80}, 0.5});

  // Boxes: one axis-aligned on the floor, one turned about the vertical, a tilted floating one
  // and a pillar near the far edge of the passthrough range.
  add(ShapeKind::kBox, At(-2.2, 0.6, 5.5), identity, {0.6, 0.6, 0.6},
      {Pattern::kChecker, {0.90, 0.15, 0.12}, {0.97, 0.95, 0.90}, 0.3});
  add(ShapeKind::kBox, At(2.0, 0.9, 8.0), AxisAngle(up, 35.0 * kPi / 180.0), {0.9, 0.9, 0.5},
      {Pattern::kStripes, {0.15, 0.25, 0.80}, {0.95, 0.85, 0.20}, 0.25});
  add(ShapeKind::kBox, At(0.3, 2.6, 9.5), AxisAngle({1, 1, 0.5}, 40.0 * kPi / 180.0),
      {0.7, 0.35, 0.5}, {Pattern::kGradient, {0.10, 0.55, 0.20}, {0.75, 0.95, 0.30}, 0.8});
  add(ShapeKind::kBox, At(4.2, 1.6, 11.3), AxisAngle(up, 20.0 * kPi / 180.0), {0.3, 1.6, 0.3},
      {Pattern::kRings, {0.60, 0.20, 0.70}, {0.95, 0.75, 0.40}, 0.2});

  // Spheres: on the floor near the camera, a large one to the left, a small floating one, and
  // one straddling the depth 12 cut.
  add(ShapeKind::kSphere, At(0.2, 0.8, 5.0), identity, {0.8, 0, 0},
      {Pattern::kChecker, {0.55, 0.20, 0.75}, {0.20, 0.85, 0.85}, 0.35});
  add(ShapeKind::kSphere, At(-3.4, 1.25, 9.0), AxisAngle({0, 0, 1}, 0.4), {1.25, 0, 0},
      {Pattern::kRings, {0.95, 0.55, 0.10}, {0.30, 0.10, 0.05}, 0.3});
  add(ShapeKind::kSphere, At(2.4, 2.4, 6.0), identity, {0.45, 0, 0},
      {Pattern::kGradient, {0.95, 0.95, 0.30}, {0.90, 0.30, 0.50}, 0.6});
  add(ShapeKind::kSphere, At(-0.8, 0.5, 12.4), identity, {1.0, 0, 0},
      {Pattern::kStripes, {0.20, 0.70, 0.45}, {0.05, 0.20, 0.35}, 0.3});
  return scene;
}

// ---------------------------------------------------------------------------------------------

namespace {

// Surface colour of a hit at local point `q` with local normal `n` (facing the camera).
Rgb Shade(ShapeKind kind, const Texture& tex, Vec3 q, Vec3 n, int face,
          const Rot3& world_from_local, double radius) {
  // 2D surface coordinates (s, t) in scene units.
  double s = 0, t = 0;
  switch (kind) {
    case ShapeKind::kRect:
      s = q.x;
      t = q.y;
      break;
    case ShapeKind::kBox: {
      const int axis = face / 2;
      s = Component(q, (axis + 1) % 3);
      t = Component(q, (axis + 2) % 3);
      break;
    }
    case ShapeKind::kSphere: {
      // Longitude/latitude, scaled to arc length so the pattern keeps its size.
      const double lon = std::atan2(q.x, q.z);
      const double lat = std::asin(std::clamp(q.y / radius, -1.0, 1.0));
      s = lon * radius;
      t = lat * radius;
      break;
    }
  }
  double mix = 0;
  switch (tex.pattern) {
    case Pattern::kChecker: {
      const auto i = static_cast<std::int64_t>(std::floor(s / tex.scale)) +
                     static_cast<std::int64_t>(std::floor(t / tex.scale));
      mix = (i & 1) ? 1.0 : 0.0;
      break;
    }
    case Pattern::kStripes:
      mix = Fract(s / (2.0 * tex.scale)) < 0.5 ? 0.0 : 1.0;
      break;
    case Pattern::kGradient:
      mix = std::fabs(2.0 * Fract((s + 0.5 * t) / (2.0 * tex.scale)) - 1.0);
      break;
    case Pattern::kRings:
      mix = (Fract(t / (2.0 * tex.scale)) < 0.5 ? 0.15 : 0.85) + 0.15 * std::sin(3.0 * s);
      break;
  }
  Rgb albedo = Mix(tex.a, tex.b, std::clamp(mix, 0.0, 1.0));
  // A slow hue drift across every surface and a per-face tint, so colour carries position.
  const double drift = 0.12 * std::sin(0.9 * s + 0.4 * t);
  albedo.r += drift;
  albedo.b -= drift;
  if (kind == ShapeKind::kBox) albedo = Mix(albedo, {1, 1, 1}, 0.05 * (face % 3));
  const Vec3 n_world = world_from_local.Apply(n);
  // Direction toward a light (world frame: above, left of and behind the camera), baked into the
  // colour so the faces of a box differ and colours vary smoothly.
  static const Vec3 kLightDirection = Normalized({-0.4, -1.0, -0.35});
  const double lambert = std::max(0.0, Dot(n_world, kLightDirection));
  const double light = 0.55 + 0.45 * lambert;
  return {albedo.r * light, albedo.g * light, albedo.b * light};
}

// Sky above the wall: no surface, disparity 0; a vertical gradient keeps the colour image natural.
Rgb Sky(double b) { return Mix({0.75, 0.85, 0.98}, {0.45, 0.62, 0.90}, std::clamp(-b, 0.0, 1.0)); }

// Exact unsigned distance from local point q to one shape's surface.
double LocalDistance(ShapeKind kind, Vec3 half, Vec3 q) {
  switch (kind) {
    case ShapeKind::kRect: {
      const double dx = std::max(std::fabs(q.x) - half.x, 0.0);
      const double dy = std::max(std::fabs(q.y) - half.y, 0.0);
      return std::sqrt(dx * dx + dy * dy + q.z * q.z);
    }
    case ShapeKind::kBox: {
      // Box signed distance: outside part plus (negative) inside part.
      const Vec3 d = {std::fabs(q.x) - half.x, std::fabs(q.y) - half.y, std::fabs(q.z) - half.z};
      const Vec3 outside = {std::max(d.x, 0.0), std::max(d.y, 0.0), std::max(d.z, 0.0)};
      const double inside = std::min(std::max(d.x, std::max(d.y, d.z)), 0.0);
      return std::fabs(Norm(outside) + inside);
    }
    case ShapeKind::kSphere:
      return std::fabs(Norm(q) - half.x);
  }
  return std::numeric_limits<double>::infinity();
}

// Pixel window [lo, hi] along one image axis of a sphere (centre (c, z) in the plane of that
// axis and the optical axis, radius r): rays x = a z tangent to the circle satisfy
// (c - a z)^2 = r^2 (1 + a^2), i.e. a = (c z +- r sqrt(c^2 + z^2 - r^2)) / (z^2 - r^2).
// Returns false when the sphere reaches the camera plane (then no window is used).
bool TangentWindow(double c, double z, double r, double focal, double principal, std::int64_t size,
                   std::int64_t* lo, std::int64_t* hi) {
  const double denom = z * z - r * r;
  if (z <= 0 || denom <= 1e-6 * z * z) return false;
  const double root = r * std::sqrt(c * c + denom);
  const double a_lo = (c * z - root) / denom;
  const double a_hi = (c * z + root) / denom;
  // Two pixels of padding absorb rounding; the window is only an early-out.
  const double p_lo = std::floor(principal + a_lo * focal) - 2.0;
  const double p_hi = std::ceil(principal + a_hi * focal) + 2.0;
  *lo = static_cast<std::int64_t>(std::clamp(p_lo, -1.0, static_cast<double>(size)));
  *hi = static_cast<std::int64_t>(std::clamp(p_hi, -1.0, static_cast<double>(size)));
  return true;
}

// Nearest t in (0, best) at which the pixel ray (camera frame: t * (a, b, 1)) meets the shape; `d`
// is (a, b, 1) in the shape's local frame. Returns `best` when there is no nearer hit; `face` gets
// the box face entered (2k: the -k face, 2k + 1: the +k face).
double Intersect(const PosedShape& p, Vec3 d, double best, int* face) {
  const Vec3 o = p.origin;
  switch (p.kind) {
    case ShapeKind::kRect: {
      if (d.z == 0.0) return best;
      const double t = -o.z / d.z;  // local plane z = 0
      if (!(t > 0.0 && t < best)) return best;
      if (std::fabs(o.x + t * d.x) > p.half.x || std::fabs(o.y + t * d.y) > p.half.y) return best;
      return t;
    }
    case ShapeKind::kBox: {
      // Slabs: the ray is inside the box for t in [latest entry, earliest exit].
      double t_near = -std::numeric_limits<double>::infinity();
      double t_far = std::numeric_limits<double>::infinity();
      int near_face = -1;
      for (int k = 0; k < 3; ++k) {
        const double ok = Component(o, k), dk = Component(d, k), hk = Component(p.half, k);
        if (dk == 0.0) {
          if (std::fabs(ok) > hk) return best;  // parallel to and outside this slab
          continue;
        }
        double t0 = (-hk - ok) / dk;
        double t1 = (hk - ok) / dk;
        int f = 2 * k;  // moving toward +k: enters through the -k face
        if (t0 > t1) {
          std::swap(t0, t1);
          f = 2 * k + 1;
        }
        if (t0 > t_near) {
          t_near = t0;
          near_face = f;
        }
        t_far = std::min(t_far, t1);
        if (t_near > t_far) return best;
      }
      if (near_face < 0 || !(t_near > 0.0 && t_near < best)) return best;
      *face = near_face;
      return t_near;
    }
    case ShapeKind::kSphere: {
      // |o + t d|^2 = r^2, i.e. A t^2 + 2 B t + C = 0. The nearer root written as C / q, with
      // q = -B + sqrt(B^2 - A C), avoids cancellation.
      const double A = Dot(d, d), B = Dot(o, d), C = Dot(o, o) - p.half.x * p.half.x;
      if (B >= 0.0 || C <= 0.0) return best;  // moving away, or camera inside (never here)
      const double disc = B * B - A * C;
      if (disc < 0.0) return best;
      const double t = C / (-B + std::sqrt(disc));
      return t > 0.0 && t < best ? t : best;
    }
  }
  return best;
}

}  // namespace

absl::StatusOr<SyntheticFrame> SyntheticScene::Render(const SyntheticOptions& options) const {
  const Limits limits;
  if (options.width == 0 || options.width > limits.max_side) {
    return absl::InvalidArgumentError(
        absl::StrCat("synthetic.width must be in [1, ", limits.max_side, "], got ", options.width));
  }
  if (options.height == 0 || options.height > limits.max_side) {
    return absl::InvalidArgumentError(absl::StrCat("synthetic.height must be in [1, ",
                                                   limits.max_side, "], got ", options.height));
  }
  const std::uint64_t pixels = std::uint64_t{options.width} * options.height;
  if (pixels > limits.max_pixels) {
    return absl::InvalidArgumentError(absl::StrCat("synthetic.width x synthetic.height is ",
                                                   options.width, "x", options.height, " = ",
                                                   pixels, " pixels; at most ", limits.max_pixels));
  }
  const DisparityEncoding encoding = options.disparity_encoding;
  if (encoding != DisparityEncoding::kU8 && encoding != DisparityEncoding::kU16 &&
      encoding != DisparityEncoding::kF32) {
    return absl::InvalidArgumentError(absl::StrCat(
        "synthetic.disparity_encoding is not a known encoding (", static_cast<int>(encoding), ")"));
  }

  const std::uint32_t width = options.width, height = options.height;
  SyntheticFrame frame;
  frame.width = width;
  frame.height = height;
  frame.disparity_encoding = encoding;
  frame.camera = CameraModel::PclCompatible(width, height, 615.0 * width / 640.0);
  if (encoding == DisparityEncoding::kU16) frame.camera.disparity_scale = 1.0 / 16.0;
  frame.disparity.assign(pixels * BytesPerPixel(encoding), 0);
  frame.colour.assign(pixels * 3, 0);

  const double fx = frame.camera.fx, fy = frame.camera.fy;
  const double cx = frame.camera.cx, cy = frame.camera.cy;
  const double baseline = frame.camera.baseline;

  // Bring every shape into the camera frame of this pose once.
  CameraPose pose = PoseForFrame(options.frame);
  pose.position = pose.position + options.eye_x * pose.world_from_cam.c0;
  std::vector<PosedShape> posed;
  posed.reserve(shapes_.size());
  for (std::size_t i = 0; i < shapes_.size(); ++i) {
    const Shape& s = shapes_[i];
    PosedShape p;
    p.kind = s.kind;
    p.half = s.half;
    p.local_from_cam = InverseTimes(s.world_from_local, pose.world_from_cam);
    p.origin = s.world_from_local.ApplyInverse(pose.position - s.centre);
    p.index = static_cast<int>(i);
    p.u_min = p.v_min = -1;
    p.u_max = width;
    p.v_max = height;
    if (s.kind != ShapeKind::kRect) {
      const double radius = s.kind == ShapeKind::kSphere ? s.half.x : Norm(s.half);
      const Vec3 c = pose.world_from_cam.ApplyInverse(s.centre - pose.position);
      std::int64_t lo, hi;
      if (TangentWindow(c.x, c.z, radius, fx, cx, width, &lo, &hi)) {
        p.u_min = lo;
        p.u_max = hi;
      }
      if (TangentWindow(c.y, c.z, radius, fy, cy, height, &lo, &hi)) {
        p.v_min = lo;
        p.v_max = hi;
      }
    }
    posed.push_back(p);
  }

  std::vector<const PosedShape*> row_shapes;
  row_shapes.reserve(posed.size());
  for (std::uint32_t v = 0; v < height; ++v) {
    row_shapes.clear();
    for (const PosedShape& p : posed) {
      if (static_cast<std::int64_t>(v) >= p.v_min && static_cast<std::int64_t>(v) <= p.v_max) {
        row_shapes.push_back(&p);
      }
    }
    // Pixel (u, v) sees the camera-frame ray t * (a, b, 1), a = (u - cx) / fx, b = (v - cy) / fy:
    // the inverse of camera.h's x = (u - cx) * z / fx, y = (v - cy) * z / fy. Its parameter t is
    // therefore the depth z along the optical axis.
    const double b = (static_cast<double>(v) - cy) / fy;
    std::uint8_t* disparity_row =
        frame.disparity.data() + std::size_t{v} * width * BytesPerPixel(encoding);
    std::uint8_t* colour_row = frame.colour.data() + std::size_t{v} * width * 3;
    for (std::uint32_t u = 0; u < width; ++u) {
      const double a = (static_cast<double>(u) - cx) / fx;
      const Vec3 ray = {a, b, 1.0};
      double best = std::numeric_limits<double>::infinity();
      const PosedShape* hit = nullptr;
      Vec3 hit_dir;  // ray direction in the hit shape's local frame
      int hit_face = 0;
      for (const PosedShape* p : row_shapes) {
        if (static_cast<std::int64_t>(u) < p->u_min || static_cast<std::int64_t>(u) > p->u_max) {
          continue;
        }
        const Vec3 d = p->local_from_cam.Apply(ray);
        int face = 0;
        const double t = Intersect(*p, d, best, &face);
        if (t < best) {
          best = t;
          hit = p;
          hit_dir = d;
          hit_face = face;
        }
      }

      std::uint8_t* colour_px = colour_row + std::size_t{u} * 3;
      if (hit == nullptr) {
        StoreBgr(Sky(b), colour_px);
        continue;  // disparity stays 0: no measurement
      }
      const double z = best;
      const double d = fx * baseline / z;  // camera.h: z = fx * baseline / d
      switch (encoding) {
        case DisparityEncoding::kU8: {
          const double q = std::round(d);
          // 8 bits cannot hold it: invalid, as an 8-bit matcher would report.
          disparity_row[u] = q > 255.0 ? 0 : static_cast<std::uint8_t>(q);
          break;
        }
        case DisparityEncoding::kU16: {
          const double scaled = d * 16.0;  // raw = d / disparity_scale, scale 1/16
          double q = std::round(scaled);
          if (q == kPclInvalidRaw) q += scaled < q ? -1.0 : 1.0;
          const std::uint16_t raw = q > 65535.0 ? 0 : static_cast<std::uint16_t>(q);
          std::memcpy(disparity_row + std::size_t{u} * 2, &raw, 2);
          break;
        }
        case DisparityEncoding::kF32: {
          float f = static_cast<float>(d);
          if (f == static_cast<float>(kPclInvalidRaw)) {
            f = std::nextafter(f, d < kPclInvalidRaw ? 0.0f : 4096.0f);
          }
          std::memcpy(disparity_row + std::size_t{u} * 4, &f, 4);
          break;
        }
      }
      const Shape& shape = shapes_[hit->index];
      const Vec3 q = hit->origin + z * hit_dir;
      Vec3 n;
      switch (shape.kind) {
        case ShapeKind::kRect:
          n = {0, 0, hit_dir.z > 0 ? -1.0 : 1.0};  // the side facing the camera
          break;
        case ShapeKind::kBox: {
          const double sign = (hit_face & 1) ? 1.0 : -1.0;
          const int axis = hit_face / 2;
          n = {axis == 0 ? sign : 0.0, axis == 1 ? sign : 0.0, axis == 2 ? sign : 0.0};
          break;
        }
        case ShapeKind::kSphere:
          n = (1.0 / shape.half.x) * q;
          break;
      }
      StoreBgr(
          Shade(shape.kind, shape.texture, q, n, hit_face, shape.world_from_local, shape.half.x),
          colour_px);
    }
  }
  return frame;
}

double SyntheticScene::DistanceToSurface(std::uint64_t frame, double x, double y, double z) const {
  const CameraPose pose = PoseForFrame(frame);
  const Vec3 world = pose.position + pose.world_from_cam.Apply({x, y, z});
  double best = std::numeric_limits<double>::infinity();
  for (const Shape& s : shapes_) {
    best = std::min(
        best, LocalDistance(s.kind, s.half, s.world_from_local.ApplyInverse(world - s.centre)));
  }
  return best;
}

absl::StatusOr<std::vector<std::uint8_t>> SyntheticStereoTruth(const SyntheticFrame& left) {
  if (left.disparity_encoding != DisparityEncoding::kF32) {
    return absl::InvalidArgumentError(
        "left.disparity_encoding: the stereo truth is computed from exact (kF32) disparities");
  }
  std::vector<std::uint8_t> truth(std::size_t{left.width} * left.height);
  const float* src = reinterpret_cast<const float*>(left.disparity.data());
  for (std::size_t i = 0; i < truth.size(); ++i) {
    // The render's disparity is for a baseline of 1; the pair's is kSyntheticStereoBaseline.
    const double v = src[i] * kSyntheticStereoBaseline;
    truth[i] =
        std::isfinite(v) && v > 0.5 && v < 255 ? static_cast<std::uint8_t>(std::lround(v)) : 0;
  }
  return truth;
}

DisparityView SyntheticFrame::disparity_view() const {
  DisparityView view;
  view.data = disparity.data();
  view.size_bytes = disparity.size();
  view.width = width;
  view.height = height;
  view.stride_bytes = std::size_t{width} * BytesPerPixel(disparity_encoding);
  view.encoding = disparity_encoding;
  return view;
}

ColorView SyntheticFrame::colour_view() const {
  ColorView view;
  view.data = colour.data();
  view.size_bytes = colour.size();
  view.width = width;
  view.height = height;
  view.stride_bytes = std::size_t{width} * 3;
  view.encoding = ColorEncoding::kBGR8;
  return view;
}

}  // namespace cloudcast
