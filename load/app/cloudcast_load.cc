// cloudcast-load: a fleet of camera streams against a cloudcast server or a replica set, with
// latency measured from each frame's intended send time (no coordinated omission). See
// load/include/cloudcast/load/fleet.h for how the schedule works, and README.md for the figures.
//
// SIGINT / SIGTERM end the run cleanly: no more frames are sent, answers still due are awaited
// (--drain-timeout), and the report is written as usual. A second signal exits at once.
#include <pthread.h>
#include <signal.h>
#include <spdlog/fmt/fmt.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <thread>

#include "cloudcast/cli/checks.h"
#include "cloudcast/cli/connection_flags.h"
#include "cloudcast/cli/rate_flags.h"
#include "cloudcast/cli/role_flags.h"
#include "cloudcast/cli/stage_flags.h"
#include "cloudcast/cli/stereo_flags.h"
#include "cloudcast/cli/video_flags.h"
#include "cloudcast/client/config.h"
#include "cloudcast/core/limits.h"
#include "cloudcast/load/fleet.h"
#include "cloudcast/load/frame_log.h"
#include "cloudcast/load/frame_store.h"
#include "cloudcast/load/memory_watch.h"
#include "cloudcast/load/probe.h"
#include "cloudcast/load/report.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/v1/cloudcast.grpc.pb.h"

