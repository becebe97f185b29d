#include "app/app.h"

#include <spdlog/fmt/fmt.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <tuple>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_join.h"
#include "app/recorder.h"
#include "app/session.h"
#include "app/stats.h"
#include "app/viewer.h"
#include "cloudcast/cli/checks.h"
#include "cloudcast/cli/connection_flags.h"
#include "cloudcast/cli/role_flags.h"
#include "cloudcast/cli/stage_flags.h"
#include "cloudcast/cli/stereo_flags.h"
#include "cloudcast/cli/rate_flags.h"
#include "cloudcast/cli/video_flags.h"
#include "cloudcast/client/config.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/filters.h"
#include "cloudcast/core/limits.h"
#include "cloudcast/core/settings.h"
#include "cloudcast/io/cloud_io.h"
#include "cloudcast/sources/frame_source.h"
#include "cloudcast/sources/uplink.h"
#include "cloudcast/video/frame_encoder.h"

namespace cloudcast::client::app {
namespace {

constexpr int kExitFailure = 1;
constexpr int kExitUsage = 2;

// Set by SIGINT / SIGTERM (a lock-free atomic store is async-signal-safe) and by a failing
// recorder; every loop of the program polls it.
std::atomic<bool> g_stop{false};

extern "C" void OnSignal(int signal_number) {
  g_stop.store(true);
  // A second Ctrl-C ends the program at once.
  std::signal(signal_number, SIG_DFL);
}

// The defaults of the flags: those of the options structs they fill, so each is written once.
const SessionOptions& SessionDefaults() {
  static const SessionOptions o;
  return o;
}
const ViewerOptions& ViewerDefaults() {
  static const ViewerOptions o;
  return o;
}

double Seconds(std::chrono::milliseconds d) { return std::chrono::duration<double>(d).count(); }

struct Flags {
  // Source
  std::string tsukuba;
  std::string illumination = sources::SourceSpec{}.illumination;
  std::string input = cli::kDefaultInput;
  // A flag per role of each sort of file: --disparity-glob, --right-video, --depth, ...
  std::unique_ptr<cli::RoleFlags> files;
  std::string synthetic;
  bool loop = false;
  std::uint64_t frames = 0;

  // Streaming
  std::string server = SessionDefaults().server;
  double connect_timeout_s = Seconds(SessionDefaults().connect_timeout);
  double fps = SessionDefaults().fps;
  int in_flight = SessionDefaults().max_in_flight;
  bool lossless = false;
  bool rate_control = false;
  double max_reply_kb = 0;  // the downlink cap (DracoConfig.max_cloud_bytes), kB; 0 = none
  std::string encoding = sources::Name(SessionDefaults().uplink.encoding);
  int jpeg_quality = SessionDefaults().uplink.jpeg_quality;
  double max_point_error = 0;  // near-lossless disparity and depth, metres; 0 = lossless
  // --encoding h264 (docs/video.md): the colour image, or a stereo pair, as H.264 pictures; the
  // --h264-* flags, shared with cloudcast-load.
  std::unique_ptr<cli::VideoFlags> h264;
  std::unique_ptr<cli::RateFlags> rate;  // --rate-*

  // TLS and the bearer token (cli::ConnectionFlags), read after parsing.
  client::ChannelSecurity security;

  // The matcher flags (--input stereo).
  std::unique_ptr<cli::StereoFlags> stereo;

  // Camera and stages: cli::StageFlags.

  // Viewer
  bool no_window = false;
  std::vector<std::string> open;
  std::string window = std::to_string(ViewerDefaults().window.width) + "x" +
                       std::to_string(ViewerDefaults().window.height);
  bool hidden = false;
  float point_size = ViewerDefaults().window.point_size;
  std::string snapshot;
  std::uint64_t snapshot_after = ViewerDefaults().snapshot_after;
  bool exit_at_end = false;

