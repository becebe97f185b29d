#include "cloudcast/proto/convert.h"

#include <algorithm>
#include <cctype>
#include <cstring>
#include <limits>
#include <string>

#include "absl/strings/cord.h"
#include "absl/strings/str_cat.h"
#include "cloudcast/core/checks.h"
#include "google/protobuf/any.pb.h"
#include "google/protobuf/io/coded_stream.h"
#include "google/protobuf/io/zero_copy_stream_impl_lite.h"
#include "google/protobuf/wire_format_lite.h"

namespace cloudcast::convert {
namespace {

// The protocol's 16- and 32-bit samples are little endian; raw rows are sent and viewed as they
// lie in memory, which is only right on a little-endian host.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__,
              "raw U16/F32 disparities are used as in memory; the protocol wants little endian");

// Only memory safety is checked where a client builds a frame, so that sizes and limits stay the
// server's one judgement.
constexpr Limits kNoLimits{std::numeric_limits<std::uint32_t>::max(),
                           std::numeric_limits<std::uint64_t>::max()};

std::string S(std::string_view v) { return std::string(v); }

// "config.camera" + "fx" -> "config.camera.fx".
std::string Path(std::string_view parent, std::string_view child) {
  return absl::StrCat(S(parent), ".", S(child));
}

// The name of an enum value, or its number when it has none (a client may send any number).
template <typename Enum>
std::string EnumName(const std::string& (*name)(Enum), Enum value) {
  const std::string& n = name(value);
  return n.empty() ? std::to_string(static_cast<int>(value)) : n;
}

absl::Status NotOneOf(std::string_view field, int value, std::string_view known) {
  return absl::InvalidArgumentError(
      absl::StrCat(S(field), " is ", value, ", not one of ", S(known)));
}

// ---------------------------------------------------------------------------------------------
// StreamConfig sections. Each checks a field as it reads it, with the core's check and the proto
// path, so that the message names what the client set.

absl::Status ResolveCamera(const v1::CameraModel& c, std::string_view p, FrameSettings* s) {
  CameraModel& cam = s->pipeline.camera;
  if (c.has_fx()) {
    if (auto st = check::Positive(Path(p, "fx"), c.fx()); !st.ok()) return st;
    cam.fx = c.fx();
    cam.fy = c.fx();  // fy follows fx unless set
    s->focal_given = true;
  }
  if (c.has_fy()) {
    if (auto st = check::Positive(Path(p, "fy"), c.fy()); !st.ok()) return st;
    if (!c.has_fx() && !s->focal_given) {
      return absl::InvalidArgumentError(
          absl::StrCat(Path(p, "fy"), " is set but ", Path(p, "fx"),
                       " is not: fx is required, fy only overrides it (it defaults to fx)"));
    }
    cam.fy = c.fy();
  }
  if (c.has_cx()) {
    if (auto st = check::Finite(Path(p, "cx"), c.cx()); !st.ok()) return st;
    s->cx = c.cx();
  }
  if (c.has_cy()) {
    if (auto st = check::Finite(Path(p, "cy"), c.cy()); !st.ok()) return st;
    s->cy = c.cy();
  }
  if (c.has_baseline()) {
    if (auto st = check::Positive(Path(p, "baseline"), c.baseline()); !st.ok()) return st;
    cam.baseline = c.baseline();
    s->baseline_given = true;
  }
  if (c.has_disparity_scale()) {
    if (auto st = check::NonZero(Path(p, "disparity_scale"), c.disparity_scale()); !st.ok()) {
      return st;
    }
    cam.disparity_scale = c.disparity_scale();
  }
  if (c.has_disparity_offset()) {
    if (auto st = check::Finite(Path(p, "disparity_offset"), c.disparity_offset()); !st.ok()) {
      return st;
    }
    cam.disparity_offset = c.disparity_offset();
  }
  if (c.has_invalid_disparities()) {
    const auto& values = c.invalid_disparities().values();
    const std::string field = Path(p, "invalid_disparities.values");
    if (auto st = check::AtMost(field, values.size(), kMaxInvalidDisparities); !st.ok()) {
      return st;
    }
    for (int i = 0; i < values.size(); ++i) {
      if (!std::isfinite(values[i])) {
        return absl::InvalidArgumentError(
            absl::StrCat(field, "[", i, "] must be finite, got ", values[i]));
      }
    }
    cam.invalid_disparities.assign(values.begin(), values.end());
  }
  if (c.has_depth_scale()) {
    if (auto st = check::Positive(Path(p, "depth_scale"), c.depth_scale()); !st.ok()) return st;
    cam.depth_scale = c.depth_scale();
  }
  return absl::OkStatus();
}

absl::Status ResolvePassThrough(const v1::PassThroughConfig& c, std::string_view p,
                                FrameSettings* s) {
  PassThroughParams& pt = s->pipeline.passthrough;
  if (c.has_enabled()) pt.enabled = c.enabled();
  // A client that gives a limit (and says nothing of `enabled`) wants the range applied, also on
  // a server whose default is no passthrough.
  if (!c.has_enabled() && (c.has_min() || c.has_max())) pt.enabled = true;
  if (auto st = FromProto(c.axis(), Path(p, "axis"), &pt.axis); !st.ok()) return st;
  if (c.has_min()) {
    if (auto st = check::FiniteFloat(Path(p, "min"), c.min()); !st.ok()) return st;
    pt.min = c.min();
  }
  if (c.has_max()) {
    if (auto st = check::FiniteFloat(Path(p, "max"), c.max()); !st.ok()) return st;
    pt.max = c.max();
  }
  if (auto st = check::Ordered(Path(p, "min"), pt.min, Path(p, "max"), pt.max,
                               c.has_min() ? "" : "the server default",
                               c.has_max() ? "" : "the server default");
      !st.ok()) {
    return st;
  }
  if (c.has_negative()) pt.negative = c.negative();
  return absl::OkStatus();
}

absl::Status ResolveVoxelGrid(const v1::VoxelGridConfig& c, std::string_view p, FrameSettings* s) {
  VoxelGridParams& v = s->pipeline.voxel;
  if (c.has_enabled()) v.enabled = c.enabled();
  if (c.has_leaf()) {
    if (auto st = check::Leaf(Path(p, "leaf"), c.leaf()); !st.ok()) return st;
    v.SetLeaf(c.leaf());
  }
  struct Axis {
    bool has;
    float value;
    const char* name;
    float* out;
  };
  for (const Axis& a : {Axis{c.has_leaf_x(), c.leaf_x(), "leaf_x", &v.leaf_x},
                        Axis{c.has_leaf_y(), c.leaf_y(), "leaf_y", &v.leaf_y},
                        Axis{c.has_leaf_z(), c.leaf_z(), "leaf_z", &v.leaf_z}}) {
    if (!a.has) continue;
    if (auto st = check::Leaf(Path(p, a.name), a.value); !st.ok()) return st;
    *a.out = a.value;
  }
  if (c.has_min_points_per_voxel()) v.min_points_per_voxel = c.min_points_per_voxel();
  // A server run with --leaf 0 has the grid off by default; a client that asks for a leaf (and
  // says nothing of `enabled`) wants it on.
  if (!c.has_enabled() && (c.has_leaf() || c.has_leaf_x() || c.has_leaf_y() || c.has_leaf_z())) {
    v.enabled = true;
  }
  if (v.enabled && !(v.leaf_x > 0.0f && v.leaf_y > 0.0f && v.leaf_z > 0.0f)) {
    // Only possible when the server runs with --leaf 0 and the client sets only `enabled`.
    return absl::InvalidArgumentError(absl::StrCat(
        Path(p, "enabled"), " is true but the server has no default leaf (--leaf 0); set ",
        Path(p, "leaf")));
  }
  return absl::OkStatus();
}

absl::Status ResolveDraco(const v1::DracoConfig& c, std::string_view p, FrameSettings* s) {
  // The proto's Draco fields are named as DracoOptions' members, so the core's own check names
  // them right under the proto path.
  DracoOptions& d = s->draco;
  if (c.has_position_bits()) d.position_bits = c.position_bits();
  if (c.has_color_bits()) d.color_bits = c.color_bits();
  if (c.has_encode_speed()) d.encode_speed = c.encode_speed();
  if (c.has_decode_speed()) d.decode_speed = c.decode_speed();
  if (c.has_max_cloud_bytes()) d.max_cloud_bytes = c.max_cloud_bytes();
  if (c.has_min_color_bits()) d.min_color_bits = c.min_color_bits();
  if (c.has_cap_min_points_per_voxel()) {
    s->cap_min_points_per_voxel = c.cap_min_points_per_voxel();
    if (auto st = FrameSettings::ValidateCapMinPoints(s->cap_min_points_per_voxel,
                                                      Path(p, "cap_min_points_per_voxel"));
        !st.ok()) {
      return st;
    }
  }
  if (c.has_max_position_error()) {
    d.max_position_error = c.max_position_error();
    s->max_position_error = c.max_position_error();
  }
  return d.Validate(p);
}

absl::Status ResolveCalibration(const v1::StereoCalibration& c, std::string_view p,
                                StereoCalibration* out) {
  auto matrix = [&](const google::protobuf::RepeatedField<double>& values, std::string_view name,
                    std::size_t n, double* to) -> absl::Status {
    if (static_cast<std::size_t>(values.size()) != n) {
      return absl::InvalidArgumentError(
          absl::StrCat(Path(p, name), " has ", values.size(), " values; it must have ", n));
    }
    for (std::size_t i = 0; i < n; ++i) to[i] = values[static_cast<int>(i)];
    return absl::OkStatus();
  };
  out->width = c.width();
  out->height = c.height();
  for (absl::Status st :
       {matrix(c.left_k(), "left_k", 9, out->left_k.data()),
        matrix(c.right_k(), "right_k", 9, out->right_k.data()),
        matrix(c.r(), "r", 9, out->r.data()), matrix(c.t(), "t", 3, out->t.data())}) {
    if (!st.ok()) return st;
  }
  out->left_d.assign(c.left_d().begin(), c.left_d().end());
  out->right_d.assign(c.right_d().begin(), c.right_d().end());
  return out->Validate(p);
}

absl::Status ResolveStereo(const v1::StereoConfig& c, std::string_view p, FrameSettings* s) {
  // The proto's fields are named as StereoParams' members, so its Validate names them right
  // under the proto path.
  StereoParams& st = s->stereo;
  if (auto e = FromProto(c.matcher(), Path(p, "matcher"), &st.matcher); !e.ok()) return e;
  if (c.has_min_disparity()) st.min_disparity = c.min_disparity();
  if (c.has_num_disparities()) st.num_disparities = c.num_disparities();
  if (c.has_block_size()) st.block_size = c.block_size();
  if (c.has_p1()) st.p1 = c.p1();
  if (c.has_p2()) st.p2 = c.p2();
  if (c.has_uniqueness_ratio()) st.uniqueness_ratio = c.uniqueness_ratio();
  if (c.has_speckle_window_size()) st.speckle_window_size = c.speckle_window_size();
  if (c.has_speckle_range()) st.speckle_range = c.speckle_range();
  if (c.has_disp12_max_diff()) st.disp12_max_diff = c.disp12_max_diff();
  if (c.has_paths()) st.paths = c.paths();
  if (c.has_return_disparity()) st.return_disparity = c.return_disparity();
  if (c.has_calibration()) {
    if (auto e = ResolveCalibration(c.calibration(), Path(p, "calibration"), &st.calibration);
        !e.ok()) {
      return e;
    }
    st.has_calibration = true;
  }
  StereoParams checked = st;
  checked.has_calibration = false;  // checked above, naming its own fields
  return checked.Validate(p);
}

template <typename View, typename Raw, typename Encoding>
absl::Status ViewAny(const Raw& raw, std::string_view pixels, std::string_view field,
                     const Limits& limits, Encoding encoding, const std::string& encoding_name,
                     View* view) {
  const std::uint64_t row_bytes = std::uint64_t{raw.width()} * BytesPerPixel(encoding);
  view->data = pixels.data();
  view->size_bytes = pixels.size();
  view->rows = nullptr;
  view->width = raw.width();
  view->height = raw.height();
  view->stride_bytes = raw.row_stride() == 0 ? row_bytes : raw.row_stride();
  view->encoding = encoding;
  return ValidateView(*view, limits, field, {"row_stride", "pixels", encoding_name});
}

}  // namespace

