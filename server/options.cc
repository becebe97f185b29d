#include "options.h"

#include <algorithm>
#include <cmath>
#include <thread>

#include <unistd.h>

#include "absl/strings/str_cat.h"

namespace cloudcast::server {
namespace {

// Core stage values are checked once more by the core itself; these checks come first so that
// the message names the proto field the client set, and says which limit it broke.
absl::Status Invalid(const std::string& message) { return absl::InvalidArgumentError(message); }

absl::Status CheckPositive(const std::string& field, double v) {
  if (!std::isfinite(v) || v <= 0.0 || v > 1e9) {
    return Invalid(absl::StrCat(field, " must be finite and in (0, 1e9], got ", v));
  }
  return absl::OkStatus();
}

absl::Status CheckFinite(const std::string& field, double v) {
  if (!std::isfinite(v) || std::fabs(v) > 1e9) {
    return Invalid(absl::StrCat(field, " must be finite and within +-1e9, got ", v));
  }
  return absl::OkStatus();
}

absl::Status CheckLeaf(const std::string& field, float v) {
  // The voxel grid multiplies by 1 / leaf in float, so that must be finite too.
  if (!std::isfinite(v) || !(v > 0.0f) || !std::isfinite(1.0f / v)) {
    return Invalid(
        absl::StrCat(field, " must be finite and > 0 (with 1/leaf a finite float), got ", v));
  }
  return absl::OkStatus();
}

absl::Status CheckRange(const std::string& field, std::int64_t v, std::int64_t lo,
                        std::int64_t hi) {
  if (v < lo || v > hi) {
    return Invalid(absl::StrCat(field, " is ", v, "; it must be in [", lo, ", ", hi, "]"));
  }
  return absl::OkStatus();
}

absl::Status ResolveCamera(const v1::CameraModel& c, const std::string& p, StreamSettings* s) {
  CameraModel& cam = s->camera;
  if (c.has_fx()) {
    if (auto st = CheckPositive(p + ".fx", c.fx()); !st.ok()) return st;
    cam.fx = c.fx();
    cam.fy = c.fx();  // fy follows fx unless set
  }
  if (c.has_fy()) {
    if (auto st = CheckPositive(p + ".fy", c.fy()); !st.ok()) return st;
    cam.fy = c.fy();
  }
  if (c.has_cx()) {
    if (auto st = CheckFinite(p + ".cx", c.cx()); !st.ok()) return st;
    cam.cx = c.cx();
    s->has_cx = true;
  }
  if (c.has_cy()) {
    if (auto st = CheckFinite(p + ".cy", c.cy()); !st.ok()) return st;
    cam.cy = c.cy();
    s->has_cy = true;
  }
  if (c.has_baseline()) {
    if (auto st = CheckPositive(p + ".baseline", c.baseline()); !st.ok()) return st;
    cam.baseline = c.baseline();
  }
  if (c.has_disparity_scale()) {
    if (auto st = CheckFinite(p + ".disparity_scale", c.disparity_scale()); !st.ok()) return st;
    if (c.disparity_scale() == 0.0) {
      return Invalid(absl::StrCat(p, ".disparity_scale must not be 0"));
    }
    cam.disparity_scale = c.disparity_scale();
  }
  if (c.has_disparity_offset()) {
    if (auto st = CheckFinite(p + ".disparity_offset", c.disparity_offset()); !st.ok()) return st;
    cam.disparity_offset = c.disparity_offset();
  }
  if (c.has_invalid_disparities()) {
    const auto& values = c.invalid_disparities().values();
    constexpr int kMaxInvalid = 16;  // the core's limit: they are tested per pixel
    if (values.size() > kMaxInvalid) {
      return Invalid(absl::StrCat(p, ".invalid_disparities.values holds ", values.size(),
                                  " values; the limit is ", kMaxInvalid));
    }
    for (int i = 0; i < values.size(); ++i) {
      if (!std::isfinite(values[i])) {
        return Invalid(absl::StrCat(p, ".invalid_disparities.values[", i, "] must be finite, got ",
                                    values[i]));
      }
    }
    cam.invalid_disparities.assign(values.begin(), values.end());
  }
  return absl::OkStatus();
}

absl::Status ResolvePassThrough(const v1::PassThroughConfig& c, const std::string& p,
                                StreamSettings* s) {
  PassThroughParams& pt = s->passthrough;
  if (c.has_enabled()) pt.enabled = c.enabled();
  switch (c.axis()) {
    case v1::AXIS_UNSPECIFIED:
      break;
    case v1::AXIS_X:
      pt.axis = Axis::kX;
      break;
    case v1::AXIS_Y:
      pt.axis = Axis::kY;
      break;
    case v1::AXIS_Z:
      pt.axis = Axis::kZ;
      break;
    default:
      return Invalid(absl::StrCat(p, ".axis is ", static_cast<int>(c.axis()),
                                  ", not one of AXIS_X, AXIS_Y, AXIS_Z"));
  }
  if (c.has_min()) {
    if (!std::isfinite(c.min()))
      return Invalid(absl::StrCat(p, ".min must be finite, got ", c.min()));
    pt.min = c.min();
  }
  if (c.has_max()) {
    if (!std::isfinite(c.max()))
      return Invalid(absl::StrCat(p, ".max must be finite, got ", c.max()));
    pt.max = c.max();
  }
  if (pt.min > pt.max) {
    return Invalid(absl::StrCat(p, ".min (", pt.min, c.has_min() ? "" : ", the server default",
                                ") must not exceed ", p, ".max (", pt.max,
                                c.has_max() ? "" : ", the server default", ")"));
  }
  if (c.has_negative()) pt.negative = c.negative();
  return absl::OkStatus();
}

absl::Status ResolveVoxelGrid(const v1::VoxelGridConfig& c, const std::string& p,
                              StreamSettings* s) {
  VoxelGridParams& v = s->voxel;
  if (c.has_enabled()) v.enabled = c.enabled();
  if (c.has_leaf()) {
    if (auto st = CheckLeaf(p + ".leaf", c.leaf()); !st.ok()) return st;
    v.SetLeaf(c.leaf());
  }
  if (c.has_leaf_x()) {
    if (auto st = CheckLeaf(p + ".leaf_x", c.leaf_x()); !st.ok()) return st;
    v.leaf_x = c.leaf_x();
  }
  if (c.has_leaf_y()) {
    if (auto st = CheckLeaf(p + ".leaf_y", c.leaf_y()); !st.ok()) return st;
    v.leaf_y = c.leaf_y();
  }
  if (c.has_leaf_z()) {
    if (auto st = CheckLeaf(p + ".leaf_z", c.leaf_z()); !st.ok()) return st;
    v.leaf_z = c.leaf_z();
  }
  if (c.has_min_points_per_voxel()) v.min_points_per_voxel = c.min_points_per_voxel();
  // A server run with --leaf 0 has the grid off by default; a client that asks for a leaf (and
  // says nothing of `enabled`) wants it on.
  if (!c.has_enabled() && (c.has_leaf() || c.has_leaf_x() || c.has_leaf_y() || c.has_leaf_z())) {
    v.enabled = true;
  }
  if (v.enabled && !(v.leaf_x > 0.0f && v.leaf_y > 0.0f && v.leaf_z > 0.0f)) {
    // Only possible when the server runs with --leaf 0 and the client sets only `enabled`.
    return Invalid(absl::StrCat(p,
                                ".enabled is true but the server has no default leaf (--leaf 0); "
                                "set ",
                                p, ".leaf"));
  }
  return absl::OkStatus();
}

absl::Status ResolveDraco(const v1::DracoConfig& c, const std::string& p, StreamSettings* s) {
  DracoOptions& d = s->draco;
  if (c.has_position_bits()) {
    if (auto st = CheckRange(p + ".position_bits", c.position_bits(), 1, 30); !st.ok()) return st;
    d.position_bits = c.position_bits();
  }
  if (c.has_color_bits()) {
    if (auto st = CheckRange(p + ".color_bits", c.color_bits(), 1, 8); !st.ok()) return st;
    d.color_bits = c.color_bits();
  }
  if (c.has_encode_speed()) {
    if (auto st = CheckRange(p + ".encode_speed", c.encode_speed(), 0, 10); !st.ok()) return st;
    d.encode_speed = c.encode_speed();
  }
  if (c.has_decode_speed()) {
    if (auto st = CheckRange(p + ".decode_speed", c.decode_speed(), 0, 10); !st.ok()) return st;
    d.decode_speed = c.decode_speed();
  }
  if (c.has_max_position_error()) {
    const float e = c.max_position_error();
    if (!std::isfinite(e) || e < 0.0f) {
      return Invalid(absl::StrCat(p, ".max_position_error must be finite and >= 0, got ", e));
    }
    d.max_position_error = e;
  } else {
    // A quarter of the smallest leaf keeps every decoded point inside its own voxel's quarter.
    d.max_position_error =
        s->voxel.enabled ? std::min({s->voxel.leaf_x, s->voxel.leaf_y, s->voxel.leaf_z}) / 4.0f
                         : 0.0f;
  }
  return absl::OkStatus();
}

}  // namespace

const char* Name(Delivery delivery) { return delivery == Delivery::kAll ? "all" : "latest"; }

bool ParseDelivery(const std::string& name, Delivery* out) {
  if (name == "latest") {
    *out = Delivery::kLatest;
    return true;
  }
  if (name == "all") {
    *out = Delivery::kAll;
    return true;
  }
  return false;
}

absl::Status ServerOptions::Validate() const {
  if (listen.empty()) return Invalid("--listen must not be empty");
  if (threads < 0 || threads > 1024) {
    return Invalid(absl::StrCat("--threads is ", threads, "; it must be in [0, 1024]"));
  }
  if (max_message_bytes < 1024 || max_message_bytes > (std::uint64_t{1} << 31) - 1) {
    // gRPC takes an int.
    return Invalid(absl::StrCat("--max-message-bytes is ", max_message_bytes,
                                "; it must be in [1024, 2^31 - 1]"));
  }
  if (limits.max_side == 0) return Invalid("--max-side must be at least 1");
  if (limits.max_pixels == 0 || limits.max_pixels > (std::uint64_t{1} << 24)) {
    // Beyond 2^24 pixels the core's per-voxel colour sums could overflow (core/limits.h).
    return Invalid(absl::StrCat("--max-pixels is ", limits.max_pixels,
                                "; it must be in [1, 2^24 = 16777216]"));
  }
  if (max_streams == 0) return Invalid("--max-streams must be at least 1");
  if (idle_timeout.count() <= 0) return Invalid("--idle-timeout must be positive");
  if (max_queued_frames == 0 || max_queued_frames > 1024) {
    return Invalid(
        absl::StrCat("--max-queued-frames is ", max_queued_frames, "; it must be in [1, 1024]"));
  }
  if (shutdown_grace.count() < 0) return Invalid("--shutdown-grace must not be negative");
  if (auto s = CheckPositive("--focal", defaults.focal); !s.ok()) return s;
  if (!std::isfinite(defaults.min) || !std::isfinite(defaults.max) || defaults.min > defaults.max) {
    return Invalid(absl::StrCat("--min (", defaults.min, ") and --max (", defaults.max,
                                ") must be finite with min <= max"));
  }
  if (defaults.leaf != 0.0f) {
    if (auto s = CheckLeaf("--leaf", defaults.leaf); !s.ok()) return s;
  }
  if (auto s = CheckRange("--draco-bits", defaults.draco_bits, 1, 30); !s.ok()) return s;
  if (auto s = CheckRange("--draco-speed", defaults.draco_speed, 0, 10); !s.ok()) return s;
  return absl::OkStatus();
}

int ServerOptions::ResolvedThreads() const {
  if (threads > 0) return threads;
  return std::max(1u, std::thread::hardware_concurrency());
}

PipelineOptions StreamSettings::ForFrame(std::uint32_t width, std::uint32_t height) const {
  PipelineOptions o;
  o.camera = camera;
  // Integer division on purpose: PCL puts the centre at static_cast<int>(width / 2).
  if (!has_cx) o.camera.cx = static_cast<double>(width / 2);   // NOLINT(bugprone-integer-division)
  if (!has_cy) o.camera.cy = static_cast<double>(height / 2);  // NOLINT(bugprone-integer-division)
  o.passthrough = passthrough;
  o.voxel = voxel;
  o.limits = limits;
  return o;
}

StreamSettings DefaultSettings(const ServerOptions& options) {
  const StageDefaults& d = options.defaults;
  StreamSettings s;
  s.camera = CameraModel::PclCompatible(640, 480, d.focal);  // cx, cy follow each frame
  s.passthrough.enabled = true;
  s.passthrough.axis = d.axis;
  s.passthrough.min = d.min;
  s.passthrough.max = d.max;
  s.voxel.enabled = d.leaf > 0.0f;
  s.voxel.SetLeaf(d.leaf > 0.0f ? d.leaf : 0.0f);
  s.draco.position_bits = d.draco_bits;
  s.draco.encode_speed = s.draco.decode_speed = d.draco_speed;
  s.draco.max_position_error = s.voxel.enabled ? d.leaf / 4.0f : 0.0f;
  s.delivery = d.delivery;
  s.limits = options.limits;
  return s;
}

absl::StatusOr<StreamSettings> ResolveStreamConfig(const v1::StreamConfig& config,
                                                   const ServerOptions& options,
                                                   const std::string& prefix) {
  StreamSettings s = DefaultSettings(options);
  if (config.has_camera()) {
    if (auto st = ResolveCamera(config.camera(), prefix + ".camera", &s); !st.ok()) return st;
  }
  if (auto st = ResolvePassThrough(config.passthrough(), prefix + ".passthrough", &s); !st.ok()) {
    return st;
  }
  if (auto st = ResolveVoxelGrid(config.voxel_grid(), prefix + ".voxel_grid", &s); !st.ok()) {
    return st;
  }
  // After the voxel grid: the default position error follows the leaf.
  if (auto st = ResolveDraco(config.draco(), prefix + ".draco", &s); !st.ok()) return st;
  switch (config.delivery()) {
    case v1::DELIVERY_UNSPECIFIED:
      break;
    case v1::DELIVERY_LATEST:
      s.delivery = Delivery::kLatest;
      break;
    case v1::DELIVERY_ALL:
      s.delivery = Delivery::kAll;
      break;
    default:
      return Invalid(absl::StrCat(prefix, ".delivery is ", static_cast<int>(config.delivery()),
                                  ", not one of DELIVERY_LATEST, DELIVERY_ALL"));
  }
  // The core's own checks, as a backstop: they must agree with the ones above.
  if (auto st = s.ForFrame(2, 2).Validate(); !st.ok()) {
    return Invalid(absl::StrCat(prefix, ": ", st.message()));
  }
  if (auto st = s.draco.Validate(); !st.ok()) {
    return Invalid(absl::StrCat(prefix, ": ", st.message()));
  }
  return s;
}

v1::StreamConfig DefaultStreamConfig(const ServerOptions& options) {
  const StreamSettings s = DefaultSettings(options);
  v1::StreamConfig c;
  v1::CameraModel* cam = c.mutable_camera();
  cam->set_fx(s.camera.fx);
  cam->set_fy(s.camera.fy);
  cam->set_baseline(s.camera.baseline);
  cam->set_disparity_scale(s.camera.disparity_scale);
  cam->set_disparity_offset(s.camera.disparity_offset);
  for (double v : s.camera.invalid_disparities) {
    cam->mutable_invalid_disparities()->add_values(v);
  }
  v1::PassThroughConfig* pt = c.mutable_passthrough();
  pt->set_enabled(s.passthrough.enabled);
  pt->set_axis(s.passthrough.axis == Axis::kX   ? v1::AXIS_X
               : s.passthrough.axis == Axis::kY ? v1::AXIS_Y
                                                : v1::AXIS_Z);
  pt->set_min(s.passthrough.min);
  pt->set_max(s.passthrough.max);
  pt->set_negative(s.passthrough.negative);
  v1::VoxelGridConfig* vg = c.mutable_voxel_grid();
  vg->set_enabled(s.voxel.enabled);
  vg->set_leaf(s.voxel.leaf_x);
  vg->set_leaf_x(s.voxel.leaf_x);
  vg->set_leaf_y(s.voxel.leaf_y);
  vg->set_leaf_z(s.voxel.leaf_z);
  vg->set_min_points_per_voxel(s.voxel.min_points_per_voxel);
  v1::DracoConfig* dc = c.mutable_draco();
  dc->set_position_bits(s.draco.position_bits);
  dc->set_color_bits(s.draco.color_bits);
  dc->set_encode_speed(s.draco.encode_speed);
  dc->set_decode_speed(s.draco.decode_speed);
  dc->set_max_position_error(s.draco.max_position_error);
  c.set_delivery(s.delivery == Delivery::kAll ? v1::DELIVERY_ALL : v1::DELIVERY_LATEST);
  return c;
}

std::string ServerOptions::ResolvedInstance() const {
  if (!instance.empty()) return instance;
  char host[256] = {};
  if (gethostname(host, sizeof host - 1) != 0 || host[0] == '\0') return "cloudcast";
  return host;
}

}  // namespace cloudcast::server