  // Output
  std::string record;
  std::string record_format = "pcd";
  std::string json;
  double progress_s = 2;
  bool print_frames = false;
  bool quiet = false;
};

// ---------------------------------------------------------------------------------------------
// Validators: they see the raw string, so they reject "nan" and "inf", which CLI11's own number
// conversion accepts.

using cli::NumberCheck;
using cli::ParseSize;
using cli::SizeCheck;
using cli::Wrap;

// Output folders are checked before any work, so a typo costs nothing.
std::string MissingFolder(const std::string& flag, const std::string& path) {
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  std::error_code ec;
  if (!path.empty() && !parent.empty() && !std::filesystem::is_directory(parent, ec)) {
    return fmt::format("{} {}: folder '{}' does not exist", flag, path, parent.string());
  }
  return std::string();
}

// ---------------------------------------------------------------------------------------------

using cli::AddInputFlag;

// The stage flags go in the middle of --help, so AddFlags registers them too.
std::unique_ptr<cli::StageFlags> AddFlags(CLI::App& app, Flags& f) {
  const std::string source = "Source (one of; default below)";
  app.add_option("--tsukuba", f.tsukuba,
                 "A New Tsukuba folder: groundtruth/disparity_maps/left/*.png with "
                 "illumination/<illumination>/left/*.png, paired by frame number; --input "
                 "stereo sends the left + right images (illumination/<illumination>/right), "
                 "--input depth the ground truth as float depth (focal x baseline / disparity)")
      ->type_name("DIR")
      ->group(source);
  app.add_option("--illumination", f.illumination,
                 "New Tsukuba illumination folder (daylight, fluorescent, lamps, flashlight)")
      ->capture_default_str()
      ->type_name("NAME")
      ->group(source);
  AddInputFlag(app, &f.input, sources::FrameKindNames(), source);
  f.files = std::make_unique<cli::RoleFlags>(
      app, std::vector<cli::FileSort>{cli::FileSort::kGlob, cli::FileSort::kVideo, cli::FileSort::kStill},
      source);
  app.add_option("--synthetic", f.synthetic,
                 "The synthetic scene at WIDTHxHEIGHT, camera moving frame by frame, as frames of "
                 "--input (a stereo pair's right image rendered from the right camera); endless")
      ->check(SizeCheck(Limits{}.max_side, Limits{}.max_pixels))
      ->type_name("WxH")
      ->group(source);
  app.add_option("--open", f.open,
                 "View local cloud files (.pcd, .ply, .drc) instead of streaming; "
                 "arrow keys step through several")
      ->type_name("FILE")
      ->expected(1, -1)
      ->group(source);
  app.add_flag("--loop", f.loop,
               fmt::format("Start finite sources (folder, globs, videos) again at their end; "
                           "decoded images are kept in memory (up to {} MB) so later passes cost "
                           "no decoding",
                           sources::SourceOptions{}.cache_bytes >> 20))
      ->group(source);
  app.add_option("--frames", f.frames, "Send at most N frames; 0 = all (endless sources: forever)")
      ->capture_default_str()
      ->type_name("N")
      ->group(source);

  const std::string streaming = "Streaming";
  app.add_option("--server", f.server, "The cloudcast server, HOST:PORT (any gRPC target)")
      ->capture_default_str()
      ->type_name("HOST:PORT")
      ->group(streaming);
  app.add_option("--connect-timeout", f.connect_timeout_s, "Seconds to wait for the server")
      ->type_name("SECONDS")
      ->check(NumberCheck("a number of seconds in (0, 3600]",
                          [](double v) { return v > 0 && v <= 3600; }))
      ->capture_default_str()
      ->group(streaming);
  app.add_option("--fps", f.fps,
                 "Frames per second to send; 0 = as fast as the server answers (and the viewer "
                 "draws), with at most --in-flight frames awaiting their reply")
      ->check(NumberCheck("a rate in [0, 10000]", [](double v) { return v >= 0 && v <= 1e4; }))
      ->capture_default_str()
      ->group(streaming);
  app.add_option("--in-flight", f.in_flight, "Frames sent and not yet answered, with --fps 0")
      ->check(CLI::Range(1, 64))
      ->capture_default_str()
      ->group(streaming);
  app.add_flag("--lossless", f.lossless,
               "Every frame is answered (DELIVERY_ALL). Default: DELIVERY_LATEST, the server "
               "skips stale frames to stay real-time")
      ->group(streaming);
  std::vector<std::string> encodings = sources::UplinkNames();
  encodings.emplace_back(video::kH264);
  app.add_option("--encoding", f.encoding,
                 "How images travel: raw pixels; zstd (lossless: row deltas + zstd, about a "
                 "third of raw and cheap for the server); png (lossless); jpeg (colour JPEG, "
                 "disparity still lossless) for a thin uplink; h264 (the colour image, or both "
                 "views of a stereo pair, as H.264 video: the thinnest; disparity and depth "
                 "still lossless; --h264-* flags)")
      ->check(CLI::IsMember(encodings))
      ->capture_default_str()
      ->group(streaming);
  app.add_option("--max-point-error", f.max_point_error,
                 "Near-lossless disparity and depth: each value may change as long as the point "
                 "the server makes from it moves by at most this many metres (per point, before "
                 "any filter; e.g. a quarter of the voxel leaf), which shrinks zstd and png "
                 "frames. 0 = lossless")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str()
      ->group(streaming);
  app.add_option("--max-reply-kb", f.max_reply_kb,
                 "Downlink cap: each reply's cloud at most this many kB (1000 bytes); the server "
                 "quantizes positions (down to the error bound) and colours (down to 5 bits) to "
                 "meet it, and says when it cannot (the progress lines count those). 0 = no cap")
      ->capture_default_str()
      ->group(streaming);
  app.add_option("--jpeg-quality", f.jpeg_quality, "JPEG quality with --encoding jpeg")
      ->check(CLI::Range(1, 100))
      ->capture_default_str()
      ->group(streaming);
  app.add_flag("--rate-control", f.rate_control,
               "Follow the link instead of queueing behind it: a rate controller holds frames "
               "past its window in the sender (a newer frame replaces a waiting one) and, with "
               "--encoding jpeg, sets each frame's JPEG quality (from --jpeg-quality down to 10) "
               "from its target bitrate, then below quality 10 sends disparity and depth frames "
               "at half resolution (their camera halved) until the target allows full again "
               "(the disparity or depth goes lossless, zstd); with --encoding h264, the encoder's bitrate (the target "
               "less the other images' bytes, up to --h264-mbps), frame by frame, and a frame is "
               "encoded only once it can be sent "
               "(a waiting raw frame is what gets replaced). The progress lines show its target, "
               "round trip and "
               "queueing delay. Not with --lossless")
      ->group(streaming);
  f.rate = std::make_unique<cli::RateFlags>(app, streaming);
  f.h264 = std::make_unique<cli::VideoFlags>(app, streaming);

  const std::string stages = "Camera and stages (stage flags left out: the server's defaults)";
  auto stage_flags = std::make_unique<cli::StageFlags>(
      app, cli::StageFlags::Groups{stages, stages, stages}, convert::ContractDefaults().frame);
  f.stereo = std::make_unique<cli::StereoFlags>(
      app, "Stereo matcher (--input stereo; flags left out: the server's defaults)");

  const std::string viewer = "Viewer";
  app.add_flag("--no-window", f.no_window,
               "No window and no OpenGL at all: stream and print statistics")
      ->group(viewer);
  app.add_option("--window", f.window, "Window size")
      ->check(SizeCheck(16384, std::uint64_t{1} << 26))
      ->capture_default_str()
      ->type_name("WxH")
      ->group(viewer);
  app.add_flag("--hidden", f.hidden,
               "Render into a hidden window (for --snapshot without showing anything); exits "
               "when the stream ends")
      ->group(viewer);
  app.add_option("--point-size", f.point_size, "Point size in pixels ('+' / '-' change it)")
      ->check(NumberCheck("a size in [1, 255]", [](double v) { return v >= 1 && v <= 255; }))
      ->capture_default_str()
      ->group(viewer);
  app.add_option("--snapshot", f.snapshot,
                 "Write the view as PNG once --snapshot-after clouds were shown and the current "
                 "one has points (or at the end of the stream, of the last cloud with points), "
                 "then exit; works under Xvfb")
      ->type_name("FILE.png")
      ->group(viewer);
  app.add_option("--snapshot-after", f.snapshot_after,
                 "Clouds displayed (files: frames drawn) before --snapshot")
      ->check(
          NumberCheck("a whole number >= 1", [](double v) { return v >= 1 && v == std::floor(v); }))
      ->capture_default_str()
      ->type_name("N")
      ->group(viewer);
  app.add_flag("--exit-at-end", f.exit_at_end,
               "Close the window when the stream ends (default: keep showing the last cloud)")
      ->group(viewer);

  const std::string output = "Output";
  app.add_option("--record", f.record,
                 "Save every received cloud in DIR as cloud_<sequence>.<format> (created when "
                 "missing)")
      ->type_name("DIR")
      ->group(output);
  app.add_option("--record-format", f.record_format,
                 "pcd / ply (PCL's writers) or drc (the server's Draco bytes, not re-encoded)")
      ->check(CLI::IsMember({"pcd", "ply", "drc"}))
      ->capture_default_str()
      ->group(output);
  app.add_option("--json", f.json, "Write the final statistics as JSON")
      ->type_name("FILE")
      ->group(output);
  app.add_option("--progress", f.progress_s, "Seconds between progress lines; 0 = none")
      ->type_name("SECONDS")
      ->check(NumberCheck("a number of seconds >= 0", [](double v) { return v >= 0; }))
      ->capture_default_str()
      ->group(output);
  app.add_flag("--print-frames", f.print_frames,
               "Print one line per reply: sequence, points after each stage, Draco bytes, server "
               "stage times and end-to-end latency")
      ->group(output);
  app.add_flag("--quiet,-q", f.quiet, "Log only warnings and errors (the summary still prints)")
      ->group(output);

  for (CLI::Option* option : app.get_options()) {
    option->description(Wrap(option->get_description()));
  }
  return stage_flags;
}

sources::FrameKind InputKind(const Flags& f) {
  sources::FrameKind kind = sources::FrameKind::kDisparity;
  sources::ParseFrameKind(f.input, &kind);  // checked by --input's IsMember
  return kind;
}

// The StreamConfig the flags ask for. The camera is always sent (it belongs to the source);
// stage settings only when given, so that the server's configured defaults apply otherwise.
// Image files and videos carry no camera: they need --camera-preset or --focal (and --baseline
// for disparity and stereo input), since no data set's camera is assumed.
absl::StatusOr<StreamConfig> BuildConfig(const Flags& f, const cli::StageFlags& stages,
                                         const sources::SourceInfo& info) {
  const bool source_camera = info.kind == "tsukuba" || info.kind == "synthetic";
  const sources::FrameKind kind = InputKind(f);
  if (!source_camera && !stages.CameraGiven()) {
    return absl::InvalidArgumentError(fmt::format(
        "the camera of {} input ({}) is unknown: give --focal (and --cx/--cy if the principal "
        "point is not the image centre{}), or a preset (--camera-preset {})",
        f.input, info.kind, kind == sources::FrameKind::kDepth ? "" : "; --baseline too",
        absl::StrJoin(PresetNames(), "|")));
  }
  if (!source_camera && kind != sources::FrameKind::kDepth && !stages.Given("--camera-preset") &&
      !stages.Given("--baseline")) {
    return absl::InvalidArgumentError(fmt::format(
        "--input {} needs the stereo baseline: give --baseline (in the unit wanted for x, y and "
        "z; 1 gives z = focal / disparity, as PCL), or --camera-preset",
        f.input));
  }
  StreamConfig config = stages.GivenStageConfig();
  FrameSettings source;
  source.pipeline.camera = info.camera;
  // The source's camera with the camera flags on top (Apply cannot fail: each flag was checked).
  const FrameSettings camera = stages.Apply(source).value_or(source);
  SetCamera(camera.pipeline.camera, &config);
  // Unset, the principal point follows each frame's centre (PCL's rule), which stays right if
  // frames change size mid-stream.
  if (camera.cx) {
    config.mutable_camera()->set_cx(*camera.cx);
  } else {
    config.mutable_camera()->clear_cx();
  }
  if (camera.cy) {
    config.mutable_camera()->set_cy(*camera.cy);
  } else {
    config.mutable_camera()->clear_cy();
  }
  config.set_delivery(f.lossless ? v1::DELIVERY_ALL : v1::DELIVERY_LATEST);
  absl::StatusOr<std::uint64_t> cap = MaxCloudBytesFromKb(f.max_reply_kb, "--max-reply-kb");
  if (!cap.ok()) return cap.status();
  if (auto s = SetMaxCloudBytes(*cap, &config); !s.ok()) return s;
  if (f.stereo->AnyGiven()) *config.mutable_stereo() = f.stereo->GivenStereoConfig();
  return config;
}

// Opens the source the flags name, or the default one.
absl::StatusOr<std::unique_ptr<sources::FrameSource>> OpenSource(const Flags& f,
                                                                 const cli::StageFlags& stages) {
  sources::SourceSpec spec;
  spec.tsukuba_dir = f.tsukuba;
  spec.illumination = f.illumination;
  spec.globs = f.files->Given(cli::FileSort::kGlob);
  spec.videos = f.files->Given(cli::FileSort::kVideo);
  spec.stills = f.files->Given(cli::FileSort::kStill);
  if (!f.synthetic.empty()) ParseSize(f.synthetic, &spec.synthetic_width, &spec.synthetic_height);
  sources::SourceOptions options;
  options.kind = InputKind(f);
  options.loop = f.loop;
  // New Tsukuba's depth frames are made from its disparity with the camera the stream uses.
  if (auto camera = stages.Apply(FrameSettings{}); camera.ok()) {
    if (stages.Given("--focal")) options.focal = camera->pipeline.camera.fx;
    if (stages.Given("--baseline")) options.baseline = camera->pipeline.camera.baseline;
  }
  const bool by_default = spec.Given().empty();
  // Ten frames go by in a blink: the default source is endless, like the synthetic scene.
  if (by_default) options.loop = true;
  auto source = sources::OpenSource(spec, options);
  if (!source.ok()) return source.status();
  if (by_default && (*source)->info().kind == "tsukuba") {
    spdlog::info("no source given: New Tsukuba frames from {}, looped",
                 sources::DefaultTsukubaDir());
  } else if (by_default) {
    spdlog::info(
        "no source given and no New Tsukuba data at {} (set CLOUDCAST_DATA): synthetic scene "
        "{}x{}",
        sources::DefaultTsukubaDir(), sources::kDefaultSyntheticWidth,
        sources::kDefaultSyntheticHeight);
  }
  return sources::LimitFrames(*std::move(source), f.frames);
}

// One line per reply, for --print-frames (the demo's per-frame latency); stereo pairs add the
// server's rectify and match times, and a disparity map sent back is noted.
void PrintFrameLine(const Result& r, bool stereo) {
  const double latency_ms = std::chrono::duration<double, std::milli>(r.latency()).count();
  if (!r.ok()) {
    std::printf("frame %6llu  error: %s\n", static_cast<unsigned long long>(r.sequence),
                r.status.ToString().c_str());
  } else {
    const auto& c = r.reply.counts();
    const auto& t = r.reply.times();
    // A stereo pair's matching is most of its server time: it goes before the other stages.
    const std::string stereo_times =
        stereo ? fmt::format("rectify {:5.2f}  match {:6.2f}  ", t.rectify_us() / 1000.0,
                             t.match_us() / 1000.0)
               : std::string();
    std::printf(
        "frame %6llu  %7llu valid  %7llu passthrough  %6llu voxels  %6.1f KB  server "
        "decode %5.2f  %spipeline %5.2f  draco %5.2f ms  latency %6.2f ms%s\n",
        static_cast<unsigned long long>(r.sequence),
        static_cast<unsigned long long>(c.valid_points()),
        static_cast<unsigned long long>(c.after_passthrough()),
        static_cast<unsigned long long>(c.after_voxel_grid()), r.draco_bytes() / 1024.0,
        t.decode_us() / 1000.0, stereo_times.c_str(), t.pipeline_us() / 1000.0,
        t.encode_us() / 1000.0, latency_ms, r.reply.has_disparity() ? "  (+ disparity map)" : "");
  }
  std::fflush(stdout);
}

int Fail(const absl::Status& status) {
  spdlog::error("{}", std::string(status.message()));
  return kExitFailure;
}

bool WriteJson(const std::string& path, const Json& j) {
  std::ofstream file(path, std::ios::trunc);
  file << j.dump(2) << "\n";
  file.close();
  return static_cast<bool>(file);
}

// Logs StreamStats::ProgressLine every `period` until destroyed.
class ProgressReporter {
 public:
  ProgressReporter(StreamStats* stats, double period_s) {
    if (period_s <= 0) return;
    const auto period = std::chrono::duration_cast<std::chrono::milliseconds>(
        std::chrono::duration<double>(period_s));
    thread_ = std::thread([this, stats, period] {
      std::unique_lock<std::mutex> lock(mu_);
      while (!cv_.wait_for(lock, period, [this] { return stop_; })) {
        spdlog::info("{}", stats->ProgressLine());
      }
    });
  }
  ~ProgressReporter() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
  }

