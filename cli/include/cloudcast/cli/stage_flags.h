// The stage flags, defined once for every program (cloudcast-process, cloudcast-server,
// cloudcast-client, cloudcast-load): camera (a preset, or its values), passthrough, voxel grid
// and Draco. Defaults come from the FrameSettings the program passes (the core structs' own unless
// it says otherwise), and --help shows them; a camera or passthrough the defaults do not have
// (FrameSettings::focal_given, passthrough off) shows none.
//
//   CLI::App app;
//   cloudcast::cli::StageFlags stages(app, {"Camera", "Stages", "Draco"});
//   app.parse(argc, argv);
//   absl::StatusOr<FrameSettings> settings = stages.Apply(base);  // base + the flags given
#pragma once

#include <CLI/CLI.hpp>
#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "cloudcast/core/settings.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::cli {

class StageFlags {
 public:
  // The --help groups the flags go in.
  struct Groups {
    std::string camera = "Camera";
    std::string stages = "Stages";
    std::string draco = "Draco";
  };

  // Registers the flags on `app` (which must outlive this object), showing `defaults`.
  StageFlags(CLI::App& app, Groups groups, const FrameSettings& defaults = FrameSettings{});
  StageFlags(const StageFlags&) = delete;
  StageFlags& operator=(const StageFlags&) = delete;

  // After parsing: `base` with every flag that was given applied on top, checked. Errors name the
  // flags (e.g. "--min (20) must not exceed --max (12)").
  absl::StatusOr<FrameSettings> Apply(FrameSettings base) const;

  // After parsing: the flags that were given, as a StreamConfig whose other fields stay unset (so
  // the server's defaults apply to them). The camera section is left to the caller.
  v1::StreamConfig GivenStageConfig() const;

  // Whether a flag was given, e.g. Given("--focal").
  bool Given(const std::string& flag) const;
  // Whether the camera was given: --camera-preset or --focal.
  bool CameraGiven() const;
  // Whether any passthrough flag was given (a preset's range then stays out).
  bool PassThroughGiven() const;

 private:
  CLI::App& app_;
  std::string preset_;
  double focal_;
  std::optional<double> fy_, cx_, cy_;
  double baseline_, disparity_scale_, disparity_offset_;
  std::string axis_;
  float min_, max_;
  bool negative_ = false;
  bool no_passthrough_ = false;
  float leaf_;
  std::uint32_t min_points_per_voxel_;
  std::uint32_t cap_min_points_per_voxel_;
  int draco_bits_, draco_speed_;
};

}  // namespace cloudcast::cli