// ---------------------------------------------------------------------------------------------

std::string_view Name(Delivery delivery) { return delivery == Delivery::kAll ? "all" : "latest"; }

bool ParseDelivery(std::string_view name, Delivery* out) {
  for (Delivery d : {Delivery::kLatest, Delivery::kAll}) {
    if (Name(d) == name) {
      *out = d;
      return true;
    }
  }
  return false;
}

v1::Axis ToProto(Axis axis) {
  switch (axis) {
    case Axis::kX:
      return v1::AXIS_X;
    case Axis::kY:
      return v1::AXIS_Y;
    case Axis::kZ:
      return v1::AXIS_Z;
  }
  return v1::AXIS_UNSPECIFIED;
}

v1::DisparityEncoding ToProto(DisparityEncoding encoding) {
  switch (encoding) {
    case DisparityEncoding::kU8:
      return v1::DISPARITY_U8;
    case DisparityEncoding::kU16:
      return v1::DISPARITY_U16;
    case DisparityEncoding::kF32:
      return v1::DISPARITY_F32;
  }
  return v1::DISPARITY_ENCODING_UNSPECIFIED;
}

v1::DepthEncoding ToProto(DepthEncoding encoding) {
  switch (encoding) {
    case DepthEncoding::kU16:
      return v1::DEPTH_U16;
    case DepthEncoding::kF32:
      return v1::DEPTH_F32;
  }
  return v1::DEPTH_ENCODING_UNSPECIFIED;
}