 private:
  std::mutex mu_;
  std::condition_variable cv_;
  bool stop_ = false;
  std::thread thread_;
};

ViewerOptions MakeViewerOptions(const Flags& f, bool exit_at_end) {
  ViewerOptions v;
  std::uint32_t w = 0, h = 0;
  if (ParseSize(f.window, &w, &h)) {  // checked by --window's SizeCheck
    v.window.width = static_cast<int>(w);
    v.window.height = static_cast<int>(h);
  }
  v.window.visible = !f.hidden;
  v.window.point_size = f.point_size;
  v.snapshot_path = f.snapshot;
  v.snapshot_after = f.snapshot_after;
  v.exit_at_end = exit_at_end;
  return v;
}

int Run(const Flags& f, const cli::StageFlags& stages) {
  // ---- local files: no server
  if (!f.open.empty()) {
    ViewerOptions v = MakeViewerOptions(f, false);
    v.window.title = "cloudcast: " + f.open.front();
    auto clouds = LoadCloudFiles(f.open);
    if (!clouds.ok()) return Fail(clouds.status());
    auto renderer = OpenWindow(v);
    if (!renderer.ok()) return Fail(renderer.status());
    absl::Status s = RunFileViewer(**renderer, f.open, *clouds, v, g_stop);
    return s.ok() ? 0 : Fail(s);
  }

  const bool windowed = !f.no_window;
  const bool interactive = windowed && !f.hidden && f.snapshot.empty();
  auto source = OpenSource(f, stages);
  if (!source.ok()) return Fail(source.status());
  const bool stereo = InputKind(f) == sources::FrameKind::kStereo;
  sources::FrameSource& src = **source;
  spdlog::info("source: {}{}", src.info().description, src.info().looped ? ", looped" : "");
  for (const std::string& w : src.info().warnings) spdlog::warn("{}", w);
  const bool endless = !src.info().frames_per_pass || src.info().looped;
  if (endless && f.frames == 0 && !interactive && f.snapshot.empty()) {
    spdlog::info("the source is endless: Ctrl-C (or --frames N) ends the stream");
  }

  std::optional<Recorder> recorder;
  if (!f.record.empty()) {
    auto r = Recorder::Create(f.record, f.record_format);
    if (!r.ok()) return Fail(r.status());
    recorder.emplace(*std::move(r));
    if (!f.lossless) {
      spdlog::info(
          "--record saves the clouds the server delivers; add --lossless to have every "
          "frame answered");
    }
  }

  SessionOptions options;
  options.server = f.server;
  options.security = f.security;
  options.connect_timeout = std::chrono::milliseconds(
      static_cast<std::int64_t>(std::llround(f.connect_timeout_s * 1000)));
  auto config = BuildConfig(f, stages, src.info());
  if (!config.ok()) return Fail(config.status());
  options.config = *std::move(config);
  options.fps = f.fps;
  options.max_in_flight = f.in_flight;
  if (f.rate_control) options.rate_control = f.rate->Options();
  sources::ParseUplink(f.encoding, &options.uplink.encoding);
  options.uplink.jpeg_quality = f.jpeg_quality;
  options.uplink.max_point_error = f.max_point_error;
  if (f.max_point_error > 0) {
    // The quantizer bounds the points of the camera the stream sends (BuildConfig).
    if (auto s = convert::ApplyCamera(options.config.camera(), "config.camera",
                                      &options.uplink.camera);
        !s.ok()) {
      return Fail(s);
    }
  }
  if (f.encoding == video::kH264) {
    // The images are taken raw from the source and coded by the session's FrameEncoder.
    options.uplink.encoding = sources::Uplink::kRaw;
    options.video = f.h264->Options(f.fps);
  }

  // The window opens first: without a display there is no point in connecting.
  std::unique_ptr<render::Renderer> renderer;
  // A hidden window nobody can close ends with its stream.
  const ViewerOptions viewer_options = MakeViewerOptions(f, f.exit_at_end || f.hidden);
  if (windowed) {
    auto r = OpenWindow(viewer_options);
    if (!r.ok()) return Fail(r.status());
    renderer = *std::move(r);
  }

  StreamStats stats;
  // With --fps 0 the display paces the stream (see CloudMailbox); a paced camera must not wait.
  CloudMailbox mailbox(/*wait_for_viewer=*/f.fps == 0);
  std::mutex record_mu;
  absl::Status record_status;
  // An empty cloud is said once per stage that emptied it, so a wrong camera or range is never
  // silent (the reply says which stage took the points and why).
  std::atomic<int> empty_stage{v1::STAGE_UNSPECIFIED};
  auto on_result = [&](Result& result) {
    if (result.status.ok() && result.reply.has_empty() &&
        empty_stage.exchange(result.reply.empty().stage()) != result.reply.empty().stage()) {
      spdlog::warn("frame {}: empty cloud: {}", result.reply.sequence(),
                   result.reply.empty().message());
    }
    if (f.print_frames) PrintFrameLine(result, stereo);
    if (recorder) {
      absl::Status s = recorder->Save(result);
      if (!s.ok()) {
        std::lock_guard<std::mutex> lock(record_mu);
        if (record_status.ok()) record_status = s;
        g_stop.store(true);
      }
    }
    if (windowed) mailbox.Put(result);
  };

  auto session = Session::Start(options, &src, &stats, on_result);
  if (!session.ok()) return Fail(session.status());
  spdlog::info("streaming {} frames to {}: {}, {} images, delivery {}", f.input, f.server,
               f.fps > 0 ? fmt::format("{} frames/s", f.fps)
                         : fmt::format("as fast as answered ({} in flight)", f.in_flight),
               f.encoding, f.lossless ? "all (lossless)" : "latest");

  absl::Status viewer_status;
  {
    ProgressReporter progress(&stats, f.quiet ? 0 : f.progress_s);
    if (windowed) {
      viewer_status = RunLiveViewer(*renderer, **session, mailbox, stats, viewer_options, g_stop);
      mailbox.Close();
    } else {
      while (!(*session)->WaitFor(std::chrono::milliseconds(100))) {
        if (g_stop.load()) (*session)->Stop();
      }
    }
  }
  absl::Status status = (*session)->Wait();
  {
    std::lock_guard<std::mutex> lock(record_mu);
    if (status.ok() && !record_status.ok()) status = record_status;
  }
  if (status.ok() && !viewer_status.ok()) status = viewer_status;
  session->reset();

  const StatsSnapshot snapshot = stats.Snapshot();
  std::string summary = "source: " + src.info().description +
                        (src.info().looped ? ", looped\n" : "\n") + "input: " + f.input +
                        (stereo ? " pairs, matched by the server\n" : " frames\n") +
                        StreamStats::SummaryText(snapshot, windowed);
  if (windowed) {
    summary +=
        fmt::format("viewer: {} clouds replaced before they were drawn\n", mailbox.skipped());
  }
  if (recorder) {
    summary += fmt::format("recorded: {} {} files in {}\n", recorder->files_written(),
                           recorder->format(), recorder->dir());
  }
  std::fputs(summary.c_str(), stdout);
  std::fflush(stdout);

  if (!f.json.empty()) {
    Json j;
    j["program"] = "cloudcast-client";
    j["status"] = status.ok() ? std::string("ok") : std::string(status.message());
    j["server"] = f.server;
    j["source"] = {{"kind", src.info().kind},
                   {"input", f.input},
                   {"description", src.info().description},
                   {"width", src.info().width},
                   {"height", src.info().height}};
    if (src.info().frames_per_pass) j["source"]["frames_per_pass"] = *src.info().frames_per_pass;
    j["settings"] = {{"fps", f.fps},
                     {"in_flight", f.in_flight},
                     {"delivery", f.lossless ? "all" : "latest"},
                     {"encoding", f.encoding},
                     {"input", f.input},
                     {"window", windowed}};
    j.update(StreamStats::ToJson(snapshot, windowed));
    if (windowed) j["viewer_skipped"] = mailbox.skipped();
    if (recorder) {
      j["record"] = {{"dir", recorder->dir()},
                     {"format", recorder->format()},
                     {"files", recorder->files_written()}};
    }
    if (!WriteJson(f.json, j)) {
      spdlog::error("--json {}: cannot write the file", f.json);
      return kExitFailure;
    }
  }
  return status.ok() ? 0 : Fail(status);
}

}  // namespace

