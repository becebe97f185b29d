// cloudcast-process: one frame through the whole chain, offline. It loads a disparity + colour
// pair (or renders the synthetic scene), runs the three stand-alone stages and the fused pipeline,
// times each, Draco-encodes the result, and writes the cloud and a JSON report.
//
// stdout carries the report (input, camera, table); stderr carries log lines and errors, so the
// report can be piped. Exit status: 0 ok, 1 processing error, 2 usage error.
#include <spdlog/fmt/fmt.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "cloudcast/cli/checks.h"
#include "cloudcast/cli/stage_flags.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/filters.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/limits.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/core/point.h"
#include "cloudcast/core/settings.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/io/cloud_io.h"
#include "cloudcast/io/image_io.h"

namespace cloudcast {
namespace {

// Keys stay in the order written, so the file reads top-down like the table.
using Json = nlohmann::ordered_json;

constexpr int kExitProcessing = 1;
constexpr int kExitUsage = 2;

// Everything the command line sets besides the stage flags (cli::StageFlags), whose camera
// flags fall back to the input's own camera when not given (its size, or the synthetic scene's).
struct Flags {
  std::string colour_path;
  std::string disparity_path;
  std::string synthetic;  // "WxH"
  std::uint64_t frame = 0;

  std::string out_path;
  std::string json_path;
  int repeat = 1;
  bool quiet = false;
};

// ---------------------------------------------------------------------------------------------
// Validators. They see the raw string, so they can reject "nan" and "inf" that CLI11's own number
// conversion accepts.

using cli::ParseSize;
using cli::Wrap;

const CLI::Validator kSize = cli::SizeCheck(Limits{}.max_side, Limits{}.max_pixels);

// ---------------------------------------------------------------------------------------------
// Timing.

template <typename Fn>
double TimeMs(Fn&& fn) {
  const auto start = std::chrono::steady_clock::now();
  fn();
  const auto end = std::chrono::steady_clock::now();
  return std::chrono::duration<double, std::milli>(end - start).count();
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Runs `fn` `repeat` times (stopping at the first error) and stores the median time in `*ms`.
absl::Status Timed(int repeat, double* ms, const std::function<absl::Status()>& fn) {
  std::vector<double> times;
  times.reserve(repeat);
  for (int i = 0; i < repeat; ++i) {
    absl::Status status;
    times.push_back(TimeMs([&] { status = fn(); }));
    if (!status.ok()) return status;
  }
  *ms = Median(times);
  return absl::OkStatus();
}

// ---------------------------------------------------------------------------------------------
// The frame and the report.

// The loaded frame: either owned images from files or a synthetic render.
struct Frame {
  OwnedDisparity disparity_file;
  OwnedColor colour_file;
  std::optional<SyntheticFrame> synthetic;

  DisparityView disparity() const {
    return synthetic ? synthetic->disparity_view() : disparity_file.view();
  }
  ColorView colour() const { return synthetic ? synthetic->colour_view() : colour_file.view(); }
};

struct Stage {
  Stage(std::string json_name, std::string table_label)
      : name(std::move(json_name)), label(std::move(table_label)) {}

  std::string name;   // JSON name
  std::string label;  // table name
  std::uint64_t points = 0;
  double ms = 0;
  std::string note;
  Json extra = Json::object();
};

std::string FormatKb(std::size_t bytes) {
  return fmt::format("{:.1f} KB", static_cast<double>(bytes) / 1024.0);
}

std::uint64_t CountFinite(const PointCloud& cloud) {
  return static_cast<std::uint64_t>(
      std::count_if(cloud.points.begin(), cloud.points.end(), [](const Point& p) {
        return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
      }));
}

Json CameraJson(const CameraModel& c) {
  return {{"fx", c.fx},
          {"fy", c.fy},
          {"cx", c.cx},
          {"cy", c.cy},
          {"baseline", c.baseline},
          {"disparity_scale", c.disparity_scale},
          {"disparity_offset", c.disparity_offset},
          {"invalid_disparities", c.invalid_disparities}};
}

// A processing error: logged, exit status 1.
int Fail(const std::string& message) {
  spdlog::error("{}", message);
  return kExitProcessing;
}

int FailStatus(const std::string& context, const absl::Status& status) {
  std::string message(status.message());
  // Core messages often name their stage already ("voxel grid: ..."); say it once.
  if (message.rfind(context, 0) != 0) message = context + ": " + message;
  return Fail(message);
}

// ---------------------------------------------------------------------------------------------

// Output folders are checked before any work, so a typo costs nothing.
absl::Status CheckFolderOf(const std::string& flag, const std::string& path) {
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  std::error_code ec;
  if (!path.empty() && !parent.empty() && !std::filesystem::is_directory(parent, ec)) {
    return absl::NotFoundError(
        fmt::format("{} '{}': folder '{}' does not exist", flag, path, parent.string()));
  }
  return absl::OkStatus();
}

int Process(const Flags& f, const cli::StageFlags& stage_flags) {
  for (const auto& [flag, path] :
       {std::pair<const char*, const std::string&>{"--out", f.out_path}, {"--json", f.json_path}}) {
    if (auto s = CheckFolderOf(flag, path); !s.ok()) return Fail(std::string(s.message()));
  }
  const bool from_files = !f.colour_path.empty();
  std::uint32_t width = 640, height = 480;
  if (!f.synthetic.empty()) ParseSize(f.synthetic, &width, &height);
  if (!from_files && f.synthetic.empty()) {
    spdlog::info("no --colour/--disparity given: using the synthetic scene (--synthetic 640x480)");
  }

  // ---- load
  Frame frame;
  Json input;
  std::string input_line;
  Stage load{"load", "load"};
  const int repeat = f.repeat;
  absl::Status status;
  if (from_files) {
    status = Timed(repeat, &load.ms, [&]() -> absl::Status {
      auto disparity = LoadDisparity(f.disparity_path);
      if (!disparity.ok()) return disparity.status();
      auto colour = LoadColor(f.colour_path);
      if (!colour.ok()) return colour.status();
      frame.disparity_file = *std::move(disparity);
      frame.colour_file = *std::move(colour);
      return absl::OkStatus();
    });
    if (!status.ok()) return Fail(std::string(status.message()));
    const DisparityView d = frame.disparity();
    const ColorView c = frame.colour();
    width = d.width;
    height = d.height;
    load.note = "(image files decoded)";
    input = {{"kind", "files"},
             {"colour", f.colour_path},
             {"disparity", f.disparity_path},
             {"width", d.width},
             {"height", d.height},
             {"colour_size", fmt::format("{}x{}", c.width, c.height)},
             {"disparity_encoding", std::string(Name(d.encoding))},
             {"colour_encoding", std::string(Name(c.encoding))}};
    input_line = fmt::format("input:  disparity {} ({}x{} {}), colour {} ({}x{} {})",
                             f.disparity_path, d.width, d.height, Name(d.encoding), f.colour_path,
                             c.width, c.height, Name(c.encoding));
  } else {
    SyntheticOptions options;
    options.width = width;
    options.height = height;
    options.frame = f.frame;
    const SyntheticScene scene = SyntheticScene::Default();
    status = Timed(repeat, &load.ms, [&]() -> absl::Status {
      auto rendered = scene.Render(options);
      if (!rendered.ok()) return rendered.status();
      frame.synthetic = *std::move(rendered);
      return absl::OkStatus();
    });
    if (!status.ok()) return FailStatus("--synthetic " + f.synthetic, status);
    load.note = "(synthetic scene rendered)";
    const DisparityView d = frame.disparity();
    input = {{"kind", "synthetic"},
             {"width", width},
             {"height", height},
             {"frame", f.frame},
             {"disparity_encoding", std::string(Name(d.encoding))},
             {"colour_encoding", std::string(Name(frame.colour().encoding))}};
    input_line = fmt::format("input:  synthetic scene {}x{}, frame {} ({} disparity)", width,
                             height, f.frame, Name(d.encoding));
  }
  load.points = std::uint64_t{width} * height;
  if (auto s = ValidateFrame(frame.disparity(), frame.colour(), Limits{}); !s.ok()) {
    return FailStatus("input", s);
  }

  // ---- camera and stages: the input's camera and the core's defaults, then every flag given.
  FrameSettings base;
  if (frame.synthetic) {
    base.pipeline.camera = frame.synthetic->camera;
    base.cx = frame.synthetic->camera.cx;
    base.cy = frame.synthetic->camera.cy;
  } else {
    base.pipeline.camera = CameraModel::PclCompatible(width, height);
  }
  auto settings = stage_flags.Apply(base);
  if (!settings.ok()) return FailStatus("options", settings.status());
  const PipelineOptions options = settings->PipelineFor(width, height);
  const CameraModel& camera = options.camera;
  const DracoOptions draco = settings->Draco();
  const std::string camera_line =
      fmt::format("camera: {} ({})", camera.ToString(),
                  frame.synthetic ? "synthetic scene's camera" : "PCL-compatible preset");

  const DisparityView disparity = frame.disparity();
  const ColorView colour = frame.colour();

  // ---- the three stand-alone stages
  PointCloud organized, passed, voxels;
  Stage convert{"convert", "convert"};
  status = Timed(repeat, &convert.ms, [&] {
    return ConvertToOrganized(camera, disparity, colour, &organized, options.limits);
  });
  if (!status.ok()) return FailStatus("convert", status);
  const std::uint64_t valid = CountFinite(organized);
  convert.points = organized.size();
  convert.note = fmt::format("({} valid)", valid);
  convert.extra["valid_points"] = valid;

  Stage pass{"passthrough", "passthrough"};
  status =
      Timed(repeat, &pass.ms, [&] { return PassThrough(organized, options.passthrough, &passed); });
  if (!status.ok()) return FailStatus("passthrough", status);
  pass.points = passed.size();
  pass.note = options.passthrough.enabled
                  ? fmt::format("({} {}in [{}, {}])", Name(options.passthrough.axis),
                                options.passthrough.negative ? "not " : "", options.passthrough.min,
                                options.passthrough.max)
                  : "(off: only NaN points removed)";

  Stage voxel{"voxel_grid", "voxel grid"};
  VoxelGrid grid;
  if (options.voxel.enabled) {
    status = Timed(repeat, &voxel.ms, [&] { return grid.Filter(passed, options.voxel, &voxels); });
    if (!status.ok()) return FailStatus("voxel grid", status);
    voxel.points = voxels.size();
    voxel.note = fmt::format("(leaf {})", options.voxel.leaf_x);
  } else {
    // VoxelGrid::Filter refuses disabled params; the stage passes its input through unchanged.
    voxel.points = passed.size();
    voxel.note = "(off: --leaf 0)";
    voxel.extra["skipped"] = true;
  }

  // ---- the fused pipeline: this is the cloud that is written
  Stage fused{"fused_chain", "fused chain"};
  Pipeline pipeline;
  PointCloud cloud;
  StageCounts counts;
  status = Timed(repeat, &fused.ms,
                 [&] { return pipeline.Run(options, disparity, colour, &cloud, &counts); });
  if (!status.ok()) return FailStatus("fused pipeline", status);
  fused.points = cloud.size();
  fused.note = "(images -> voxel cloud in one pass)";
  fused.extra["counts"] = {{"pixels", counts.pixels},
                           {"valid_points", counts.valid_points},
                           {"after_passthrough", counts.after_passthrough},
                           {"after_voxel", counts.after_voxel}};
  // The two routes must agree; a mismatch is a bug in core worth shouting about, but the run's
  // figures are still worth having.
  const bool consistent = counts.valid_points == valid && counts.after_passthrough == pass.points &&
                          counts.after_voxel == voxel.points && cloud.size() == voxel.points;
  if (!consistent) {
    spdlog::warn(
        "the fused pipeline disagrees with the stand-alone stages: valid {} vs {}, passthrough "
        "{} vs {}, voxel grid {} vs {}, output {} points",
        counts.valid_points, valid, counts.after_passthrough, pass.points, counts.after_voxel,
        voxel.points, cloud.size());
  }

  // ---- Draco
  Stage encode{"draco_encode", "draco encode"};
  std::string encoded;
  DracoEncodeInfo info;
  status = Timed(repeat, &encode.ms, [&] { return EncodeDraco(cloud, draco, &encoded, &info); });
  if (!status.ok()) return FailStatus("Draco encode", status);
  encode.points = CountFinite(cloud);
  encode.note = fmt::format("{}, {}-bit positions, speed {}", FormatKb(info.bytes),
                            info.position_bits, draco.encode_speed);
  encode.extra = {{"bytes", info.bytes},
                  {"position_bits", info.position_bits},
                  {"position_error_bound", info.position_error_bound}};

  std::vector<Stage> stages = {load, convert, pass, voxel, fused, encode};

  // ---- write
  Json output;
  if (!f.out_path.empty()) {
    Stage write{"write", "write"};
    status = Timed(1, &write.ms, [&] { return SaveCloud(f.out_path, cloud, draco); });
    if (!status.ok()) return Fail(std::string(status.message()));
    std::error_code ec;
    const auto bytes = std::filesystem::file_size(f.out_path, ec);
    write.points = cloud.size();
    write.note = ec ? f.out_path : fmt::format("{} ({})", f.out_path, FormatKb(bytes));
    output = {{"path", f.out_path}, {"points", cloud.size()}, {"bytes", ec ? 0 : bytes}};
    stages.push_back(write);
  }

  // ---- report
  if (!f.quiet) {
    std::string table = input_line + "\n" + camera_line + "\n";
    table += fmt::format("{:<14} {:>9} {:>10}\n", "stage", "points", "ms");
    for (const Stage& s : stages) {
      table += fmt::format("{:<14} {:>9} {:>10.3f}   {}\n", s.label, s.points, s.ms, s.note);
    }
    if (repeat > 1) {
      table += f.out_path.empty() ? fmt::format("ms: median of {} runs\n", repeat)
                                  : fmt::format("ms: median of {} runs (write: one run)\n", repeat);
    }
    std::fputs(table.c_str(), stdout);
    std::fflush(stdout);
  }

  if (!f.json_path.empty()) {
    Json j;
    j["tool"] = "cloudcast-process";
    j["repeat"] = repeat;
    j["input"] = input;
    j["camera"] = CameraJson(camera);
    j["passthrough"] = {{"enabled", options.passthrough.enabled},
                        {"axis", std::string(Name(options.passthrough.axis))},
                        {"min", options.passthrough.min},
                        {"max", options.passthrough.max},
                        {"negative", options.passthrough.negative}};
    j["voxel_grid"] = {{"enabled", options.voxel.enabled},
                       {"leaf", options.voxel.enabled ? options.voxel.leaf_x : 0.0f},
                       {"min_points_per_voxel", options.voxel.min_points_per_voxel}};
    j["stages"] = Json::array();
    for (const Stage& s : stages) {
      Json stage = {{"name", s.name}, {"points", s.points}, {"ms", s.ms}};
      stage.update(s.extra);
      j["stages"].push_back(stage);
    }
    j["draco_bytes"] = info.bytes;
    j["draco"] = {{"position_bits", info.position_bits},
                  {"requested_position_bits", draco.position_bits},
                  {"speed", draco.encode_speed},
                  {"max_position_error", draco.max_position_error}};
    j["fused_matches_stages"] = consistent;
    if (!output.is_null()) j["output"] = output;
    std::ofstream file(f.json_path, std::ios::trunc);
    file << j.dump(2) << "\n";
    file.close();
    if (!file) return Fail("cannot write --json '" + f.json_path + "'");
  }
  return 0;
}

int Main(int argc, char** argv) {
  Flags f;
  CLI::App app(
      "cloudcast-process: turns one stereo frame (disparity + colour) into a filtered point "
      "cloud,\n"
      "the way the cloudcast server does: organized conversion (as PCL's OrganizedConversion),\n"
      "passthrough, voxel grid, Draco. It runs the three stand-alone stages and the fused\n"
      "pipeline, times each (median of --repeat runs), and writes the fused result.\n"
      "With no input flags it renders the synthetic scene at 640x480.\n\n"
      "Examples:\n"
      "  D=../shared/data/new_tsukuba   # New Tsukuba frame 00001, the paper's parameters\n"
      "  cloudcast-process --colour $D/illumination/daylight/left/tsukuba_daylight_L_00001.png \\\n"
      "    --disparity $D/groundtruth/disparity_maps/left/tsukuba_disparity_L_00001.png \\\n"
      "    --focal 615 --min 3 --max 12 --leaf 0.03 --repeat 21 --out frame.pcd --json frame.json\n"
      "  cloudcast-process --synthetic 1280x720 --frame 30 --out synthetic.drc\n",
      "cloudcast-process");
  app.footer(
      "Exit status: 0 success, 1 processing error (unreadable file, bad frame, write failure),\n"
      "2 usage error (bad or conflicting flags).");
  app.get_formatter()->column_width(34);

  // Input
  auto* colour = app.add_option("--colour", f.colour_path,
                                "Colour image (PNG, JPEG, TIFF, ...): 8 or 16-bit BGR, BGRA "
                                "(alpha ignored) or grey")
                     ->type_name("FILE")
                     ->group("Input");
  auto* disparity = app.add_option("--disparity", f.disparity_path,
                                   "Disparity map, one channel: 8 or 16-bit PNG/TIFF, or 32-bit "
                                   "float TIFF; raw value 0 = invalid")
                        ->type_name("FILE")
                        ->group("Input");
  colour->needs(disparity);
  disparity->needs(colour);
  auto* synthetic = app.add_option("--synthetic", f.synthetic,
                                   "Render the synthetic scene at WIDTHxHEIGHT instead of reading "
                                   "files (the default input is 640x480)")
                        ->check(kSize)
                        ->type_name("WxH")
                        ->group("Input");
  synthetic->excludes(colour)->excludes(disparity);
  auto* frame = app.add_option("--frame", f.frame,
                               "Frame index of the synthetic scene (its camera moves with it)")
                    ->capture_default_str()
                    ->group("Input");
  frame->excludes(colour)->excludes(disparity);

  const cli::StageFlags stages(app, {"Camera", "Stages", "Draco"});

  // Output
  app.add_option("--out", f.out_path,
                 "Write the fused cloud as .pcd, .ply or .drc (by the extension)")
      ->type_name("FILE")
      ->group("Output");
  app.add_option("--json", f.json_path, "Write the report (input, camera, stages) as JSON")
      ->type_name("FILE")
      ->group("Output");
  app.add_option("--repeat", f.repeat, "Run each stage N times and report the median ms")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str()
      ->type_name("N")
      ->group("Output");
  app.add_flag("--quiet,-q", f.quiet, "Print only warnings and errors")->group("Output");

  for (CLI::Option* option : app.get_options()) {
    option->description(Wrap(option->get_description()));
  }

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // CLI11's own exit codes are 100+; usage errors are 2 here, as for most Unix tools.
    return app.exit(e) == 0 ? 0 : kExitUsage;
  }

  // Checks that involve more than one flag, reported as usage errors.
  auto usage = [](const std::string& message) {
    std::fprintf(stderr, "%s\nRun with --help for more information.\n", message.c_str());
    return kExitUsage;
  };
  if (auto s = stages.Apply(FrameSettings{}); !s.ok())
    return usage(std::string(s.status().message()));
  if (!f.out_path.empty()) {
    if (auto s = CheckCloudPath(f.out_path); !s.ok()) {
      return usage("--out " + std::string(s.message()));
    }
  }

  auto logger = spdlog::stderr_color_mt("cloudcast-process");
  logger->set_pattern("%n: %^%l%$: %v");
  logger->set_level(f.quiet ? spdlog::level::warn : spdlog::level::info);
  spdlog::set_default_logger(logger);
  return Process(f, stages);
}

}  // namespace
}  // namespace cloudcast

int main(int argc, char** argv) {
  try {
    return cloudcast::Main(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cloudcast-process: error: %s\n", e.what());
  } catch (...) {
    std::fprintf(stderr, "cloudcast-process: error: unknown exception\n");
  }
  return 1;
}