v1::StereoMatcher ToProto(StereoMatcher matcher) {
  switch (matcher) {
    case StereoMatcher::kSgm:
      return v1::STEREO_MATCHER_SGM;
    case StereoMatcher::kOpenCvSgbm:
      return v1::STEREO_MATCHER_OPENCV_SGBM;
    case StereoMatcher::kOpenCvSgbm3Way:
      return v1::STEREO_MATCHER_OPENCV_SGBM_3WAY;
    case StereoMatcher::kOpenCvHH:
      return v1::STEREO_MATCHER_OPENCV_HH;
    case StereoMatcher::kOpenCvBm:
      return v1::STEREO_MATCHER_OPENCV_BM;
  }
  return v1::STEREO_MATCHER_UNSPECIFIED;
}

absl::Status FromProto(v1::StereoMatcher matcher, std::string_view field, StereoMatcher* out) {
  switch (matcher) {
    case v1::STEREO_MATCHER_UNSPECIFIED:
      return absl::OkStatus();
    case v1::STEREO_MATCHER_SGM:
      *out = StereoMatcher::kSgm;
      return absl::OkStatus();
    case v1::STEREO_MATCHER_OPENCV_SGBM:
      *out = StereoMatcher::kOpenCvSgbm;
      return absl::OkStatus();
    case v1::STEREO_MATCHER_OPENCV_SGBM_3WAY:
      *out = StereoMatcher::kOpenCvSgbm3Way;
      return absl::OkStatus();
    case v1::STEREO_MATCHER_OPENCV_HH:
      *out = StereoMatcher::kOpenCvHH;
      return absl::OkStatus();
    case v1::STEREO_MATCHER_OPENCV_BM:
      *out = StereoMatcher::kOpenCvBm;
      return absl::OkStatus();
    default:
      return NotOneOf(field, matcher,
                      "STEREO_MATCHER_SGM, STEREO_MATCHER_OPENCV_SGBM, "
                      "STEREO_MATCHER_OPENCV_SGBM_3WAY, STEREO_MATCHER_OPENCV_HH, "
                      "STEREO_MATCHER_OPENCV_BM");
  }
}

absl::Status FromProto(v1::DepthEncoding encoding, std::string_view field, DepthEncoding* out) {
  switch (encoding) {
    case v1::DEPTH_U16:
      *out = DepthEncoding::kU16;
      return absl::OkStatus();
    case v1::DEPTH_F32:
      *out = DepthEncoding::kF32;
      return absl::OkStatus();
    default:
      return absl::InvalidArgumentError(absl::StrCat(S(field), " is ",
                                                     EnumName(&v1::DepthEncoding_Name, encoding),
                                                     "; it must be one of DEPTH_U16, DEPTH_F32"));
  }
}

v1::ColorEncoding ToProto(ColorEncoding encoding) {
  switch (encoding) {
    case ColorEncoding::kBGR8:
      return v1::COLOR_BGR8;
    case ColorEncoding::kRGB8:
      return v1::COLOR_RGB8;
    case ColorEncoding::kRGBA8:
      return v1::COLOR_RGBA8;
    case ColorEncoding::kMono8:
      return v1::COLOR_MONO8;
  }
  return v1::COLOR_ENCODING_UNSPECIFIED;
}

v1::DeliveryMode ToProto(Delivery delivery) {
  return delivery == Delivery::kAll ? v1::DELIVERY_ALL : v1::DELIVERY_LATEST;
}

absl::Status FromProto(v1::Axis axis, std::string_view field, Axis* out) {
  switch (axis) {
    case v1::AXIS_UNSPECIFIED:
      return absl::OkStatus();
    case v1::AXIS_X:
      *out = Axis::kX;
      return absl::OkStatus();
    case v1::AXIS_Y:
      *out = Axis::kY;
      return absl::OkStatus();
    case v1::AXIS_Z:
      *out = Axis::kZ;
      return absl::OkStatus();
    default:
      return NotOneOf(field, axis, "AXIS_X, AXIS_Y, AXIS_Z");
  }
}