int ClientMain(int argc, char** argv) {
  Flags f;
  CLI::App app(
      "cloudcast-client: streams frames to a cloudcast server (--input: disparity + colour,\n"
      "depth + colour, or a rectified stereo pair the server matches) and shows the filtered\n"
      "point clouds it sends back, live, in an OpenGL window; or records them, or just measures\n"
      "the stream. It also opens local .pcd/.ply/.drc files.\n\n"
      "Default source: the New Tsukuba frames in $CLOUDCAST_DATA, else ../shared/data/new_tsukuba\n"
      "next to the checkout (looped), else the synthetic scene 640x480: endless either way.\n"
      "The camera always goes with the stream; stage flags left out take the server's defaults\n"
      "(shown below as they are out of the box).\n\n"
      "Examples:\n"
      "  cloudcast-server &                                  # serves on :50051\n"
      "  cloudcast-client                                    # live view of the default source\n"
      "  cloudcast-client --tsukuba ../shared/data/new_tsukuba --loop --fps 30\n"
      "  cloudcast-client --tsukuba ../shared/data/new_tsukuba --input stereo --matcher sgbm\n"
      "  cloudcast-client --input depth --depth-glob 'depth/*.png' --colour-glob 'rgb/*.png' \\\n"
      "    --focal 525 --cx 319.5 --cy 239.5\n"
      "  cloudcast-client --synthetic 1280x720 --leaf 0.05 --encoding jpeg\n"
      "  cloudcast-client --disparity-glob 'd/*.png' --colour-glob 'c/*.png' --lossless \\\n"
      "    --record out --record-format drc --no-window --json stats.json\n"
      "  cloudcast-client --disparity-video d.mkv --colour-video c.mkv --loop\n"
      "  xvfb-run -a cloudcast-client --frames 30 --snapshot view.png\n"
      "  cloudcast-client --open frame.pcd other.ply cloud.drc\n",
      "cloudcast-client");
  app.footer(
      "Keys: mouse drag orbits (left) or pans (right), wheel zooms, space pauses, r resets the\n"
      "view, +/- point size, s screenshot, arrows next/previous file (--open), q or Esc quits.\n"
      "Exit status: 0 success, 1 failure while running (server, files, stream), 2 usage error.");
  app.get_formatter()->column_width(34);
  const std::unique_ptr<cli::StageFlags> stages = AddFlags(app, f);
  const cli::ConnectionFlags connection(app);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // CLI11's own exit codes are 100+; usage errors are 2 here, as for most Unix tools.
    return app.exit(e) == 0 ? 0 : kExitUsage;
  }

  auto usage = [](const std::string& message) {
    std::fprintf(stderr, "cloudcast-client: %s\nRun with --help for more information.\n",
                 message.c_str());
    return kExitUsage;
  };
  // One source at most; a sort of files (globs, videos, stills) gives every image of the kind.
  const sources::FrameKind kind = InputKind(f);
  std::vector<std::string> given;
  for (const char* single : {"--tsukuba", "--synthetic", "--open"}) {
    if (app.count(single) > 0) given.emplace_back(single);
  }
  absl::StatusOr<std::vector<std::string>> files = f.files->Check(kind);
  if (!files.ok()) return usage(std::string(files.status().message()));
  given.insert(given.end(), files->begin(), files->end());
  if (given.size() > 1) {
    return usage(fmt::format("choose one source: {} and {} were both given", given[0], given[1]));
  }
  if (kind != sources::FrameKind::kStereo && f.stereo->AnyGiven()) {
    return usage(
        fmt::format("{} applies to --input stereo only (the server matches stereo "
                    "pairs; this is --input {})",
                    f.stereo->GivenFlags().front(), f.input));
  }
  if (absl::Status s = f.stereo->Check(); !s.ok()) return usage(std::string(s.message()));
  if (f.encoding != video::kH264 && f.h264->AnyGiven()) {
    return usage(f.h264->GivenFlags().front() + " needs --encoding h264");
  }
  if (absl::Status s = f.rate->Check(f.rate_control); !s.ok()) {
    return usage(std::string(s.message()));
  }
  if (f.rate_control && f.lossless) {
    return usage(
        "--rate-control needs DELIVERY_LATEST (a frame past the window is replaced by "
        "a newer one): drop --lossless");
  }
  if (f.no_window) {
    for (const char* flag : {"--open", "--snapshot", "--hidden", "--window"}) {
      if (app.count(flag) > 0)
        return usage(fmt::format("{} needs a window: drop --no-window", flag));
    }
  }
  if (auto s = stages->Apply(FrameSettings{}); !s.ok()) {
    return usage(std::string(s.status().message()));
  }
  if (auto security = connection.Security(); security.ok()) {
    f.security = *std::move(security);
  } else {
    return usage(std::string(security.status().message()));
  }
  if (!f.open.empty()) {
    for (const char* flag : {"--record", "--json", "--lossless", "--fps", "--frames", "--loop",
                             "--server", "--input"}) {
      if (app.count(flag) > 0) return usage(fmt::format("{} does not apply to --open", flag));
    }
  }
  if (!f.snapshot.empty()) {
    std::string ext = std::filesystem::path(f.snapshot).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return std::tolower(c); });
    if (ext != ".png") return usage("--snapshot " + f.snapshot + ": the file must end in .png");
  }
  for (const auto& [flag, path] :
       {std::pair<const char*, const std::string&>{"--json", f.json}, {"--snapshot", f.snapshot}}) {
    if (std::string m = MissingFolder(flag, path); !m.empty()) return usage(m);
  }

  auto logger = spdlog::stderr_color_mt("cloudcast-client");
  logger->set_pattern("%n: %^%l%$: %v");
  logger->set_level(f.quiet ? spdlog::level::warn : spdlog::level::info);
  spdlog::set_default_logger(logger);

  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  return Run(f, *stages);
}

}  // namespace cloudcast::client::app
