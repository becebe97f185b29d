#include "cloudcast/cli/stage_flags.h"

#include <cmath>

#include "cloudcast/cli/checks.h"
#include "cloudcast/core/checks.h"
#include "cloudcast/proto/convert.h"

namespace cloudcast::cli {
namespace {

const CLI::Validator& Positive() {
  static const CLI::Validator v =
      NumberCheck("a finite number > 0", [](double x) { return x > 0 && x <= 1e9; });
  return v;
}
const CLI::Validator& Finite() {
  static const CLI::Validator v =
      NumberCheck("a finite number", [](double x) { return std::fabs(x) <= 1e9; });
  return v;
}

}  // namespace

StageFlags::StageFlags(CLI::App& app, Groups groups, const FrameSettings& defaults)
    : app_(app),
      focal_(defaults.pipeline.camera.fx),
      fy_(),
      cx_(defaults.cx),
      cy_(defaults.cy),
      baseline_(defaults.pipeline.camera.baseline),
      disparity_scale_(defaults.pipeline.camera.disparity_scale),
      disparity_offset_(defaults.pipeline.camera.disparity_offset),
      axis_(Name(defaults.pipeline.passthrough.axis)),
      min_(defaults.pipeline.passthrough.min),
      max_(defaults.pipeline.passthrough.max),
      negative_(defaults.pipeline.passthrough.negative),
      no_passthrough_(!defaults.pipeline.passthrough.enabled),
      leaf_(defaults.pipeline.voxel.enabled ? defaults.pipeline.voxel.leaf_x : 0.0f),
      min_points_per_voxel_(defaults.pipeline.voxel.min_points_per_voxel),
      cap_min_points_per_voxel_(defaults.cap_min_points_per_voxel),
      draco_bits_(defaults.draco.position_bits),
      draco_speed_(defaults.draco.encode_speed) {
  const std::string& cam = groups.camera;
  app.add_option("--camera-preset", preset_,
                 "A known camera, by name: new_tsukuba (the paper's: fx = fy = 615, baseline 1, "
                 "0 and 2047 invalid, and its passthrough z in [3, 12] unless passthrough flags "
                 "are given). The camera flags below override its values")
      ->check(CLI::IsMember(PresetNames()))
      ->group(cam);
  CLI::Option* focal =
      app.add_option("--focal", focal_,
                     std::string("Focal length in pixels, fx = fy (z = focal * baseline / d)") +
                         (defaults.focal_given ? ""
                                               : "; no default: give it, or --camera-preset, "
                                                 "unless the source has its own camera"))
          ->check(Positive())
          ->group(cam);
  // A program that captures every default (cloudcast-server) must not show one it does not have.
  if (defaults.focal_given) {
    focal->capture_default_str();
  } else {
    focal->default_str("");
  }
  app.add_option("--fy", fy_, "Vertical focal length in pixels [default: --focal]")
      ->check(Positive())
      ->group(cam);
  app.add_option("--cx", cx_,
                 "Principal point column [default: width/2 of each frame, integer division as "
                 "PCL]")
      ->check(Finite())
      ->group(cam);
  app.add_option("--cy", cy_, "Principal point row [default: height/2 of each frame]")
      ->check(Finite())
      ->group(cam);
  CLI::Option* baseline =
      app.add_option("--baseline", baseline_,
                     "Stereo baseline, in the unit wanted for x y z (1 reproduces PCL: z = f/d; "
                     "New Tsukuba: 0.1 for metres); disparity and stereo input need it")
          ->check(Positive())
          ->group(cam);
  if (defaults.baseline_given) {
    baseline->capture_default_str();
  } else {
    baseline->default_str("");
  }
  app.add_option("--disparity-scale", disparity_scale_,
                 "Multiplies raw disparity values (0.0625 for 1/16 fixed point)")
      ->check(NumberCheck("a finite number other than 0",
                          [](double x) { return x != 0 && std::fabs(x) <= 1e9; }))
      ->capture_default_str()
      ->group(cam);
  app.add_option("--disparity-offset", disparity_offset_,
                 "Added to the scaled disparity before z = f * b / d")
      ->check(Finite())
      ->capture_default_str()
      ->group(cam);

  const std::string& st = groups.stages;
  app.add_option("--axis", axis_, "Passthrough axis")
      ->check(CLI::IsMember({"x", "y", "z"}))
      ->capture_default_str()
      ->group(st);
  // The passthrough is off unless asked for: --min or --max switches it on.
  const bool pt_on = defaults.pipeline.passthrough.enabled;
  CLI::Option* min = app.add_option(
      "--min", min_, "Passthrough lower limit, inclusive, in the cloud's unit; switches it on");
  min->check(Finite())->group(st);
  CLI::Option* max = app.add_option(
      "--max", max_, "Passthrough upper limit, inclusive, in the cloud's unit; switches it on");
  max->check(Finite())->group(st);
  if (pt_on) {
    min->capture_default_str();
    max->capture_default_str();
  } else {
    min->default_str("");
    max->default_str("");
  }
  app.add_flag("--negative", negative_, "Passthrough keeps the points outside [min, max]")
      ->group(st);
  app.add_flag("--no-passthrough", no_passthrough_,
               std::string("Switch the passthrough off (points without a valid disparity are "
                           "still removed)") +
                   (pt_on ? "" : "; it is off unless --min, --max or a preset asks for it"))
      ->group(st);
  app.add_option("--leaf", leaf_, "Voxel grid leaf size on x, y and z; 0 switches it off")
      ->check(NumberCheck("a finite number >= 0 (0 switches the voxel grid off)",
                          [](double x) { return x >= 0 && x <= 1e9; }))
      ->capture_default_str()
      ->group(st);
  app.add_option("--min-points-per-voxel", min_points_per_voxel_,
                 "Voxels with fewer points are dropped (0 and 1 keep all)")
      ->capture_default_str()
      ->group(st);

  const std::string& dr = groups.draco;
  app.add_option("--draco-bits", draco_bits_,
                 "Draco position quantization bits; raised when needed to keep the error under "
                 "a quarter of the leaf")
      ->check(CLI::Range(1, 30))
      ->capture_default_str()
      ->group(dr);
  app.add_option("--draco-speed", draco_speed_,
                 "Draco encode / decode speed, 0 (smallest) .. 10 (fastest)")
      ->check(CLI::Range(0, 10))
      ->capture_default_str()
      ->group(dr);
  app.add_option("--cap-min-points-per-voxel", cap_min_points_per_voxel_,
                 "With a downlink cap (max_cloud_bytes, --max-reply-kb): a cloud still over it "
                 "at the fewest bits its bounds allow loses the voxels of fewest points, the "
                 "minimum raised up to N (e.g. 2: a stereo matcher's lone stray points first); "
                 "0: never")
      ->check(CLI::Range(0u, FrameSettings::kMaxCapMinPoints))
      ->capture_default_str()
      ->group(dr);
}

bool StageFlags::Given(const std::string& flag) const { return app_.count(flag) > 0; }

bool StageFlags::PassThroughGiven() const {
  return Given("--no-passthrough") || Given("--axis") || Given("--min") || Given("--max") ||
         Given("--negative");
}

absl::StatusOr<FrameSettings> StageFlags::Apply(FrameSettings base) const {
  if (Given("--camera-preset")) {
    if (auto s = ApplyPreset(preset_, &base, "--camera-preset", !PassThroughGiven()); !s.ok()) {
      return s;
    }
  }
  CameraModel& camera = base.pipeline.camera;
  if (Given("--focal")) {
    camera.fx = camera.fy = focal_;
    base.focal_given = true;
  }
  if (fy_) camera.fy = *fy_;
  if (cx_) base.cx = *cx_;
  if (cy_) base.cy = *cy_;
  if (Given("--baseline")) {
    camera.baseline = baseline_;
    base.baseline_given = true;
  }
  if (Given("--disparity-scale")) camera.disparity_scale = disparity_scale_;
  if (Given("--disparity-offset")) camera.disparity_offset = disparity_offset_;

  PassThroughParams& pt = base.pipeline.passthrough;
  if (Given("--min") || Given("--max")) pt.enabled = true;
  if (Given("--no-passthrough")) pt.enabled = !no_passthrough_;
  if (Given("--axis") && !ParseAxis(axis_, &pt.axis)) {
    return absl::InvalidArgumentError("--axis must be x, y or z, got " + axis_);
  }
  if (Given("--min")) pt.min = min_;
  if (Given("--max")) pt.max = max_;
  if (Given("--negative")) pt.negative = negative_;
  if (pt.enabled) {
    if (auto s = check::Ordered("--min", pt.min, "--max", pt.max); !s.ok()) return s;
  }

  VoxelGridParams& v = base.pipeline.voxel;
  if (Given("--leaf")) {
    v.enabled = leaf_ > 0;
    if (v.enabled) v.SetLeaf(leaf_);
  }
  if (Given("--min-points-per-voxel")) v.min_points_per_voxel = min_points_per_voxel_;
  if (v.enabled) {
    if (auto s = check::Leaf("--leaf", v.leaf_x); !s.ok()) return s;
  }

  if (Given("--draco-bits")) base.draco.position_bits = draco_bits_;
  if (Given("--draco-speed")) base.draco.encode_speed = base.draco.decode_speed = draco_speed_;
  if (Given("--cap-min-points-per-voxel")) {
    base.cap_min_points_per_voxel = cap_min_points_per_voxel_;
  }
  // Every flag has its own range check; this catches a bad `base`.
  if (auto s = base.Validate(); !s.ok()) return s;
  return base;
}

bool StageFlags::CameraGiven() const { return Given("--camera-preset") || Given("--focal"); }

v1::StreamConfig StageFlags::GivenStageConfig() const {
  v1::StreamConfig config;
  if (Given("--camera-preset") && !PassThroughGiven()) {
    // The preset's depth range goes with it.
    FrameSettings preset;
    if (ApplyPreset(preset_, &preset).ok())
      convert::SetPassThrough(preset.pipeline.passthrough, &config);
  }
  if (PassThroughGiven()) {
    v1::PassThroughConfig* p = config.mutable_passthrough();
    if (Given("--no-passthrough")) p->set_enabled(!no_passthrough_);
    Axis axis;
    if (Given("--axis") && ParseAxis(axis_, &axis)) p->set_axis(convert::ToProto(axis));
    if (Given("--min")) p->set_min(min_);
    if (Given("--max")) p->set_max(max_);
    if (Given("--negative")) p->set_negative(negative_);
  }
  if (Given("--leaf") || Given("--min-points-per-voxel")) {
    v1::VoxelGridConfig* v = config.mutable_voxel_grid();
    if (Given("--leaf")) {
      v->set_enabled(leaf_ > 0);
      if (leaf_ > 0) v->set_leaf(leaf_);
    }
    if (Given("--min-points-per-voxel")) v->set_min_points_per_voxel(min_points_per_voxel_);
  }
  if (Given("--draco-bits")) config.mutable_draco()->set_position_bits(draco_bits_);
  if (Given("--draco-speed")) {
    config.mutable_draco()->set_encode_speed(draco_speed_);
    config.mutable_draco()->set_decode_speed(draco_speed_);
  }
  if (Given("--cap-min-points-per-voxel")) {
    config.mutable_draco()->set_cap_min_points_per_voxel(cap_min_points_per_voxel_);
  }
  return config;
}

}  // namespace cloudcast::cli