absl::Status FromProto(v1::DeliveryMode mode, std::string_view field, Delivery* out) {
  switch (mode) {
    case v1::DELIVERY_UNSPECIFIED:
      return absl::OkStatus();
    case v1::DELIVERY_LATEST:
      *out = Delivery::kLatest;
      return absl::OkStatus();
    case v1::DELIVERY_ALL:
      *out = Delivery::kAll;
      return absl::OkStatus();
    default:
      return NotOneOf(field, mode, "DELIVERY_LATEST, DELIVERY_ALL");
  }
}

absl::Status FromProto(v1::DisparityEncoding encoding, std::string_view field,
                       DisparityEncoding* out) {
  switch (encoding) {
    case v1::DISPARITY_U8:
      *out = DisparityEncoding::kU8;
      return absl::OkStatus();
    case v1::DISPARITY_U16:
      *out = DisparityEncoding::kU16;
      return absl::OkStatus();
    case v1::DISPARITY_F32:
      *out = DisparityEncoding::kF32;
      return absl::OkStatus();
    default:
      return absl::InvalidArgumentError(
          absl::StrCat(S(field), " is ", EnumName(&v1::DisparityEncoding_Name, encoding),
                       "; it must be one of DISPARITY_U8, DISPARITY_U16, DISPARITY_F32"));
  }
}

absl::Status FromProto(v1::ColorEncoding encoding, std::string_view field, ColorEncoding* out) {
  switch (encoding) {
    case v1::COLOR_BGR8:
      *out = ColorEncoding::kBGR8;
      return absl::OkStatus();
    case v1::COLOR_RGB8:
      *out = ColorEncoding::kRGB8;
      return absl::OkStatus();
    case v1::COLOR_RGBA8:
      *out = ColorEncoding::kRGBA8;
      return absl::OkStatus();
    case v1::COLOR_MONO8:
      *out = ColorEncoding::kMono8;
      return absl::OkStatus();
    default:
      return absl::InvalidArgumentError(
          absl::StrCat(S(field), " is ", EnumName(&v1::ColorEncoding_Name, encoding),
                       "; it must be one of COLOR_BGR8, COLOR_RGB8, COLOR_RGBA8, COLOR_MONO8"));
  }
}

// ---------------------------------------------------------------------------------------------

StreamSettings ContractDefaults() {
  StreamSettings s;
  s.frame.focal_given = false;
  s.frame.baseline_given = false;
  PassThroughParams& pt = s.frame.pipeline.passthrough;
  pt.enabled = false;
  pt.axis = Axis::kZ;
  pt.min = std::numeric_limits<float>::lowest();
  pt.max = std::numeric_limits<float>::max();
  pt.negative = false;
  return s;
}

absl::Status ApplyCamera(const v1::CameraModel& camera, std::string_view field,
                         FrameSettings* settings) {
  return ResolveCamera(camera, field, settings);
}

absl::Status RequireCamera(const FrameSettings& settings, v1::Frame::GeometryCase geometry,
                           std::string_view field) {
  const char* kind = geometry == v1::Frame::kDepth       ? "a depth frame"
                     : geometry == v1::Frame::kDisparity ? "a disparity frame"
                                                         : "a stereo pair";
  if (!settings.focal_given) {
    if (geometry == v1::Frame::kRight && settings.stereo.has_calibration) return absl::OkStatus();
    return RequiredError(
        Path(field, "fx"),
        absl::StrCat(Path(field, "fx"), " is not set and ", kind,
                     " needs the camera's focal length in pixels: set StreamConfig.camera (or "
                     "Frame.camera) fx, fy, cx, cy, or use a preset (cloudcast-client "
                     "--camera-preset new_tsukuba); this server has no default camera"));
  }
  if (!settings.baseline_given && geometry != v1::Frame::kDepth &&
      !(geometry == v1::Frame::kRight && settings.stereo.has_calibration)) {
    return RequiredError(
        Path(field, "baseline"),
        absl::StrCat(Path(field, "baseline"), " is not set and ", kind,
                     " needs the stereo baseline (z = fx * baseline / disparity, in the unit "
                     "wanted for x, y and z); this server has no default baseline"));
  }
  return absl::OkStatus();
}

absl::StatusOr<StreamSettings> Resolve(const v1::StreamConfig& config,
                                       const StreamSettings& defaults, std::string_view field) {
  StreamSettings s = defaults;
  if (config.has_camera()) {
    if (auto st = ResolveCamera(config.camera(), Path(field, "camera"), &s.frame); !st.ok()) {
      return st;
    }
  }
  if (auto st = ResolvePassThrough(config.passthrough(), Path(field, "passthrough"), &s.frame);
      !st.ok()) {
    return st;
  }
  if (auto st = ResolveVoxelGrid(config.voxel_grid(), Path(field, "voxel_grid"), &s.frame);
      !st.ok()) {
    return st;
  }
  if (auto st = ResolveDraco(config.draco(), Path(field, "draco"), &s.frame); !st.ok()) return st;
  if (auto st = ResolveStereo(config.stereo(), Path(field, "stereo"), &s.frame); !st.ok()) {
    return st;
  }
  if (auto st = FromProto(config.delivery(), Path(field, "delivery"), &s.delivery); !st.ok()) {
    return st;
  }
  return s;
}