namespace {

using cloudcast::cli::NumberCheck;
using cloudcast::cli::Wrap;
namespace load = cloudcast::load;

constexpr int kExitFailure = 1;
constexpr int kExitUsage = 2;
constexpr int kExitSoakFailed = 3;
// Hard bounds on a run, whatever the flags say.
constexpr double kMaxDurationS = 3600;
constexpr double kMaxFrames = 1e8;

// The defaults of the flags: those of the options structs they fill, so each is written once.
const load::FleetOptions& FleetDefaults() {
  static const load::FleetOptions o;
  return o;
}
const load::FrameSourceOptions& FrameDefaults() {
  static const load::FrameSourceOptions o;
  return o;
}

double Seconds(std::chrono::nanoseconds d) { return std::chrono::duration<double>(d).count(); }

struct Flags {
  std::string server = FleetDefaults().server;
  double connect_timeout_s = Seconds(FleetDefaults().connect_timeout);
  bool probe = false;
  std::string probe_service = cloudcast::v1::CloudCast::service_full_name();
  std::string lb = FleetDefaults().lb_policy;
  bool resilient = FleetDefaults().resilient;
  double reconnect_timeout_s = Seconds(FleetDefaults().reconnect_timeout);
  int streams = FleetDefaults().streams;
  int connections = FleetDefaults().connections;
  double fps = FleetDefaults().schedule.start;
  double max_reply_kb = 0;  // the downlink cap (DracoConfig.max_cloud_bytes), kB; 0 = none
  int in_flight = FleetDefaults().in_flight;
  std::string schedule = std::string(load::Name(FleetDefaults().schedule.kind));
  double load_start = 0;  // unset: --fps
  double load_step = FleetDefaults().schedule.step, load_end = FleetDefaults().schedule.end;
  double load_step_duration_s = Seconds(FleetDefaults().schedule.step_duration);
  double duration_s = Seconds(FleetDefaults().duration);
  double frames = static_cast<double>(FleetDefaults().frames);
  double drain_timeout_s = Seconds(FleetDefaults().drain_timeout);
  std::uint64_t seed = FleetDefaults().seed;
  int scheduler_threads = FleetDefaults().scheduler_threads;
  // Frames
  std::string input = cloudcast::cli::kDefaultInput;
  std::string tsukuba, synthetic;
  // --disparity-glob, --colour-glob, --depth-glob, --right-glob
  std::unique_ptr<cloudcast::cli::RoleFlags> globs;
  std::unique_ptr<cloudcast::cli::StereoFlags> stereo;
  std::string illumination = FrameDefaults().source.illumination;
  int synthetic_frames = FrameDefaults().synthetic_frames;
  std::string encoding = cloudcast::sources::Name(FrameDefaults().uplink.encoding);
  int jpeg_quality = FrameDefaults().uplink.jpeg_quality;
  double max_point_error = FrameDefaults().uplink.max_point_error;  // metres; 0 = lossless
  std::unique_ptr<cloudcast::cli::VideoFlags> h264;  // --h264-*, as cloudcast-client's
  std::unique_ptr<cloudcast::cli::RateFlags> rate;   // --rate-*, as cloudcast-client's
  bool rate_control = false;
  bool lossless = false;
  // Server memory and the soak
  std::string watch_memory;
  double memory_interval_s = 5;
  bool soak = false;
  double soak_warmup_s = load::SoakBounds{}.warmup_s;
  double soak_max_growth_mb = load::SoakBounds{}.max_growth_bytes / 1e6;
  // Output
  std::string json, html, frame_log;
  double progress_s = 1;
  bool quiet = false;
};

std::string MissingFolder(const std::string& flag, const std::string& path) {
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  std::error_code ec;
  if (!path.empty() && !parent.empty() && !std::filesystem::is_directory(parent, ec)) {
    return fmt::format("{} {}: folder '{}' does not exist", flag, path, parent.string());
  }
  return "";
}

std::unique_ptr<cloudcast::cli::StageFlags> AddFlags(CLI::App& app, Flags& f) {
  const std::string target = "Target";
  app.add_option("--server", f.server,
                 "The server or load balancer, any gRPC target (HOST:PORT, dns:///name:port, "
                 "ipv4:a:p,b:p ...)")
      ->capture_default_str()
      ->type_name("TARGET")
      ->group(target);
  app.add_option("--connect-timeout", f.connect_timeout_s,
                 "Seconds to wait for every channel to connect (and for --probe)")
      ->check(NumberCheck("a number of seconds in (0, 600]",
                          [](double v) { return v > 0 && v <= 600; }))
      ->capture_default_str()
      ->group(target);
  app.add_flag("--probe", f.probe,
               "Only check the server's gRPC health (grpc.health.v1) for --probe-service: exit 0 "
               "when SERVING, 1 otherwise (a container HEALTHCHECK)")
      ->group(target);
  app.add_option("--probe-service", f.probe_service, "The health service name --probe asks for")
      ->capture_default_str()
      ->group(target);
  app.add_option("--lb", f.lb,
                 "gRPC load balancing over the target's addresses: round_robin (with health "
                 "checking: a draining replica gets no new streams) or pick_first. Default: "
                 "round_robin for a dns:/// target or a list of addresses (ipv4:a:p,b:p), else "
                 "pick_first")
      ->check(CLI::IsMember({"round_robin", "pick_first"}))
      ->group(target);
  app.add_flag("--resilient", f.resilient,
               "A stream whose call ends with UNAVAILABLE (replica killed, drained, GOAWAY) or an "
               "unasked-for CANCELLED (a server stopping as the call opened) opens "
               "a new one, sends its config again and, with --lossless, every frame sent and not "
               "answered (latency still counts from the intended time); answers count once per "
               "frame")
      ->group(target);
  app.add_option("--reconnect-timeout", f.reconnect_timeout_s,
                 "With --resilient: seconds without a working call before a stream gives up and "
                 "reports its unanswered frames lost")
      ->check(NumberCheck("a number of seconds in (0, 600]",
                          [](double v) { return v > 0 && v <= 600; }))
      ->capture_default_str()
      ->group(target);

  const std::string load_group = "Load";
  app.add_option("--streams", f.streams, "Concurrent Stream calls (robots)")
      ->check(CLI::Range(1, 10000))
      ->capture_default_str()
      ->group(load_group);
  app.add_option("--connections", f.connections,
                 "gRPC channels (TCP connections) the streams share, round robin; 0 = one per "
                 "stream")
      ->check(CLI::Range(0, 10000))
      ->capture_default_str()
      ->group(load_group);
  app.add_option("--fps", f.fps,
                 "Frames per second per stream, open loop: every frame has an intended send time "
                 "fixed before the run; 0 = closed loop with --in-flight frames awaiting replies")
      ->check(NumberCheck("a rate in [0, 10000]", [](double v) { return v >= 0 && v <= 1e4; }))
      ->capture_default_str()
      ->group(load_group);
  app.add_option("--in-flight", f.in_flight,
                 "Closed loop (--fps 0): frames awaiting their reply per stream")
      ->check(CLI::Range(1, 64))
      ->capture_default_str()
      ->group(load_group);
  app.add_option("--max-reply-kb", f.max_reply_kb,
                 "Downlink cap: each reply's cloud at most this many kB (1000 bytes), met by the "
                 "server's Draco bits within the error bound (cloudcast-client --help); 0 = none")
      ->capture_default_str()
      ->group(load_group);
  app.add_option("--schedule", f.schedule,
                 "Rate over time (as ghz's --load-schedule): const (--fps), step (--load-start, "
                 "+--load-step every --load-step-duration up to --load-end) or line (+--load-step "
                 "per second); rates are per stream")
      ->check(CLI::IsMember({"const", "step", "line"}))
      ->capture_default_str()
      ->group(load_group);
  app.add_option("--load-start", f.load_start,
                 "First rate of a step/line ramp, fps per stream [default: --fps]")
      ->check(NumberCheck("a rate in (0, 10000]", [](double v) { return v > 0 && v <= 1e4; }))
      ->group(load_group);
  app.add_option("--load-step", f.load_step,
                 "Ramp step (step) or slope per second (line), fps per stream")
      ->check(
          NumberCheck("a rate in [-10000, 10000]", [](double v) { return std::fabs(v) <= 1e4; }))
      ->group(load_group);
  app.add_option("--load-end", f.load_end, "The rate where a ramp stops changing; 0 = none")
      ->check(NumberCheck("a rate in [0, 10000]", [](double v) { return v >= 0 && v <= 1e4; }))
      ->group(load_group);
  app.add_option("--load-step-duration", f.load_step_duration_s, "Seconds per step of a step ramp")
      ->check(NumberCheck("a number of seconds in [0.001, 3600]",
                          [](double v) { return v >= 0.001 && v <= 3600; }))
      ->capture_default_str()
      ->group(load_group);
  app.add_option("--duration", f.duration_s,
                 fmt::format("Seconds during which frames are due; 0 = bounded by --frames only "
                             "(at most {:g})",
                             kMaxDurationS))
      ->check(NumberCheck(fmt::format("a number of seconds in [0, {:g}]", kMaxDurationS),
                          [](double v) { return v >= 0 && v <= kMaxDurationS; }))
      ->capture_default_str()
      ->group(load_group);
  app.add_option("--frames", f.frames,
                 fmt::format("Frames in all, shared out over the streams; 0 = bounded by "
                             "--duration only (at most {:g})",
                             kMaxFrames))
      ->check(NumberCheck(fmt::format("a whole number in [0, {:g}]", kMaxFrames),
                          [](double v) { return v >= 0 && v <= kMaxFrames && v == std::floor(v); }))
      ->type_name("N")
      ->group(load_group);
  app.add_option("--drain-timeout", f.drain_timeout_s,
                 "Seconds to wait for answers after the last frame is due (or after a stop); then "
                 "the calls are cancelled")
      ->check(NumberCheck("a number of seconds in [0, 600]",
                          [](double v) { return v >= 0 && v <= 600; }))
      ->capture_default_str()
      ->group(load_group);
  app.add_option("--seed", f.seed, "Seed of the streams' random phases")
      ->capture_default_str()
      ->group(load_group);
  app.add_option("--scheduler-threads", f.scheduler_threads,
                 "Threads that send frames at their intended times (streams are shared out)")
      ->check(CLI::Range(1, 16))
      ->capture_default_str()
      ->group(load_group);

  const std::string frames =
      "Frames (prepared before the run; default: New Tsukuba when present, else synthetic 640x480)";
  cloudcast::cli::AddInputFlag(app, &f.input, cloudcast::sources::FrameKindNames(), frames);
  app.add_option("--tsukuba", f.tsukuba,
                 "A New Tsukuba folder (every frame in it): --input stereo sends its left + right "
                 "images, --input depth its ground truth as float depth")
      ->type_name("DIR")
      ->group(frames);
  app.add_option("--illumination", f.illumination, "New Tsukuba illumination folder")
      ->capture_default_str()
      ->group(frames);
  f.globs = std::make_unique<cloudcast::cli::RoleFlags>(
      app, std::vector<cloudcast::cli::FileSort>{cloudcast::cli::FileSort::kGlob}, frames);
  app.add_option("--synthetic", f.synthetic,
                 "The synthetic scene at WIDTHxHEIGHT, as frames of --input")
      ->check(
          cloudcast::cli::SizeCheck(cloudcast::Limits{}.max_side, cloudcast::Limits{}.max_pixels))
      ->type_name("WxH")
      ->group(frames);
  app.add_option("--synthetic-frames", f.synthetic_frames,
                 "Distinct synthetic frames (camera poses)")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str()
      ->group(frames);
  std::vector<std::string> encodings = cloudcast::sources::UplinkNames();
  encodings.emplace_back(cloudcast::video::kH264);
  app.add_option("--encoding", f.encoding,
                 "How images travel: raw pixels; zstd (lossless: row deltas + zstd, cheap for "
                 "the server); png (lossless: PNG, float disparities and depths TIFF); jpeg "
                 "(colour images JPEG, disparity and depth as png); h264 (the colour image, or "
                 "both views of a stereo pair, as H.264 video, encoded once before the run into "
                 "a picture sequence each stream plays in order from an IDR, or with "
                 "--rate-control live by each stream; disparity and depth lossless, zstd; "
                 "--h264-* flags)")
      ->check(CLI::IsMember(encodings))
      ->capture_default_str()
      ->group(frames);
  app.add_option("--jpeg-quality", f.jpeg_quality, "JPEG quality with --encoding jpeg")
      ->check(CLI::Range(1, 100))
      ->capture_default_str()
      ->group(frames);
  app.add_option("--max-point-error", f.max_point_error,
                 "Near-lossless disparity and depth, as cloudcast-client's: each value may change "
                 "as long as the point the server makes from it moves by at most this many "
                 "metres (per point, in the camera's optical frame, before any filter; e.g. a "
                 "quarter of the voxel leaf), quantized per frame with the camera the server "
                 "processes it with (the stream's; a half-resolution frame's own, halved). "
                 "Shrinks the compressed geometry of --encoding zstd, png, jpeg, h264 and "
                 "--rate-control; not for raw or --input stereo. The report gives the bytes with "
                 "and without. 0 = lossless")
      ->check(NumberCheck("a distance in metres, finite and >= 0",
                          [](double v) { return std::isfinite(v) && v >= 0; }))
      ->capture_default_str()
      ->group(frames);
  f.h264 = std::make_unique<cloudcast::cli::VideoFlags>(app, frames);
  app.add_flag("--rate-control", f.rate_control,
               "The adaptive sender, as robots on real links should send: each stream's rate "
               "controller (delay-based, from the replies' timing and the server's byte count) "
               "sets how many frames may be in flight and the bitrate each frame is made at: "
               "disparity and depth lossless (zstd), colour JPEG at the best quality of a ladder "
               "(95 to 10) that fits the target. Replaces --encoding and --jpeg-quality, "
               "except --encoding h264: then each stream encodes its frames live at its "
               "controller's bitrate (an encoder per stream, as a robot runs: for a few streams, "
               "the encoders' CPU is the generator's)")
      ->group(frames);
  f.rate = std::make_unique<cloudcast::cli::RateFlags>(app, frames);
  app.add_flag("--lossless", f.lossless,
               "Every frame is answered (DELIVERY_ALL). Default: DELIVERY_LATEST, the server "
               "skips stale frames (counted as drops)")
      ->group(frames);

  const std::string stages = "Camera and stages (stage flags left out: the server's defaults)";
  auto stage_flags = std::make_unique<cloudcast::cli::StageFlags>(
      app, cloudcast::cli::StageFlags::Groups{stages, stages, stages},
      cloudcast::convert::ContractDefaults().frame);  // what a server has out of the box
  f.stereo = std::make_unique<cloudcast::cli::StereoFlags>(
      app, "Stereo matcher (--input stereo; flags left out: the server's defaults)");

  const std::string soak = "Server memory and soak";
  app.add_option("--watch-memory", f.watch_memory,
                 "Sample the server's resident memory from its Prometheus endpoint "
                 "(cloudcast_process_resident_memory_bytes) every --memory-interval seconds, "
                 "into the report")
      ->type_name("URL")
      ->group(soak);
  app.add_option("--memory-interval", f.memory_interval_s, "Seconds between memory samples")
      ->check(NumberCheck("a number of seconds in [0.1, 600]",
                          [](double v) { return v >= 0.1 && v <= 600; }))
      ->capture_default_str()
      ->group(soak);
  app.add_flag("--soak", f.soak,
               "Judge the run as a soak (needs --watch-memory): exit 3 when any frame is lost, "
               "unsent or answered with an error (with --lossless: when any frame is not "
               "answered), or when the memory after --soak-warmup rises more than "
               "--soak-max-growth-mb above its value at the end of the warm-up")
      ->group(soak);
  app.add_option("--soak-warmup", f.soak_warmup_s,
                 "Seconds of warm-up: memory growth counts from the last sample before this")
      ->check(NumberCheck("a number of seconds in [0, 3600]",
                          [](double v) { return v >= 0 && v <= 3600; }))
      ->capture_default_str()
      ->group(soak);
  app.add_option("--soak-max-growth-mb", f.soak_max_growth_mb,
                 "Allowed rise of the server's memory after the warm-up, MB")
      ->check(
          NumberCheck("a number of MB in [0, 1e6]", [](double v) { return v >= 0 && v <= 1e6; }))
      ->capture_default_str()
      ->group(soak);

  const std::string output = "Output";
  app.add_option("--json", f.json, "Write the report in ghz's JSON shape (plus per-frame fields)")
      ->type_name("FILE")
      ->group(output);
  app.add_option("--html", f.html, "Write the report as one self-contained HTML page")
      ->type_name("FILE")
      ->group(output);
  app.add_option("--frame-log", f.frame_log,
                 "Write a CSV line per answered frame: the load's write and receipt and the "
                 "server's receipt and send (Unix ns), bytes each way, points, the server's "
                 "stage times, the reply cap: which way a late frame waited "
                 "(docs/load-testing.md)")
      ->type_name("FILE")
      ->group(output);
  app.add_option("--progress", f.progress_s, "Seconds between progress lines on stderr; 0 = none")
      ->check(NumberCheck("0 or 1", [](double v) { return v == 0 || v == 1; }))
      ->capture_default_str()
      ->group(output);
  app.add_flag("--quiet,-q", f.quiet, "No progress lines (the report still prints)")->group(output);
  for (CLI::Option* option : app.get_options())
    option->description(Wrap(option->get_description()));
  return stage_flags;
}

// The signal thread's target: set once the fleet exists.
std::atomic<load::Fleet*> g_fleet{nullptr};
std::atomic<bool> g_stop{false};

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "cloudcast-load: a fleet of camera streams against a cloudcast server or a load-balanced "
      "replica set. Open loop: latency counts from each frame's intended send time, so a slow "
      "server cannot hide behind a slowed sender (no coordinated omission)."};
  Flags f;
  auto stages = AddFlags(app, f);
  const cloudcast::cli::ConnectionFlags connection(app);
  CLI11_PARSE(app, argc, argv);
  auto security = connection.Security();
  if (!security.ok()) {
    std::cerr << "cloudcast-load: " << security.status().message() << "\n";
    return kExitUsage;
  }

  if (f.probe) {
    const absl::Status s = load::ProbeHealth(
        f.server, f.probe_service,
        std::chrono::milliseconds(static_cast<std::int64_t>(f.connect_timeout_s * 1000)),
        *security);
    if (!s.ok()) {
      std::cerr << "cloudcast-load --probe: " << s.message() << "\n";
      return kExitFailure;
    }
    std::cout << f.server << ": " << f.probe_service << " is SERVING\n";
    return 0;
  }

  auto usage = [](const std::string& message) {
    std::cerr << "cloudcast-load: " << message << "\n";
    return kExitUsage;
  };
  using cloudcast::sources::FrameKind;
  FrameKind kind = FrameKind::kDisparity;
  cloudcast::sources::ParseFrameKind(f.input, &kind);  // checked by IsMember
  absl::StatusOr<std::vector<std::string>> globs = f.globs->Check(kind);
  if (!globs.ok()) return usage(std::string(globs.status().message()));
  const bool any_glob = !globs->empty();
  const int sources = !f.tsukuba.empty() + any_glob + !f.synthetic.empty();
  if (sources > 1) return usage("give one of --tsukuba, the globs, --synthetic");
  if (kind != FrameKind::kStereo && f.stereo->AnyGiven()) {
    return usage(f.stereo->GivenFlags().front() + " applies to --input stereo only (this is " +
                 "--input " + f.input + ")");
  }
  if (absl::Status s = f.stereo->Check(); !s.ok()) return usage(std::string(s.message()));
  if (f.duration_s == 0 && f.frames == 0) {
    return usage("--duration 0 needs --frames N: a run must be bounded");
  }
  for (const auto& [flag, path] : {std::pair<std::string, std::string>{"--json", f.json},
                                   {"--html", f.html},
                                   {"--frame-log", f.frame_log}}) {
    if (const std::string m = MissingFolder(flag, path); !m.empty()) return usage(m);
  }
  const bool ramp = f.schedule != "const";
  if (!ramp && (app.count("--load-step") || app.count("--load-end"))) {
    return usage("--load-step and --load-end need --schedule step or line");
  }
  if (ramp && f.fps == 0)
    return usage("--schedule " + f.schedule + " needs an open loop (--fps > 0)");
  if (f.fps == 0 && app.count("--load-start")) return usage("--load-start needs --fps > 0");
  if (app.count("--reconnect-timeout") && !f.resilient) {
    return usage("--reconnect-timeout needs --resilient");
  }
  if (f.soak && f.watch_memory.empty()) {
    return usage(
        "--soak needs --watch-memory URL (the server's /metrics, e.g. "
        "http://127.0.0.1:9464/metrics)");
  }
  for (const char* flag : {"--memory-interval", "--soak-warmup", "--soak-max-growth-mb"}) {
    const bool needs_soak = std::string(flag) != "--memory-interval";
    if (app.count(flag) && (needs_soak ? !f.soak : f.watch_memory.empty())) {
      return usage(std::string(flag) + (needs_soak ? " needs --soak" : " needs --watch-memory"));
    }
  }
  if (!f.watch_memory.empty()) {
    // Checked before the run, so a wrong URL is a usage error and not a failed soak.
    if (auto rss = load::MemoryWatch::Scrape(f.watch_memory); !rss.ok()) {
      return usage("--watch-memory " + std::string(rss.status().message()));
    }
  }
  if (absl::Status s = f.rate->Check(f.rate_control); !s.ok()) {
    return usage(std::string(s.message()));
  }
  const bool h264 = f.encoding == cloudcast::video::kH264;
  if (f.rate_control && ((app.count("--encoding") && !h264) || app.count("--jpeg-quality"))) {
    return usage(
        "--rate-control chooses the encoding itself (a JPEG ladder), or encodes H.264 live with "
        "--encoding h264; leave out --encoding " +
        f.encoding + " and --jpeg-quality");
  }
  if (!h264 && f.h264->AnyGiven()) {
    return usage(f.h264->GivenFlags().front() + " needs --encoding h264");
  }
  if (h264 && f.resilient) {
    return usage(
        "--resilient does not take --encoding h264 yet: a new call's decoders start at "
        "an IDR, and the frames resent on it reference pictures the lost call decoded");
  }
  if (f.fps > 0 && app.count("--in-flight")) {
    return usage("--in-flight is for the closed loop (--fps 0); open loop sends on schedule");
  }

  load::FrameSourceOptions source;
  source.source.tsukuba_dir = f.tsukuba;
  source.source.illumination = f.illumination;
  source.source.globs = f.globs->Given(cloudcast::cli::FileSort::kGlob);
  source.kind = kind;
  // New Tsukuba's depth frames are made from its disparity with the camera the stream uses.
  if (auto camera = stages->Apply(cloudcast::FrameSettings{}); camera.ok()) {
    if (stages->Given("--focal")) source.focal = camera->pipeline.camera.fx;
    if (stages->Given("--baseline")) source.baseline = camera->pipeline.camera.baseline;
  }
  if (!f.synthetic.empty()) {
    cloudcast::cli::ParseSize(f.synthetic, &source.source.synthetic_width,
                              &source.source.synthetic_height);
  }
  source.synthetic_frames = f.synthetic_frames;
  cloudcast::sources::ParseUplink(f.encoding, &source.uplink.encoding);
  // The encoder's one-frame VBV is bitrate / fps: the schedule's starting rate.
  const double schedule_fps = app.count("--load-start") ? f.load_start : f.fps;
  if (h264) source.video = f.h264->Options(schedule_fps);
  source.uplink.jpeg_quality = f.jpeg_quality;
  source.uplink.max_point_error = f.max_point_error;
  // The StreamConfig's camera: the source's, the stage flags over it. Made while the frames are
  // prepared, so that near-lossless frames are quantized for it (and the half-resolution
  // levels get it halved).
  source.stream_camera =
      [&stages](const cloudcast::CameraModel& camera) -> absl::StatusOr<cloudcast::v1::CameraModel> {
    cloudcast::FrameSettings camera_settings;
    camera_settings.pipeline.camera = camera;
    auto applied = stages->Apply(camera_settings);
    if (!applied.ok()) return applied.status();
    cloudcast::v1::StreamConfig config = stages->GivenStageConfig();
    cloudcast::convert::SetCamera(applied->pipeline.camera, &config);
    if (applied->cx)
      config.mutable_camera()->set_cx(*applied->cx);
    else
      config.mutable_camera()->clear_cx();
    if (applied->cy)
      config.mutable_camera()->set_cy(*applied->cy);
    else
      config.mutable_camera()->clear_cy();
    return config.camera();
  };
  if (f.rate_control && h264) {
    source.live_video = true;  // each stream encodes at its controller's bitrate
  } else if (f.rate_control) {
    source.jpeg_ladder = {95, 90, 80, 70, 60, 50, 40, 30, 20, 10};
    source.half_resolution_ladder = {90, 70, 50, 30, 10};
  }

  load::FleetOptions o;
  o.security = *security;
  o.server = f.server;
  o.streams = f.streams;
  o.connections = f.connections;
  o.closed_loop = f.fps == 0;
  o.in_flight = f.in_flight;
  load::ParseScheduleKind(f.schedule, &o.schedule.kind);
  o.schedule.start = app.count("--load-start") ? f.load_start : f.fps;
  o.schedule.step = f.load_step;
  o.schedule.end = f.load_end;
  o.schedule.step_duration =
      std::chrono::nanoseconds(static_cast<std::int64_t>(f.load_step_duration_s * 1e9));
  o.duration = std::chrono::nanoseconds(static_cast<std::int64_t>(f.duration_s * 1e9));
  o.frames = static_cast<std::uint64_t>(f.frames);
  o.connect_timeout =
      std::chrono::nanoseconds(static_cast<std::int64_t>(f.connect_timeout_s * 1e9));
  o.drain_timeout = std::chrono::nanoseconds(static_cast<std::int64_t>(f.drain_timeout_s * 1e9));
  o.seed = f.seed;
  o.scheduler_threads = f.scheduler_threads;
  o.lb_policy = f.lb;
  o.resilient = f.resilient;
  if (f.rate_control) o.rate_control = f.rate->Options();
  o.reconnect_timeout =
      std::chrono::nanoseconds(static_cast<std::int64_t>(f.reconnect_timeout_s * 1e9));
  std::string schedule_text =
      "closed loop, " + std::to_string(f.in_flight) + " in flight per stream";
  if (!o.closed_loop) {
    auto schedule = load::Schedule::Create(o.schedule);
    if (!schedule.ok()) return usage(std::string(schedule.status().message()));
    schedule_text = schedule->Describe();
  }

  auto t_prepare = std::chrono::steady_clock::now();
  auto store = load::FrameStore::Prepare(source);
  if (!store.ok()) return usage(std::string(store.status().message()));
  const double prepare_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t_prepare).count();
  if (const auto& n = store->near_lossless();
      n && n->geometry_bytes >= n->geometry_bytes_lossless && !f.quiet) {
    // e.g. New Tsukuba's whole-pixel disparity (a step moves a point further than the bound), or
    // a float map sent as TIFF (uncompressed) by --encoding png and jpeg.
    std::fprintf(stderr,
                 "cloudcast-load: note: --max-point-error %g saved nothing on these frames (%s "
                 "%.1f KB a frame either way, %.0f%% of its values changed)\n",
                 n->max_point_error, n->geometry.c_str(), n->geometry_bytes / 1024,
                 n->values > 0 ? 100.0 * static_cast<double>(n->changed) /
                                     static_cast<double>(n->values)
                               : 0.0);
  }

  // The StreamConfig: the stage flags given, the stream's camera (made with the frames), the
  // delivery mode.
  o.config = stages->GivenStageConfig();
  *o.config.mutable_camera() = *store->stream_camera();
  o.config.set_delivery(f.lossless ? cloudcast::v1::DELIVERY_ALL : cloudcast::v1::DELIVERY_LATEST);
  if (f.stereo->AnyGiven()) *o.config.mutable_stereo() = f.stereo->GivenStereoConfig();
  auto cap = cloudcast::client::MaxCloudBytesFromKb(f.max_reply_kb, "--max-reply-kb");
  if (!cap.ok()) return usage(std::string(cap.status().message()));
  cloudcast::client::SetMaxCloudBytes(*cap, &o.config).IgnoreError();  // a checked cap

  // Signals: blocked before any thread starts, taken by sigwait on a thread of ours.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  std::thread([signals] {
    int signal_number = 0;
    sigwait(&signals, &signal_number);
    g_stop.store(true);
    if (load::Fleet* fleet = g_fleet.load()) fleet->Stop();
    std::fprintf(stderr, "cloudcast-load: %s, stopping (again to exit at once)\n",
                 strsignal(signal_number));
    sigwait(&signals, &signal_number);
    std::_Exit(130);
  }).detach();

  std::unique_ptr<load::FrameLog> frame_log;
  if (!f.frame_log.empty()) {
    auto opened = load::FrameLog::Open(f.frame_log, "--frame-log");
    if (!opened.ok()) {
      std::cerr << "cloudcast-load: " << opened.status().message() << "\n";
      return kExitUsage;
    }
    frame_log = *std::move(opened);
    o.frame_log = frame_log.get();
  }
  auto fleet = load::Fleet::Connect(o, &*store);
  if (!fleet.ok()) {
    std::cerr << "cloudcast-load: " << fleet.status().message() << "\n";
    return absl::IsInvalidArgument(fleet.status()) ? kExitUsage : kExitFailure;
  }
  g_fleet.store(fleet->get());
  if (g_stop.load()) (*fleet)->Stop();  // a signal that came while connecting

  const bool progress = f.progress_s > 0 && !f.quiet;
  if (progress) {
    std::fprintf(stderr, "cloudcast-load: %d streams -> %s, %s; %s (prepared in %.1f s)\n",
                 f.streams, f.server.c_str(), schedule_text.c_str(), store->description().c_str(),
                 prepare_s);
  }
  const auto& at_start = (*fleet)->replicas_at_start();
  if (!at_start.empty() && !f.quiet) {
    std::string names;
    for (const std::string& n : at_start) names += (names.empty() ? "" : ", ") + n;
    std::fprintf(stderr, "cloudcast-load: %s; replicas answering: %d (%s)\n",
                 (*fleet)->lb_policy().c_str(), (*fleet)->replicas_answering(), names.c_str());
  }
  const int listed = load::ListedAddresses(f.server);
  if (listed > 0 && (*fleet)->lb_policy() == "round_robin" &&
      (*fleet)->replicas_answering() < listed) {
    std::fprintf(stderr,
                 "cloudcast-load: warning: %d of the %d addresses answered within "
                 "--connect-timeout; streams go to those\n",
                 (*fleet)->replicas_answering(), listed);
  }
  std::unique_ptr<load::MemoryWatch> memory;
  if (!f.watch_memory.empty()) {
    memory = std::make_unique<load::MemoryWatch>(
        f.watch_memory,
        std::chrono::milliseconds(static_cast<std::int64_t>(f.memory_interval_s * 1000)));
  }
  std::uint64_t errors = 0, drops = 0;
  const load::FleetResult result = (*fleet)->Run([&](const load::SecondStats& s) {
    errors += s.errors;
    drops += s.drops;
    if (progress) std::fprintf(stderr, "%s\n", load::ProgressLine(s, errors, drops).c_str());
  });
  if (memory) memory->Stop();

  nlohmann::json options = {
      {"call", "cloudcast.v1.CloudCast.Stream"},
      {"host", f.server},
      {"insecure", true},
      {"concurrency", f.streams},
      {"connections", o.connections == 0 ? f.streams : std::min(o.connections, f.streams)},
      {"rps", o.closed_loop ? 0.0 : o.schedule.start * f.streams},
      {"fps", f.fps},
      {"in-flight", f.in_flight},
      {"load-schedule", f.schedule},
      {"load-start", o.schedule.start},
      {"load-step", o.schedule.step},
      {"load-end", o.schedule.end},
      {"load-step-duration", o.schedule.step_duration.count()},
      {"total", o.frames},
      {"duration", o.duration.count()},
      {"drain-timeout", o.drain_timeout.count()},
      {"delivery", f.lossless ? "all" : "latest"},
      {"encoding", store->encoding()},
      {"rate-control", f.rate_control},
      {"max-point-error", f.max_point_error},
      {"rate-target-delay-ms",
       o.rate_control ? static_cast<double>(o.rate_control->target_delay.count()) : 0.0},
      {"input", f.input},
      {"frames-source", store->description()},
      {"seed", f.seed},
      {"config", o.config.ShortDebugString()},
      {"lb", (*fleet)->lb_policy()},
      {"resilient", f.resilient},
      {"reconnect-timeout", o.reconnect_timeout.count()},
  };
  load::Report report =
      load::MakeReport(**fleet, result, store->description(), schedule_text, options);
  report.encoding = store->encoding();
  report.video = store->video();
  if (store->live_video()) report.live_video = store->live_video()->settings;
  report.near_lossless = store->near_lossless();
  if (memory) {
    report.memory_url = f.watch_memory;
    report.memory = memory->samples();
  }
  if (f.soak) {
    report.soak = true;
    report.soak_bounds.warmup_s = f.soak_warmup_s;
    report.soak_bounds.max_growth_bytes = f.soak_max_growth_mb * 1e6;
    report.soak_bounds.lossless = f.lossless;
    report.soak_verdict = load::JudgeSoak(report.memory, report.totals, report.soak_bounds);
  }
  std::cout << load::FormatTable(report) << std::flush;
  int code = 0;
  if (!f.json.empty()) {
    std::ofstream out(f.json);
    out << load::GhzJson(report).dump(2) << "\n";
    if (!out) {
      std::cerr << "cloudcast-load: cannot write --json " << f.json << "\n";
      code = kExitFailure;
    }
  }
  if (!f.html.empty()) {
    std::ofstream out(f.html);
    out << load::Html(report);
    if (!out) {
      std::cerr << "cloudcast-load: cannot write --html " << f.html << "\n";
      code = kExitFailure;
    }
  }
  if (frame_log) {
    if (absl::Status s = frame_log->Close(); !s.ok()) {
      std::cerr << "cloudcast-load: " << s.message() << "\n";
      code = kExitFailure;
    }
  }
  g_fleet.store(nullptr);
  if (code == 0 && f.soak && !report.soak_verdict.passed) code = kExitSoakFailed;
  return code;
}