v1::StreamConfig ToProto(const StreamSettings& settings) {
  const FrameSettings& f = settings.frame;
  v1::StreamConfig c;
  SetCamera(f.pipeline.camera, &c);
  // No default camera unless the operator gave one: a client must send its own.
  if (!f.focal_given) {
    c.mutable_camera()->clear_fx();
    c.mutable_camera()->clear_fy();
  }
  if (!f.baseline_given) c.mutable_camera()->clear_baseline();
  if (f.cx.has_value()) {
    c.mutable_camera()->set_cx(*f.cx);
  } else {
    c.mutable_camera()->clear_cx();
  }
  if (f.cy.has_value()) {
    c.mutable_camera()->set_cy(*f.cy);
  } else {
    c.mutable_camera()->clear_cy();
  }
  SetPassThrough(f.pipeline.passthrough, &c);
  SetVoxelGrid(f.pipeline.voxel, &c);
  const VoxelGridParams& v = f.pipeline.voxel;
  if (v.leaf_x == v.leaf_y && v.leaf_y == v.leaf_z) c.mutable_voxel_grid()->set_leaf(v.leaf_x);
  // The error bound as it applies with these settings' leaf (GetInfo shows what a client gets).
  SetDraco(f.Draco(), &c);
  c.mutable_draco()->set_max_position_error(f.Draco().max_position_error);
  c.mutable_draco()->set_cap_min_points_per_voxel(f.cap_min_points_per_voxel);
  c.set_delivery(ToProto(settings.delivery));
  SetStereo(f.stereo, &c);
  return c;
}

void SetCamera(const CameraModel& camera, v1::StreamConfig* config) {
  v1::CameraModel* c = config->mutable_camera();
  c->set_fx(camera.fx);
  c->set_fy(camera.fy);
  c->set_cx(camera.cx);
  c->set_cy(camera.cy);
  c->set_baseline(camera.baseline);
  c->set_disparity_scale(camera.disparity_scale);
  c->set_disparity_offset(camera.disparity_offset);
  // Set even when empty: an empty list means "no invalid values", unlike an absent one.
  v1::InvalidDisparities* invalid = c->mutable_invalid_disparities();
  invalid->clear_values();
  for (double v : camera.invalid_disparities) invalid->add_values(v);
  if (camera.depth_scale.has_value()) {
    c->set_depth_scale(*camera.depth_scale);
  } else {
    c->clear_depth_scale();
  }
}

void SetStereo(const StereoParams& params, v1::StreamConfig* config) {
  v1::StereoConfig* c = config->mutable_stereo();
  c->set_matcher(ToProto(params.matcher));
  c->set_min_disparity(params.min_disparity);
  c->set_num_disparities(params.num_disparities);
  c->set_block_size(params.block_size);
  c->set_p1(params.p1);
  c->set_p2(params.p2);
  c->set_uniqueness_ratio(params.uniqueness_ratio);
  c->set_speckle_window_size(params.speckle_window_size);
  c->set_speckle_range(params.speckle_range);
  c->set_disp12_max_diff(params.disp12_max_diff);
  c->set_paths(params.paths);
  c->set_return_disparity(params.return_disparity);
  c->clear_calibration();
  if (!params.has_calibration) return;
  const StereoCalibration& k = params.calibration;
  v1::StereoCalibration* out = c->mutable_calibration();
  out->set_width(k.width);
  out->set_height(k.height);
  for (double v : k.left_k) out->add_left_k(v);
  for (double v : k.left_d) out->add_left_d(v);
  for (double v : k.right_k) out->add_right_k(v);
  for (double v : k.right_d) out->add_right_d(v);
  for (double v : k.r) out->add_r(v);
  for (double v : k.t) out->add_t(v);
}

void SetPassThrough(const PassThroughParams& params, v1::StreamConfig* config) {
  v1::PassThroughConfig* p = config->mutable_passthrough();
  p->set_enabled(params.enabled);
  p->set_axis(ToProto(params.axis));
  p->set_min(params.min);
  p->set_max(params.max);
  p->set_negative(params.negative);
}

void SetVoxelGrid(const VoxelGridParams& params, v1::StreamConfig* config) {
  v1::VoxelGridConfig* v = config->mutable_voxel_grid();
  v->set_enabled(params.enabled);
  v->clear_leaf();
  v->set_leaf_x(params.leaf_x);
  v->set_leaf_y(params.leaf_y);
  v->set_leaf_z(params.leaf_z);
  v->set_min_points_per_voxel(params.min_points_per_voxel);
}

void SetDraco(const DracoOptions& options, v1::StreamConfig* config) {
  v1::DracoConfig* d = config->mutable_draco();
  d->set_position_bits(options.position_bits);
  d->set_color_bits(options.color_bits);
  d->set_encode_speed(options.encode_speed);
  d->set_decode_speed(options.decode_speed);
  d->set_max_cloud_bytes(options.max_cloud_bytes);
  d->set_min_color_bits(options.min_color_bits);
  if (options.max_position_error > 0) {
    d->set_max_position_error(options.max_position_error);
  } else {
    d->clear_max_position_error();
  }
}

absl::StatusOr<v1::StreamConfig> PresetConfig(std::string_view name, std::string_view field) {
  FrameSettings settings;
  if (absl::Status s = ApplyPreset(name, &settings, field); !s.ok()) return s;
  v1::StreamConfig config;
  SetCamera(settings.pipeline.camera, &config);
  config.mutable_camera()->clear_cx();
  config.mutable_camera()->clear_cy();
  SetPassThrough(settings.pipeline.passthrough, &config);
  return config;
}

v1::StreamConfig MakeStreamConfig(const PipelineOptions& options) {
  v1::StreamConfig config;
  SetCamera(options.camera, &config);
  SetPassThrough(options.passthrough, &config);
  SetVoxelGrid(options.voxel, &config);
  return config;
}

// ---------------------------------------------------------------------------------------------

namespace {

template <typename View>
std::size_t PackedSize(const View& view) {
  return std::size_t{view.width} * BytesPerPixel(view.encoding) * view.height;
}

// Copies the view's rows to `dst`, packed.
template <typename View>
void CopyRows(const View& view, void* dst) {
  const std::size_t row_bytes = std::size_t{view.width} * BytesPerPixel(view.encoding);
  auto* out = static_cast<char*>(dst);
  if (view.rows == nullptr && view.stride_bytes == row_bytes) {
    std::memcpy(out, view.data, row_bytes * view.height);
    return;
  }
  for (std::uint32_t v = 0; v < view.height; ++v) {
    std::memcpy(out + v * row_bytes, view.row(v), row_bytes);
  }
}

template <typename View, typename Raw>
absl::Status FillRawHeader(const View& view, std::string_view field, Raw* raw) {
  if (absl::Status s = ValidateView(view, kNoLimits, field); !s.ok()) return s;
  raw->set_encoding(ToProto(view.encoding));
  raw->set_width(view.width);
  raw->set_height(view.height);
  raw->set_row_stride(0);
  return absl::OkStatus();
}

template <typename View, typename Raw>
absl::Status FillRaw(const View& view, std::string_view field, Raw* raw) {
  if (absl::Status s = FillRawHeader(view, field, raw); !s.ok()) return s;
  // Same-size frames keep the size, so resize() neither allocates nor zero-fills after the first.
  raw->mutable_pixels()->resize(PackedSize(view));
  CopyRows(view, raw->mutable_pixels()->data());
  return absl::OkStatus();
}

}  // namespace

absl::Status ToProto(const DisparityView& view, std::string_view field, v1::RawDisparity* raw) {
  return FillRaw(view, field, raw);
}

absl::Status ToProto(const DepthView& view, std::string_view field, v1::RawDepth* raw) {
  return FillRaw(view, field, raw);
}

absl::Status ToProto(const ColorView& view, std::string_view field, v1::RawColor* raw) {
  return FillRaw(view, field, raw);
}

absl::Status ToProtoWithoutPixels(const DisparityView& view, std::string_view field,
                                  v1::RawDisparity* raw) {
  raw->clear_pixels();
  return FillRawHeader(view, field, raw);
}

absl::Status ToProtoWithoutPixels(const DepthView& view, std::string_view field,
                                  v1::RawDepth* raw) {
  raw->clear_pixels();
  return FillRawHeader(view, field, raw);
}

absl::Status ToProtoWithoutPixels(const ColorView& view, std::string_view field,
                                  v1::RawColor* raw) {
  raw->clear_pixels();
  return FillRawHeader(view, field, raw);
}

std::size_t PackedBytes(const DisparityView& view) { return PackedSize(view); }
std::size_t PackedBytes(const DepthView& view) { return PackedSize(view); }
std::size_t PackedBytes(const ColorView& view) { return PackedSize(view); }
void PackRows(const DisparityView& view, void* out) { CopyRows(view, out); }
void PackRows(const DepthView& view, void* out) { CopyRows(view, out); }
void PackRows(const ColorView& view, void* out) { CopyRows(view, out); }

absl::Status BgraToProto(const void* data, std::size_t size_bytes, std::uint32_t width,
                         std::uint32_t height, std::size_t stride_bytes, std::string_view field,
                         v1::RawColor* raw) {
  // The same memory checks as any four-byte-per-pixel view.
  ColorView as_rgba{data, size_bytes, width, height, stride_bytes, ColorEncoding::kRGBA8};
  if (absl::Status s = ValidateView(as_rgba, kNoLimits, field, {"stride_bytes", "data", "bgra8"});
      !s.ok()) {
    return s;
  }
  raw->set_encoding(v1::COLOR_BGR8);
  raw->set_width(width);
  raw->set_height(height);
  raw->set_row_stride(0);
  std::string* out = raw->mutable_pixels();
  out->resize(std::size_t{width} * 3 * height);
  auto* dst = reinterpret_cast<std::uint8_t*>(out->data());
  for (std::uint32_t v = 0; v < height; ++v) {
    const auto* src = static_cast<const std::uint8_t*>(data) + v * stride_bytes;
    for (std::uint32_t u = 0; u < width; ++u, src += 4, dst += 3) {
      dst[0] = src[0];
      dst[1] = src[1];
      dst[2] = src[2];
    }
  }
  return absl::OkStatus();
}

absl::Status ViewRaw(const v1::RawDisparity& raw, std::string_view pixels, std::string_view field,
                     const Limits& limits, DisparityView* view) {
  DisparityEncoding encoding;
  if (auto s = FromProto(raw.encoding(), Path(field, "encoding"), &encoding); !s.ok()) return s;
  return ViewAny(raw, pixels, field, limits, encoding, v1::DisparityEncoding_Name(raw.encoding()),
                 view);
}

absl::Status ViewRaw(const v1::RawDepth& raw, std::string_view pixels, std::string_view field,
                     const Limits& limits, DepthView* view) {
  DepthEncoding encoding;
  if (auto s = FromProto(raw.encoding(), Path(field, "encoding"), &encoding); !s.ok()) return s;
  return ViewAny(raw, pixels, field, limits, encoding, v1::DepthEncoding_Name(raw.encoding()),
                 view);
}

absl::Status ViewRaw(const v1::RawColor& raw, std::string_view pixels, std::string_view field,
                     const Limits& limits, ColorView* view) {
  ColorEncoding encoding;
  if (auto s = FromProto(raw.encoding(), Path(field, "encoding"), &encoding); !s.ok()) return s;
  return ViewAny(raw, pixels, field, limits, encoding, v1::ColorEncoding_Name(raw.encoding()),
                 view);
}

absl::Status ViewRaw(const v1::RawDisparity& raw, std::string_view field, const Limits& limits,
                     DisparityView* view) {
  return ViewRaw(raw, raw.pixels(), field, limits, view);
}

absl::Status ViewRaw(const v1::RawDepth& raw, std::string_view field, const Limits& limits,
                     DepthView* view) {
  return ViewRaw(raw, raw.pixels(), field, limits, view);
}

absl::Status ViewRaw(const v1::RawColor& raw, std::string_view field, const Limits& limits,
                     ColorView* view) {
  return ViewRaw(raw, raw.pixels(), field, limits, view);
}

// ---------------------------------------------------------------------------------------------

absl::Status FromProto(v1::Compression compression, std::string_view field, Predictor* out) {
  switch (compression) {
    case v1::COMPRESSION_ZSTD:
      *out = Predictor::kNone;
      return absl::OkStatus();
    case v1::COMPRESSION_ZSTD_DELTA_ROWS:
      *out = Predictor::kUp;
      return absl::OkStatus();
    case v1::COMPRESSION_ZSTD_DELTA_LEFT:
      *out = Predictor::kLeft;
      return absl::OkStatus();
    default:
      return absl::InvalidArgumentError(
          absl::StrCat(S(field), " is ", EnumName(&v1::Compression_Name, compression),
                       "; it must be one of COMPRESSION_ZSTD, COMPRESSION_ZSTD_DELTA_ROWS, "
                       "COMPRESSION_ZSTD_DELTA_LEFT"));
  }
}

const std::vector<v1::Compression>& AcceptedCompressions() {
  static const std::vector<v1::Compression> accepted = {
      v1::COMPRESSION_ZSTD, v1::COMPRESSION_ZSTD_DELTA_ROWS, v1::COMPRESSION_ZSTD_DELTA_LEFT};
  return accepted;
}

namespace {

PlaneCompressor* ThreadCompressor() {
  thread_local PlaneCompressor compressor;
  return &compressor;
}

template <typename View, typename Compressed>
absl::Status CompressAny(const View& view, const Compression& compression, std::string_view field,
                         Compressed* out, PlaneCompressor* compressor) {
  Predictor predictor;
  if (auto s = FromProto(compression.codec, Path(field, "compression"), &predictor); !s.ok()) {
    return s;
  }
  if (compressor == nullptr) compressor = ThreadCompressor();
  if (auto s =
          compressor->Compress(view, predictor, compression.level, field, out->mutable_payload());
      !s.ok()) {
    return s;
  }
  out->set_encoding(ToProto(view.encoding));
  out->set_width(view.width);
  out->set_height(view.height);
  out->set_compression(compression.codec);
  return absl::OkStatus();
}

template <typename Compressed, typename Encoding, typename View>
absl::Status DecodeAny(const Compressed& c, std::string_view field, const Limits& limits,
                       Encoding encoding, const std::string& encoding_name,
                       PlaneDecompressor* decompressor, View* view) {
  Predictor predictor;
  if (auto s = FromProto(c.compression(), Path(field, "compression"), &predictor); !s.ok()) {
    return s;
  }
  if (auto s = check::ImageSize(field, c.width(), c.height(), limits); !s.ok()) return s;
  const PlaneLayout layout = LayoutOf(encoding, c.width(), c.height());
  const std::uint8_t* pixels = nullptr;
  if (auto s = decompressor->Decompress(
          c.payload(), layout, predictor, Path(field, "payload"),
          absl::StrCat(c.width(), "x", c.height(), " ", encoding_name), &pixels);
      !s.ok()) {
    return s;
  }
  view->data = pixels;
  view->size_bytes = layout.bytes();
  view->width = c.width();
  view->height = c.height();
  view->stride_bytes = std::size_t{c.width()} * layout.bpp;
  view->encoding = encoding;
  return absl::OkStatus();
}

}  // namespace

absl::Status ToProto(const DisparityView& view, const Compression& compression,
                     std::string_view field, v1::CompressedDisparity* out,
                     PlaneCompressor* compressor) {
  return CompressAny(view, compression, field, out, compressor);
}

absl::Status ToProto(const DepthView& view, const Compression& compression, std::string_view field,
                     v1::CompressedDepth* out, PlaneCompressor* compressor) {
  return CompressAny(view, compression, field, out, compressor);
}

absl::Status ToProto(const ColorView& view, const Compression& compression, std::string_view field,
                     v1::CompressedColor* out, PlaneCompressor* compressor) {
  return CompressAny(view, compression, field, out, compressor);
}

absl::Status DecodeCompressed(const v1::CompressedDisparity& compressed, std::string_view field,
                              const Limits& limits, PlaneDecompressor* decompressor,
                              DisparityView* view) {
  DisparityEncoding encoding;
  if (auto s = FromProto(compressed.encoding(), Path(field, "encoding"), &encoding); !s.ok()) {
    return s;
  }
  return DecodeAny(compressed, field, limits, encoding,
                   v1::DisparityEncoding_Name(compressed.encoding()), decompressor, view);
}

absl::Status DecodeCompressed(const v1::CompressedDepth& compressed, std::string_view field,
                              const Limits& limits, PlaneDecompressor* decompressor,
                              DepthView* view) {
  DepthEncoding encoding;
  if (auto s = FromProto(compressed.encoding(), Path(field, "encoding"), &encoding); !s.ok()) {
    return s;
  }
  return DecodeAny(compressed, field, limits, encoding,
                   v1::DepthEncoding_Name(compressed.encoding()), decompressor, view);
}

absl::Status DecodeCompressed(const v1::CompressedColor& compressed, std::string_view field,
                              const Limits& limits, PlaneDecompressor* decompressor,
                              ColorView* view) {
  ColorEncoding encoding;
  if (auto s = FromProto(compressed.encoding(), Path(field, "encoding"), &encoding); !s.ok()) {
    return s;
  }
  return DecodeAny(compressed, field, limits, encoding,
                   v1::ColorEncoding_Name(compressed.encoding()), decompressor, view);
}

// ---------------------------------------------------------------------------------------------

namespace {

// Where a status carries its field and rule when its message does not start with the field, or
// the rule is not the code's (RequiredError).
constexpr char kFieldPayload[] = "type.cloudcast.io/cloudcast.field";
constexpr char kReasonPayload[] = "type.cloudcast.io/cloudcast.reason";
constexpr char kBadRequestTypeUrl[] = "type.googleapis.com/google.rpc.BadRequest";

// A proto field path: "frame.depth.raw.row_stride", "config.stereo.calibration.left_d",
// "config.camera.invalid_disparities.values[3]".
bool IsFieldPath(std::string_view token) {
  if (token.empty() || !std::islower(static_cast<unsigned char>(token.front()))) return false;
  for (char c : token) {
    const auto u = static_cast<unsigned char>(c);
    if (!(std::islower(u) || std::isdigit(u) || c == '_' || c == '.' || c == '[' || c == ']')) {
      return false;
    }
  }
  return token.back() != '.';
}

}  // namespace

absl::Status RequiredError(std::string_view field, std::string_view message) {
  absl::Status status = absl::InvalidArgumentError(S(message));
  status.SetPayload(kFieldPayload, absl::Cord(S(field)));
  status.SetPayload(kReasonPayload, absl::Cord("REQUIRED"));
  return status;
}

v1::FieldViolation FieldViolationOf(const absl::Status& status, std::string_view fallback_field) {
  v1::FieldViolation v;
  v.set_description(std::string(status.message()));
  if (auto field = status.GetPayload(kFieldPayload); field.has_value()) {
    v.set_field(std::string(*field));
  } else {
    // Every message names its field first (core/checks.h words them so; the server's tests
    // hold every error path to it), e.g. "frame.color.raw.height is 0".
    const std::string message(status.message());
    const std::size_t end = std::min(message.find_first_of(" :,;("), message.size());
    const std::string_view token = std::string_view(message).substr(0, end);
    // A dotted path ("frame.color.raw.height is 0"), or one word before a colon ("frame: ...");
    // a plain first word ("the ...") is no field.
    const bool path = IsFieldPath(token) && (token.find('.') != std::string_view::npos ||
                                             (end < message.size() && message[end] == ':'));
    v.set_field(path ? std::string(token) : S(fallback_field));
  }
  if (auto reason = status.GetPayload(kReasonPayload); reason.has_value()) {
    v.set_reason(std::string(*reason));
  } else {
    v.set_reason(status.code() == absl::StatusCode::kResourceExhausted ? "OVER_LIMIT" : "INVALID");
  }
  return v;
}

void FillError(const absl::Status& status, v1::ErrorKind kind, std::uint64_t sequence,
               const std::string& frame_id, v1::FrameError* error) {
  error->set_sequence(sequence);
  error->set_frame_id(frame_id);
  error->set_code(static_cast<int>(status.code()));  // absl and gRPC share the numbering
  error->set_message(std::string(status.message()));
  error->set_kind(kind);
  const char* fallback = kind == v1::ERROR_KIND_CONFIG    ? "config"
                         : kind == v1::ERROR_KIND_REQUEST ? "kind"
                                                          : "frame";
  v1::BadRequest* bad = error->mutable_bad_request();
  bad->clear_field_violations();
  *bad->add_field_violations() = FieldViolationOf(status, fallback);
  // A request with neither a config nor a frame: the oneof `kind` is what it got wrong.
  if (kind == v1::ERROR_KIND_REQUEST) bad->mutable_field_violations(0)->set_field("kind");
}

std::string StatusDetails(const absl::Status& status, std::string_view fallback_field) {
  v1::BadRequest bad;
  *bad.add_field_violations() = FieldViolationOf(status, fallback_field);
  google::protobuf::Any any;
  any.set_type_url(kBadRequestTypeUrl);
  any.set_value(bad.SerializeAsString());
  const std::string any_bytes = any.SerializeAsString();
  const std::string message(status.message());
  // google.rpc.Status: code = 1, message = 2, repeated google.protobuf.Any details = 3.
  std::string out;
  {
    google::protobuf::io::StringOutputStream stream(&out);
    google::protobuf::io::CodedOutputStream coded(&stream);
    coded.WriteTag(google::protobuf::internal::WireFormatLite::MakeTag(
        1, google::protobuf::internal::WireFormatLite::WIRETYPE_VARINT));
    coded.WriteVarint32SignExtended(static_cast<int>(status.code()));
    for (const auto& [number, bytes] : {std::pair<int, const std::string*>{2, &message},
                                        std::pair<int, const std::string*>{3, &any_bytes}}) {
      coded.WriteTag(google::protobuf::internal::WireFormatLite::MakeTag(
          number, google::protobuf::internal::WireFormatLite::WIRETYPE_LENGTH_DELIMITED));
      coded.WriteVarint32(static_cast<std::uint32_t>(bytes->size()));
      coded.WriteString(*bytes);
    }
  }
  return out;
}

bool ParseStatusDetails(const std::string& details, v1::BadRequest* out) {
  google::protobuf::io::CodedInputStream in(reinterpret_cast<const std::uint8_t*>(details.data()),
                                            static_cast<int>(details.size()));
  bool found = false;
  while (std::uint32_t tag = in.ReadTag()) {
    using google::protobuf::internal::WireFormatLite;
    if (WireFormatLite::GetTagFieldNumber(tag) == 3 &&
        WireFormatLite::GetTagWireType(tag) == WireFormatLite::WIRETYPE_LENGTH_DELIMITED) {
      std::uint32_t size = 0;
      std::string bytes;
      if (!in.ReadVarint32(&size) || !in.ReadString(&bytes, static_cast<int>(size))) return false;
      google::protobuf::Any any;
      if (!any.ParseFromString(bytes)) return false;
      if (any.type_url() != kBadRequestTypeUrl) continue;
      v1::BadRequest bad;
      if (!bad.ParseFromString(any.value())) return false;
      out->MergeFrom(bad);
      found = true;
    } else if (!WireFormatLite::SkipField(&in, tag)) {
      return false;
    }
  }
  return found;
}

absl::Status ToStatus(const v1::FrameError& error) {
  int code = error.code();
  if (code <= 0 || code > 16) code = static_cast<int>(absl::StatusCode::kUnknown);
  absl::Status status(static_cast<absl::StatusCode>(code), error.message());
  // The field and rule ride along, so that FieldViolationOf(status) gives them back.
  if (error.bad_request().field_violations_size() > 0) {
    const v1::FieldViolation& v = error.bad_request().field_violations(0);
    status.SetPayload(kFieldPayload, absl::Cord(v.field()));
    status.SetPayload(kReasonPayload, absl::Cord(v.reason()));
  }
  return status;
}

bool AnswersNoFrame(const v1::FrameError& error) {
  return error.kind() == v1::ERROR_KIND_CONFIG || error.kind() == v1::ERROR_KIND_REQUEST;
}

}  // namespace cloudcast::convert
