#include "bridge_options.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <sstream>
#include <tuple>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "cloudcast/client/config.h"
#include "cloudcast/core/stereo.h"
#include "cloudcast/proto/convert.h"

namespace cloudcast::ros_bridge {
namespace {

const video::H264Settings& H264Default() {
  static const video::H264Settings s;
  return s;
}

const std::vector<ParamDoc>& Docs() {
  static const std::vector<ParamDoc> docs = {
      {"server", "string", "127.0.0.1:50051",
       "gRPC target of the cloudcast server (host:port, dns:///name:port, unix:///path)"},
      {"input", "string", "disparity",
       "what the camera gives: disparity (stereo_msgs/DisparityImage + colour + camera_info), "
       "depth (a 16UC1 or 32FC1 depth image + colour + camera_info) or stereo (rectified left "
       "and right images + both camera_infos, matched on the server)"},
      {"queue_size", "int", "5", "message_filters synchronizer queue, per input topic"},
      {"approximate_sync", "bool", "false",
       "pair the input topics with ApproximateTime instead of ExactTime"},
      {"delivery", "string", "(server's)",
       "latest: the server skips frames it cannot keep up with (real time); all: every frame "
       "is answered, the bridge waits for the server"},
      {"resilient", "bool", "true",
       "reopen the stream after a lost connection (and resend unanswered frames with "
       "delivery all)"},
      {"reconnect_timeout", "double", "30",
       "seconds a resilient stream keeps reconnecting before it gives up (the bridge then "
       "opens a new one on the next frame)"},
      {"connect_timeout", "double", "5", "seconds to wait for the server when opening a stream"},
      {"rate_control", "bool", "false",
       "follow the link instead of queueing behind it (a robot on Wi-Fi or LTE): a rate "
       "controller keeps a window of frames in flight and a newer frame replaces one waiting "
       "past it (needs delivery latest, which it sets when delivery is left unset)"},
      {"rate/target_delay_ms", "double",
       absl::StrCat(client::RateControlOptions{}.target_delay.count()),
       "with rate_control: the queueing delay (ms) over which the link counts as full, 1..1000; "
       "lower keeps latency lower at the cost of bytes per frame (docs/links.md measures 15 and "
       "30)"},
      {"rate/start_mbps", "double", absl::StrCat(client::RateControlOptions{}.start_bps / 1e6),
       "with rate_control: the bitrate a stream's frames (and replies) start at, Mbit/s, "
       "0.01..10000"},
      {"rate/min_mbps", "double", absl::StrCat(client::RateControlOptions{}.min_bps / 1e6),
       "with rate_control: the least the controller sets, Mbit/s, 0.01..10000"},
      {"rate/max_mbps", "double", absl::StrCat(client::RateControlOptions{}.max_bps / 1e6),
       "with rate_control: the most the controller sets, Mbit/s, 0.01..10000"},
      {"rate/reply_cap", "bool", "true",
       "with rate_control: the replies follow the downlink too, each reply's cloud capped at "
       "the bitrate the downlink carries (never above draco/max_reply_kb); false: replies take "
       "what they take"},
      {"encoding", "string", "raw",
       "how the images travel: raw; zstd (lossless: row deltas + zstd, about a third of the "
       "bytes); h264 (the colour image, or both views of a stereo pair, as H.264 video, about "
       "a tenth; a disparity or depth map stays lossless, zstd; the h264/ parameters); jpeg "
       "(the colour image, or both views of a pair, as JPEG; a disparity or depth map stays "
       "lossless, zstd; with rate_control the quality follows the controller's target frame by "
       "frame, then disparity and depth frames go at half resolution; the jpeg/ parameters). "
       "For a thin uplink (Wi-Fi, LTE), h264 or jpeg with rate_control"},
      {"compress", "bool", "false",
       "deprecated: true is encoding zstd (kept for existing launch files; refused beside "
       "another encoding)"},
      {"h264/preset", "string", H264Default().preset,
       "encoding h264: the x264 preset, ultrafast .. medium (docs/video.md measures them)"},
      {"h264/crf", "double", absl::StrCat(H264Default().crf),
       "encoding h264: constant quality, 1..51 (lower is better), capped by h264/mbps; 0: "
       "h264/mbps alone"},
      {"h264/mbps", "double", absl::StrCat(H264Default().mbps),
       "encoding h264: bitrate, Mbit/s, both views of a pair together, 0.05..1000: the cap of "
       "a one-frame VBV; with rate_control, the most the rate controller's target may give the "
       "encoder"},
      {"h264/fps", "double", "30",
       "encoding h264: the camera's frame rate, for the one-frame VBV (h264/mbps / h264/fps "
       "bits a frame), 1..1000"},
      {"h264/keyframe_interval", "int", absl::StrCat(H264Default().keyframe_interval),
       "encoding h264: frames between IDRs (0: only the first and those the server asks for)"},
      {"h264/threads", "int", absl::StrCat(H264Default().threads),
       "encoding h264: encoder threads, 1..16 (x264 sliced threads: no added latency)"},
      {"h264/colour_444", "bool", "false",
       "encoding h264: colour as 4:4:4 (4:2:0 alone caps colour near 28-39 dB PSNR)"},
      {"h264/grey", "bool", "false",
       "encoding h264: images coded grey (4:0:0: what stereo matching reads, in fewer bits; "
       "the points are grey)"},
      {"h264/separate_stereo", "bool", "false",
       "encoding h264, input stereo: a bitstream per view instead of the right view "
       "interleaved after the left (the measured best)"},
      {"h264/lossless", "bool", "false",
       "encoding h264: every picture exactly as given (qp 0; not with h264/crf or h264/mbps): "
       "for rendered, noise-free cameras (a simulator's); a real camera's noise makes it 40 "
       "Mbit/s and more"},
      {"h264/x264_params", "string", "",
       "encoding h264: more x264 options, key=value:key=value, after ours (e.g. "
       "partitions=all:ref=4; the latency and rate control options are refused)"},
      {"jpeg/quality", "int", "90",
       "encoding jpeg: the JPEG quality, 1..100. Without rate_control every frame's (fixed, at "
       "full resolution); with it, the quality a stream starts at"},
      {"jpeg/min_quality", "int", "10",
       "encoding jpeg with rate_control: the lowest quality the controller's target may bring, "
       "1..100; below it, the half-resolution floor"},
      {"jpeg/max_quality", "int", "95",
       "encoding jpeg with rate_control: the highest quality a roomy target may bring, 1..100"},
      {"jpeg/half_resolution", "bool", "true",
       "encoding jpeg with rate_control, input disparity or depth: when even jpeg/min_quality "
       "(or the lossless disparity or depth alone) is over the target's bytes per frame, send "
       "frames at half width and height, each with its camera halved, until the target carries "
       "a full-resolution frame again"},
      {"jpeg/fps", "double", "30",
       "encoding jpeg with rate_control: the camera's frame rate; the target over it is a "
       "frame's budget in bytes, 1..1000"},
      {"passthrough/enabled", "bool", "(server's)", "keep only points with z in [min, max]"},
      {"passthrough/min", "double", "(server's)",
       "passthrough lower bound on z, in the camera's unit (metres for a baseline T in metres)"},
      {"passthrough/max", "double", "(server's)", "passthrough upper bound on z"},
      {"voxel/enabled", "bool", "(server's)", "downsample on a voxel grid (PCL VoxelGrid)"},
      {"voxel/leaf", "double", "(server's)", "voxel edge, in the camera's unit"},
      {"voxel/min_points", "int", "(server's)", "voxels with fewer points give no point"},
      {"draco/position_bits", "int", "(server's)",
       "Draco position quantization bits, 1..30 (the server raises them to keep "
       "draco/max_position_error)"},
      {"draco/max_position_error", "double", "(server's)",
       "largest per-coordinate position error Draco may add; 0: no bound"},
      {"draco/encode_speed", "int", "(server's)", "Draco encode speed 0 (smallest) .. 10"},
      {"draco/decode_speed", "int", "(server's)", "Draco decode speed 0 .. 10"},
      {"draco/max_reply_kb", "double", "0",
       "the downlink cap: each reply's cloud at most this many kB (1000 bytes), the server "
       "lowering position bits (within draco/max_position_error) and colour bits to meet it; "
       "a cloud it cannot bring under still comes back, marked over the cap. 0: no cap; else "
       "at least 0.064"},
      {"draco/min_color_bits", "int", "(server's)",
       "with draco/max_reply_kb: the fewest colour bits per channel the server may go down to, "
       "1..8 (the server's default: 5)"},
      {"draco/cap_min_points", "int", "0",
       "with draco/max_reply_kb or rate_control (whose reply cap is on by default): a cloud "
       "still over the cap at the fewest bits allowed loses the voxels of fewest points, "
       "voxel/min_points raised up to this, 0..64 (2: a stereo matcher's lone stray points "
       "first); 0: never"},
      {"tls/enabled", "bool", "false",
       "connect with TLS, trusting the system's CAs (implied by every other tls/ parameter)"},
      {"tls/ca", "string", "", "PEM file of the CA certificates to trust for the server"},
      {"tls/cert", "string", "", "mutual TLS: this client's PEM certificate chain (with tls/key)"},
      {"tls/key", "string", "", "mutual TLS: the PEM private key of tls/cert"},
      {"tls/server_name", "string", "",
       "the name the server's certificate must carry, when ~server is an address"},
      {"token_file", "string", "",
       "send the bearer token in this file with every call (a file, so that the token stays "
       "out of the parameter server)"},
      {"diagnostics_period", "double", "1", "seconds between two diagnostics messages"},
      {"depth_scale", "double", "(REP 118's)",
       "~input depth: the unit of a raw depth value, z = D * depth_scale (default 0.001 for "
       "16UC1 millimetres, 1 for 32FC1 metres)"},
      {"stereo/matcher", "string", "(server's)",
       "~input stereo: sgm (cloudcast's own, the fast one), sgbm, sgbm-3way, hh (OpenCV "
       "StereoSGBM's modes) or bm (OpenCV StereoBM)"},
      {"stereo/min_disparity", "int", "(server's)", "smallest disparity searched, pixels"},
      {"stereo/num_disparities", "int", "(server's)",
       "disparities searched from min_disparity: a positive multiple of 16 (min_disparity + "
       "num_disparities at most 2048)"},
      {"stereo/block_size", "int", "(server's)",
       "sgm: the census window, 3, 5 or 7; OpenCV's matchers: the block, odd, 1..255 (bm: 5..255)"},
      {"stereo/p1", "int", "(server's)",
       "smoothness penalty for a disparity change of 1 (0: the matcher's own; sgm's costs are "
       "0..12, OpenCV's 8 x block^2 by default)"},
      {"stereo/p2", "int", "(server's)",
       "penalty for larger changes, > p1 (0: the matcher's own; sgm: at most 31 minus its largest "
       "cost, 19 for blocks 5 and 7)"},
      {"stereo/uniqueness_ratio", "int", "(server's)",
       "percent by which the best cost must beat the second best, 0..99"},
      {"stereo/speckle_window_size", "int", "(server's)",
       "largest blob of disparities treated as speckle noise and invalidated; 0: no filter"},
      {"stereo/speckle_range", "int", "(server's)",
       "largest disparity variation within one connected blob, pixels"},
      {"stereo/disp12_max_diff", "int", "(server's)",
       "left-right consistency tolerance, pixels; -1: no check"},
      {"stereo/paths", "int", "(server's)", "sgm: 4 or 8 aggregation paths"},
      {"stereo/publish_disparity", "bool", "false",
       "also publish the server's disparity map as stereo_msgs/DisparityImage on 'disparity' "
       "(it comes back zstd-compressed with each cloud)"},
  };
  return docs;
}

// Errors name the parameter as the transport spells it ("~voxel/leaf" on ROS 1, "voxel.leaf" on
// ROS 2): ParamReader::Display.
absl::Status OutOfRange(const ParamReader& p, const std::string& name, double value,
                        const std::string& rule) {
  std::ostringstream os;
  os << p.Display(name) << " is " << value << "; must be " << rule;
  return absl::InvalidArgumentError(os.str());
}

// Every parameter the node was given must be one of ParamDocs.
absl::Status CheckNoUnknownParams(const ParamReader& p, const std::string& program) {
  for (const std::string& name : p.Names()) {
    const bool known = std::any_of(Docs().begin(), Docs().end(),
                                   [&](const ParamDoc& d) { return d.name == name; });
    if (!known) {
      return absl::InvalidArgumentError(absl::StrCat(
          p.Display(name), " is not a parameter of ", program, " (see --help for the list)"));
    }
  }
  return absl::OkStatus();
}

#define CLOUDCAST_ASSIGN_OR_RETURN(lhs, expr)   \
  auto lhs##_or = (expr);                       \
  if (!lhs##_or.ok()) return lhs##_or.status(); \
  auto lhs = *std::move(lhs##_or)

// rate/*: the rate controller's settings, as cloudcast-client's --rate-* flags (the same ranges),
// and only with rate_control, so that a setting is never silently ignored.
absl::Status ReadRateSettings(const ParamReader& p, BridgeOptions* o) {
  struct Setting {
    const char* name;
    double lo, hi;
    const char* unit;
  };
  static constexpr Setting kSettings[] = {{"rate/target_delay_ms", 1, 1000, "ms"},
                                          {"rate/start_mbps", 0.01, 10000, "Mbit/s"},
                                          {"rate/min_mbps", 0.01, 10000, "Mbit/s"},
                                          {"rate/max_mbps", 0.01, 10000, "Mbit/s"}};
  double values[4] = {static_cast<double>(o->rate.target_delay.count()), o->rate.start_bps / 1e6,
                      o->rate.min_bps / 1e6, o->rate.max_bps / 1e6};
  for (int i = 0; i < 4; ++i) {
    const Setting& s = kSettings[i];
    CLOUDCAST_ASSIGN_OR_RETURN(v, p.Double(s.name));
    if (!v) continue;
    if (!o->rate_control) {
      return absl::InvalidArgumentError(
          absl::StrCat(p.Display(s.name), " needs ", p.Display("rate_control"), " true"));
    }
    if (!(std::isfinite(*v) && *v >= s.lo && *v <= s.hi)) {
      std::ostringstream rule;
      rule << "in [" << s.lo << ", " << s.hi << "] " << s.unit;
      return OutOfRange(p, s.name, *v, rule.str());
    }
    values[i] = *v;
  }
  if (values[2] > values[3] || values[1] < values[2] || values[1] > values[3]) {
    return absl::InvalidArgumentError(absl::StrCat(
        p.Display("rate/min_mbps"), " <= ", p.Display("rate/start_mbps"), " <= ",
        p.Display("rate/max_mbps"), " must hold; they are ", values[2], ", ", values[1], ", ",
        values[3]));
  }
  o->rate.target_delay = std::chrono::milliseconds(std::llround(values[0]));
  o->rate.start_bps = values[1] * 1e6;
  o->rate.min_bps = values[2] * 1e6;
  o->rate.max_bps = values[3] * 1e6;
  CLOUDCAST_ASSIGN_OR_RETURN(reply_cap, p.Bool("rate/reply_cap"));
  if (reply_cap) {
    if (!o->rate_control) {
      return absl::InvalidArgumentError(
          absl::StrCat(p.Display("rate/reply_cap"), " needs ", p.Display("rate_control"), " true"));
    }
    o->rate.cap_replies = *reply_cap;
  }
  return absl::OkStatus();
}

absl::Status ReadConnection(const ParamReader& p, BridgeOptions* o) {
  CLOUDCAST_ASSIGN_OR_RETURN(server, p.String("server"));
  if (server) {
    if (server->empty()) return absl::InvalidArgumentError(p.Display("server") + " is empty; give host:port");
    o->server = *server;
  }
  CLOUDCAST_ASSIGN_OR_RETURN(connect, p.Double("connect_timeout"));
  if (connect) {
    if (!(std::isfinite(*connect) && *connect >= 0)) {
      return OutOfRange(p, "connect_timeout", *connect, "finite and >= 0 (seconds)");
    }
    o->client.connect_timeout = std::chrono::milliseconds(std::llround(*connect * 1000));
  }
  CLOUDCAST_ASSIGN_OR_RETURN(resilient, p.Bool("resilient"));
  if (resilient) o->resilient = *resilient;
  CLOUDCAST_ASSIGN_OR_RETURN(reconnect, p.Double("reconnect_timeout"));
  if (reconnect) {
    if (!(std::isfinite(*reconnect) && *reconnect > 0)) {
      return OutOfRange(p, "reconnect_timeout", *reconnect, "finite and > 0 (seconds)");
    }
    o->reconnect_timeout = std::chrono::milliseconds(std::llround(*reconnect * 1000));
  }
  CLOUDCAST_ASSIGN_OR_RETURN(rate_control, p.Bool("rate_control"));
  if (rate_control) o->rate_control = *rate_control;
  if (absl::Status s = ReadRateSettings(p, o); !s.ok()) return s;

  // TLS and the token: the same rules as the programs' --tls-* and --token-file flags.
  CLOUDCAST_ASSIGN_OR_RETURN(tls, p.Bool("tls/enabled"));
  client::TlsFiles files;
  const std::pair<const char*, std::string*> tls_files[] = {
      {"tls/ca", &files.ca_file},
      {"tls/cert", &files.cert_file},
      {"tls/key", &files.key_file},
      {"tls/server_name", &files.server_name}};
  bool any_tls = tls.value_or(false);
  for (const auto& [name, out] : tls_files) {
    CLOUDCAST_ASSIGN_OR_RETURN(value, p.String(name));
    if (value && !value->empty()) {
      *out = *value;
      any_tls = true;
    }
  }
  if (any_tls) {
    if (files.cert_file.empty() != files.key_file.empty()) {
      return absl::InvalidArgumentError(
          files.cert_file.empty()
              ? absl::StrCat(p.Display("tls/key"), " needs ", p.Display("tls/cert"),
                             " (the certificate it belongs to)")
              : absl::StrCat(p.Display("tls/cert"), " needs ", p.Display("tls/key"), " (its private key)"));
    }
    auto loaded = client::LoadTlsFiles(files);
    if (!loaded.ok()) {
      return absl::InvalidArgumentError(absl::StrCat(p.Display("tls/..."), ": ", loaded.status().message()));
    }
    o->client.security.tls = *std::move(loaded);
  }
  CLOUDCAST_ASSIGN_OR_RETURN(token_file, p.String("token_file"));
  if (token_file && !token_file->empty()) {
    auto token = client::ReadTokenFile(*token_file);
    if (!token.ok()) {
      return absl::InvalidArgumentError(absl::StrCat(p.Display("token_file"), ": ", token.status().message()));
    }
    o->client.security.bearer_token = *std::move(token);
  }
  return absl::OkStatus();
}

// ~encoding jpeg: the ~jpeg/* settings of client::AdaptiveJpegCoder. Without rate_control the
// coder has no target to follow and every frame goes at ~jpeg/quality, full resolution, so the
// settings of the follower (min and max quality, the half-resolution floor, the frame rate that
// makes a frame's budget) are refused there rather than ignored.
absl::Status ReadJpeg(const ParamReader& p, BridgeOptions* o) {
  if (!HasJpegEncoder()) {
    return absl::InvalidArgumentError(
        absl::StrCat(p.Display("encoding"),
                     " is 'jpeg' but this bridge was built without the JPEG coder "
                     "(cloudcast_client_opencv, OpenCV); use raw or zstd"));
  }
  JpegSettings& j = o->jpeg;
  const std::pair<const char*, int*> qualities[] = {{"jpeg/quality", &j.quality},
                                                    {"jpeg/min_quality", &j.min_quality},
                                                    {"jpeg/max_quality", &j.max_quality}};
  for (const auto& [name, out] : qualities) {
    CLOUDCAST_ASSIGN_OR_RETURN(q, p.Int(name));
    if (!q) continue;
    if (std::string(name) != "jpeg/quality" && !o->rate_control) {
      return absl::InvalidArgumentError(absl::StrCat(p.Display(name), " needs ",
                                                     p.Display("rate_control"),
                                                     " true (without it every frame "
                                                     "goes at ",
                                                     p.Display("jpeg/quality"), ")"));
    }
    if (*q < 1 || *q > 100) return OutOfRange(p, name, *q, "in 1..100");
    *out = *q;
  }
  CLOUDCAST_ASSIGN_OR_RETURN(half, p.Bool("jpeg/half_resolution"));
  if (half) {
    if (!o->rate_control) {
      return absl::InvalidArgumentError(absl::StrCat(p.Display("jpeg/half_resolution"), " needs ",
                                                     p.Display("rate_control"), " true"));
    }
    if (o->input == InputKind::kStereo) {
      // A pair's calibration is the server's (its rectification): no half floor for pairs.
      return absl::InvalidArgumentError(absl::StrCat(
          p.Display("jpeg/half_resolution"), " is set but ", p.Display("input"),
          " is 'stereo'; the half-resolution floor is for disparity and depth frames only"));
    }
    j.half_resolution = *half;
  }
  CLOUDCAST_ASSIGN_OR_RETURN(fps, p.Double("jpeg/fps"));
  if (fps) {
    if (!o->rate_control) {
      return absl::InvalidArgumentError(
          absl::StrCat(p.Display("jpeg/fps"), " needs ", p.Display("rate_control"), " true"));
    }
    if (!(std::isfinite(*fps) && *fps >= 1 && *fps <= 1000)) {
      return OutOfRange(p, "jpeg/fps", *fps, "in [1, 1000] frames a second");
    }
    j.fps = *fps;
  }
  if (o->rate_control && !(j.min_quality <= j.quality && j.quality <= j.max_quality)) {
    return absl::InvalidArgumentError(absl::StrCat(
        p.Display("jpeg/min_quality"), " <= ", p.Display("jpeg/quality"),
        " <= ", p.Display("jpeg/max_quality"), " must hold with ", p.Display("rate_control"),
        "; they are ", j.min_quality, ", ", j.quality, ", ", j.max_quality));
  }
  return absl::OkStatus();
}

// ~encoding (and ~compress, its old name for zstd) and, with h264, the ~h264/* settings, by the
// rules of the programs' --h264-* flags (video::H264Settings).
absl::Status ReadUplink(const ParamReader& p, BridgeOptions* o) {
  CLOUDCAST_ASSIGN_OR_RETURN(encoding, p.String("encoding"));
  if (encoding) {
    if (*encoding == "raw") {
      o->uplink = Uplink::kRaw;
    } else if (*encoding == "zstd") {
      o->uplink = Uplink::kZstd;
    } else if (*encoding == "h264") {
      o->uplink = Uplink::kH264;
    } else if (*encoding == "jpeg") {
      o->uplink = Uplink::kJpeg;
    } else {
      return absl::InvalidArgumentError(absl::StrCat(p.Display("encoding"), " is '", *encoding,
                                                     "'; must be raw, zstd, h264 or jpeg"));
    }
  }
  CLOUDCAST_ASSIGN_OR_RETURN(compress, p.Bool("compress"));
  if (compress.value_or(false)) {
    if (encoding && o->uplink != Uplink::kZstd) {
      return absl::InvalidArgumentError(absl::StrCat(
          p.Display("compress"), " is true (the old name of ", p.Display("encoding"),
          " zstd) but ", p.Display("encoding"), " is '", *encoding, "'; drop ",
          p.Display("compress")));
    }
    o->uplink = Uplink::kZstd;
  }
  // Each encoding's own parameters are refused with another, so that none is silently ignored.
  for (const auto& [uplink, prefix] : {std::pair{Uplink::kH264, std::string("h264/")},
                                       std::pair{Uplink::kJpeg, std::string("jpeg/")}}) {
    if (o->uplink == uplink) continue;
    for (const std::string& name : p.Names()) {
      if (name.rfind(prefix, 0) != 0) continue;
      return absl::InvalidArgumentError(
          absl::StrCat(p.Display(name), " is set but ", p.Display("encoding"), " is '",
                       std::string(Name(o->uplink)), "'; it applies to ", p.Display("encoding"),
                       " ", std::string(Name(uplink)), " only"));
    }
  }
  if (o->uplink == Uplink::kJpeg) return ReadJpeg(p, o);
  if (o->uplink != Uplink::kH264) return absl::OkStatus();
  if (!HasVideoEncoder()) {
    return absl::InvalidArgumentError(absl::StrCat(
        p.Display("encoding"), " is 'h264' but this bridge was built without the video encoder "
        "(CLOUDCAST_WITH_VIDEO, FFmpeg); use raw or zstd"));
  }
  video::H264Settings& h = o->h264;
  CLOUDCAST_ASSIGN_OR_RETURN(preset, p.String("h264/preset"));
  if (preset) {
    if (!video::H264Settings::PresetOk(*preset)) {
      return absl::InvalidArgumentError(absl::StrCat(p.Display("h264/preset"), " is '", *preset,
                                                     "'; must be ",
                                                     video::H264Settings::kPresetRule));
    }
    h.preset = *preset;
  }
  CLOUDCAST_ASSIGN_OR_RETURN(crf, p.Double("h264/crf"));
  if (crf) {
    if (!video::H264Settings::CrfOk(*crf)) {
      return OutOfRange(p, "h264/crf", *crf, video::H264Settings::kCrfRule);
    }
    h.crf = *crf;
  }
  CLOUDCAST_ASSIGN_OR_RETURN(mbps, p.Double("h264/mbps"));
  if (mbps) {
    if (!video::H264Settings::MbpsOk(*mbps)) {
      return OutOfRange(p, "h264/mbps", *mbps, video::H264Settings::kMbpsRule);
    }
    h.mbps = *mbps;
  }
  CLOUDCAST_ASSIGN_OR_RETURN(fps, p.Double("h264/fps"));
  if (fps) {
    if (!(std::isfinite(*fps) && *fps >= 1 && *fps <= 1000)) {
      return OutOfRange(p, "h264/fps", *fps, "in [1, 1000] frames a second");
    }
    o->h264_fps = *fps;
  }
  CLOUDCAST_ASSIGN_OR_RETURN(interval, p.Int("h264/keyframe_interval"));
  if (interval) {
    if (*interval < 0 || *interval > video::H264Settings::kMaxKeyframeInterval) {
      return OutOfRange(p, "h264/keyframe_interval", *interval,
                        absl::StrCat("in 0..", video::H264Settings::kMaxKeyframeInterval));
    }
    h.keyframe_interval = *interval;
  }
  CLOUDCAST_ASSIGN_OR_RETURN(threads, p.Int("h264/threads"));
  if (threads) {
    if (*threads < 1 || *threads > video::H264Settings::kMaxThreads) {
      return OutOfRange(p, "h264/threads", *threads,
                        absl::StrCat("in 1..", video::H264Settings::kMaxThreads));
    }
    h.threads = *threads;
  }
  const std::pair<const char*, bool*> flags[] = {{"h264/colour_444", &h.colour_444},
                                                 {"h264/grey", &h.grey},
                                                 {"h264/separate_stereo", &h.separate_stereo},
                                                 {"h264/lossless", &h.lossless}};
  for (const auto& [name, out] : flags) {
    CLOUDCAST_ASSIGN_OR_RETURN(value, p.Bool(name));
    if (value) *out = *value;
  }
  if (h.lossless && (crf || mbps)) {
    return absl::InvalidArgumentError(
        absl::StrCat(p.Display("h264/lossless"), " is true but ",
                     p.Display(crf ? "h264/crf" : "h264/mbps"),
                     " is set; a lossless stream has no quality or bitrate to set"));
  }
  CLOUDCAST_ASSIGN_OR_RETURN(x264_params, p.String("h264/x264_params"));
  if (x264_params) {
    const std::string why = video::H264Settings::X264ParamsProblem(*x264_params);
    if (!why.empty()) {
      return absl::InvalidArgumentError(
          absl::StrCat(p.Display("h264/x264_params"), " '", *x264_params, "': ", why));
    }
    h.x264_params = *x264_params;
  }
  // One image to code: the layout of a pair's two would be silently ignored.
  CLOUDCAST_ASSIGN_OR_RETURN(separate, p.Bool("h264/separate_stereo"));
  if (separate && o->input != InputKind::kStereo) {
    return absl::InvalidArgumentError(absl::StrCat(
        p.Display("h264/separate_stereo"), " is set but ", p.Display("input"), " is '",
        std::string(Name(o->input)), "'; it applies to ", p.Display("input"), " stereo only"));
  }
  return absl::OkStatus();
}

absl::Status ReadInput(const ParamReader& p, BridgeOptions* o) {
  CLOUDCAST_ASSIGN_OR_RETURN(input, p.String("input"));
  if (input) {
    if (*input == "disparity") {
      o->input = InputKind::kDisparity;
    } else if (*input == "depth") {
      o->input = InputKind::kDepth;
    } else if (*input == "stereo") {
      o->input = InputKind::kStereo;
    } else {
      return absl::InvalidArgumentError(
          absl::StrCat(p.Display("input"), " is '", *input, "'; must be disparity, depth or stereo"));
    }
  }
  CLOUDCAST_ASSIGN_OR_RETURN(queue, p.Int("queue_size"));
  if (queue) {
    if (*queue < 1 || *queue > 1000) return OutOfRange(p, "queue_size", *queue, "in 1..1000");
    o->sync.queue_size = *queue;
  }
  CLOUDCAST_ASSIGN_OR_RETURN(approx, p.Bool("approximate_sync"));
  if (approx) o->sync.approximate_sync = *approx;
  CLOUDCAST_ASSIGN_OR_RETURN(period, p.Double("diagnostics_period"));
  if (period) {
    if (!(std::isfinite(*period) && *period > 0)) {
      return OutOfRange(p, "diagnostics_period", *period, "finite and > 0 (seconds)");
    }
    o->diagnostics_period_s = *period;
  }
  return absl::OkStatus();
}

// Parameters that belong to one input kind only are refused with the others, so that a setting is
// never silently ignored.
absl::Status OnlyFor(const ParamReader& p, const BridgeOptions& o, InputKind kind,
                     const std::string& prefix) {
  if (o.input == kind) return absl::OkStatus();
  for (const std::string& name : p.Names()) {
    if (name.rfind(prefix, 0) != 0) continue;
    return absl::InvalidArgumentError(absl::StrCat(
        p.Display(name), " is set but ", p.Display("input"), " is '", std::string(Name(o.input)),
        "'; it applies to ", p.Display("input"), " ", std::string(Name(kind)), " only"));
  }
  return absl::OkStatus();
}

absl::Status ReadDepth(const ParamReader& p, BridgeOptions* o) {
  CLOUDCAST_ASSIGN_OR_RETURN(scale, p.Double("depth_scale"));
  if (scale) {
    if (!(std::isfinite(*scale) && *scale > 0)) {
      return OutOfRange(p, "depth_scale", *scale, "finite and > 0 (units of z per raw depth value)");
    }
    o->depth_scale = *scale;
  }
  return absl::OkStatus();
}

absl::Status ReadStereo(const ParamReader& p, BridgeOptions* o) {
  // Unset members keep the core's defaults for the check only: the config carries the set ones,
  // and the server's defaults fill the rest.
  StereoParams checked;
  v1::StereoConfig* c = o->config.mutable_stereo();
  CLOUDCAST_ASSIGN_OR_RETURN(matcher, p.String("stereo/matcher"));
  if (matcher) {
    if (!ParseStereoMatcher(*matcher, &checked.matcher)) {
      std::vector<std::string> names;
      for (StereoMatcher m : AllStereoMatchers()) names.emplace_back(Name(m));
      return absl::InvalidArgumentError(absl::StrCat(
          p.Display("stereo/matcher"), " is '", *matcher, "'; must be one of ", absl::StrJoin(names, ", ")));
    }
    c->set_matcher(convert::ToProto(checked.matcher));
  }
  const std::tuple<const char*, int StereoParams::*, void (v1::StereoConfig::*)(std::int32_t)>
      ints[] = {
          {"min_disparity", &StereoParams::min_disparity, &v1::StereoConfig::set_min_disparity},
          {"num_disparities", &StereoParams::num_disparities,
           &v1::StereoConfig::set_num_disparities},
          {"block_size", &StereoParams::block_size, &v1::StereoConfig::set_block_size},
          {"p1", &StereoParams::p1, &v1::StereoConfig::set_p1},
          {"p2", &StereoParams::p2, &v1::StereoConfig::set_p2},
          {"uniqueness_ratio", &StereoParams::uniqueness_ratio,
           &v1::StereoConfig::set_uniqueness_ratio},
          {"speckle_window_size", &StereoParams::speckle_window_size,
           &v1::StereoConfig::set_speckle_window_size},
          {"speckle_range", &StereoParams::speckle_range, &v1::StereoConfig::set_speckle_range},
          {"disp12_max_diff", &StereoParams::disp12_max_diff,
           &v1::StereoConfig::set_disp12_max_diff},
          {"paths", &StereoParams::paths, &v1::StereoConfig::set_paths},
      };
  for (const auto& [name, member, setter] : ints) {
    CLOUDCAST_ASSIGN_OR_RETURN(value, p.Int(absl::StrCat("stereo/", name)));
    if (!value) continue;
    checked.*member = *value;
    (c->*setter)(*value);
  }
  // The core's rules, as the server applies them (StereoParams::Validate names the member).
  if (absl::Status s = checked.Validate("stereo"); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat(p.Display("stereo/..."), ": ", s.message()));
  }
  CLOUDCAST_ASSIGN_OR_RETURN(publish, p.Bool("stereo/publish_disparity"));
  if (publish) {
    o->publish_disparity = *publish;
    c->set_return_disparity(*publish);
  }
  return absl::OkStatus();
}

absl::Status ReadStages(const ParamReader& p, BridgeOptions* o) {
  v1::StreamConfig& c = o->config;
  CLOUDCAST_ASSIGN_OR_RETURN(delivery, p.String("delivery"));
  if (delivery && !delivery->empty()) {
    convert::Delivery d;
    if (!convert::ParseDelivery(*delivery, &d)) {
      return absl::InvalidArgumentError(
          absl::StrCat(p.Display("delivery"), " is '", *delivery, "'; must be latest or all"));
    }
    c.set_delivery(convert::ToProto(d));
  }
  if (o->rate_control) {
    // A frame past the rate controller's window must be replaceable.
    if (c.delivery() == v1::DELIVERY_ALL) {
      return absl::InvalidArgumentError(absl::StrCat(
          p.Display("rate_control"), " needs delivery latest; ", p.Display("delivery"), " is all"));
    }
    c.set_delivery(v1::DELIVERY_LATEST);
  }

  CLOUDCAST_ASSIGN_OR_RETURN(pt_on, p.Bool("passthrough/enabled"));
  if (pt_on) c.mutable_passthrough()->set_enabled(*pt_on);
  CLOUDCAST_ASSIGN_OR_RETURN(pt_min, p.Double("passthrough/min"));
  CLOUDCAST_ASSIGN_OR_RETURN(pt_max, p.Double("passthrough/max"));
  if (pt_min) {
    if (!std::isfinite(*pt_min)) return OutOfRange(p, "passthrough/min", *pt_min, "finite");
    c.mutable_passthrough()->set_min(static_cast<float>(*pt_min));
  }
  if (pt_max) {
    if (!std::isfinite(*pt_max)) return OutOfRange(p, "passthrough/max", *pt_max, "finite");
    c.mutable_passthrough()->set_max(static_cast<float>(*pt_max));
  }
  if (pt_min && pt_max && *pt_min > *pt_max) {
    return OutOfRange(p, "passthrough/min", *pt_min,
                      absl::StrCat("<= ", p.Display("passthrough/max"), " (", *pt_max, ")"));
  }

  CLOUDCAST_ASSIGN_OR_RETURN(voxel_on, p.Bool("voxel/enabled"));
  if (voxel_on) c.mutable_voxel_grid()->set_enabled(*voxel_on);
  CLOUDCAST_ASSIGN_OR_RETURN(leaf, p.Double("voxel/leaf"));
  if (leaf) {
    if (!(std::isfinite(*leaf) && *leaf > 0))
      return OutOfRange(p, "voxel/leaf", *leaf, "finite and > 0");
    c.mutable_voxel_grid()->set_leaf(static_cast<float>(*leaf));
  }
  CLOUDCAST_ASSIGN_OR_RETURN(min_points, p.Int("voxel/min_points"));
  if (min_points) {
    if (*min_points < 0) return OutOfRange(p, "voxel/min_points", *min_points, ">= 0");
    c.mutable_voxel_grid()->set_min_points_per_voxel(static_cast<std::uint32_t>(*min_points));
  }

  CLOUDCAST_ASSIGN_OR_RETURN(bits, p.Int("draco/position_bits"));
  if (bits) {
    if (*bits < 1 || *bits > 30) return OutOfRange(p, "draco/position_bits", *bits, "in 1..30");
    c.mutable_draco()->set_position_bits(*bits);
  }
  CLOUDCAST_ASSIGN_OR_RETURN(max_error, p.Double("draco/max_position_error"));
  if (max_error) {
    if (!(std::isfinite(*max_error) && *max_error >= 0)) {
      return OutOfRange(p, "draco/max_position_error", *max_error, "finite and >= 0");
    }
    c.mutable_draco()->set_max_position_error(static_cast<float>(*max_error));
  }
  for (const char* name : {"draco/encode_speed", "draco/decode_speed"}) {
    CLOUDCAST_ASSIGN_OR_RETURN(speed, p.Int(name));
    if (!speed) continue;
    if (*speed < 0 || *speed > 10) return OutOfRange(p, name, *speed, "in 0..10");
    if (std::string(name) == "draco/encode_speed") {
      c.mutable_draco()->set_encode_speed(*speed);
    } else {
      c.mutable_draco()->set_decode_speed(*speed);
    }
  }

  // The downlink cap (contract revision 4): the client library's rules (MaxCloudBytesFromKb,
  // SetMaxCloudBytes), as cloudcast-client's --max-reply-kb.
  CLOUDCAST_ASSIGN_OR_RETURN(cap_kb, p.Double("draco/max_reply_kb"));
  CLOUDCAST_ASSIGN_OR_RETURN(min_color_bits, p.Int("draco/min_color_bits"));
  std::uint64_t cap = 0;
  if (cap_kb) {
    absl::StatusOr<std::uint64_t> bytes =
        client::MaxCloudBytesFromKb(*cap_kb, p.Display("draco/max_reply_kb"));
    if (!bytes.ok()) return absl::InvalidArgumentError(bytes.status().message());
    cap = *bytes;
  }
  if (min_color_bits) {
    if (*min_color_bits < 1 || *min_color_bits > 8) {
      return OutOfRange(p, "draco/min_color_bits", *min_color_bits, "in 1..8");
    }
    if (cap == 0) {
      // Without a cap the server keeps every colour bit: the floor would be silently ignored.
      return absl::InvalidArgumentError(
          absl::StrCat(p.Display("draco/min_color_bits"), " needs ",
                       p.Display("draco/max_reply_kb"), " (the cap it is the floor of)"));
    }
  }
  // The cap's last resort (contract revision 5): only meaningful with a cap, set or controlled.
  CLOUDCAST_ASSIGN_OR_RETURN(cap_min_points, p.Int("draco/cap_min_points"));
  if (cap_min_points) {
    if (*cap_min_points < 0 || *cap_min_points > int{FrameSettings::kMaxCapMinPoints}) {
      return OutOfRange(p, "draco/cap_min_points", *cap_min_points,
                        absl::StrCat("in 0..", FrameSettings::kMaxCapMinPoints));
    }
    if (*cap_min_points > 0 && cap == 0 && !o->rate_control) {
      return absl::InvalidArgumentError(absl::StrCat(
          p.Display("draco/cap_min_points"), " needs ", p.Display("draco/max_reply_kb"), " or ",
          p.Display("rate_control"), " (a cap to meet)"));
    }
    c.mutable_draco()->set_cap_min_points_per_voxel(static_cast<std::uint32_t>(*cap_min_points));
  }
  if (cap > 0) {
    if (absl::Status s = client::SetMaxCloudBytes(cap, &c, min_color_bits.value_or(0),
                                                  p.Display("draco/max_reply_kb"));
        !s.ok()) {
      return absl::InvalidArgumentError(s.message());
    }
  }

  // The proto boundary's own checks, as the server will make them (a safety net: every value
  // above was checked already, so this names proto fields only for rules not repeated here).
  if (auto resolved = convert::Resolve(c, convert::StreamSettings{}); !resolved.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("the parameters make an invalid stream config: ",
                                                   resolved.status().message()));
  }
  return absl::OkStatus();
}

}  // namespace

std::string_view Name(InputKind kind) {
  switch (kind) {
    case InputKind::kDisparity:
      return "disparity";
    case InputKind::kDepth:
      return "depth";
    case InputKind::kStereo:
      return "stereo";
  }
  return "?";
}

std::string_view Name(Uplink uplink) {
  switch (uplink) {
    case Uplink::kRaw:
      return "raw";
    case Uplink::kZstd:
      return "zstd";
    case Uplink::kH264:
      return "h264";
    case Uplink::kJpeg:
      return "jpeg";
  }
  return "?";
}

bool HasVideoEncoder() {
#ifdef CLOUDCAST_BRIDGE_VIDEO
  return true;
#else
  return false;
#endif
}

bool HasJpegEncoder() {
#ifdef CLOUDCAST_BRIDGE_JPEG
  return true;
#else
  return false;
#endif
}

const std::vector<ParamDoc>& ParamDocs() { return Docs(); }

// `text` in lines of at most `width` characters, each after `indent`.
std::string WrapText(const std::string& text, std::size_t width, const std::string& indent) {
  std::string out, line;
  std::istringstream words(text);
  std::string word;
  while (words >> word) {
    if (!line.empty() && line.size() + 1 + word.size() > width) {
      out += indent + line + "\n";
      line.clear();
    }
    line += (line.empty() ? "" : " ") + word;
  }
  if (!line.empty()) out += indent + line + "\n";
  return out;
}


absl::StatusOr<BridgeOptions> ReadBridgeOptions(const ParamReader& p, const std::string& program) {
  if (absl::Status s = CheckNoUnknownParams(p, program); !s.ok()) return s;
  BridgeOptions o;
  o.client.connect_timeout = std::chrono::milliseconds(5000);
  if (absl::Status s = ReadConnection(p, &o); !s.ok()) return s;
  if (absl::Status s = ReadInput(p, &o); !s.ok()) return s;
  if (absl::Status s = ReadUplink(p, &o); !s.ok()) return s;
  if (absl::Status s = OnlyFor(p, o, InputKind::kDepth, "depth_scale"); !s.ok()) return s;
  if (absl::Status s = OnlyFor(p, o, InputKind::kStereo, "stereo/"); !s.ok()) return s;
  if (o.input == InputKind::kDepth) {
    if (absl::Status s = ReadDepth(p, &o); !s.ok()) return s;
  }
  if (o.input == InputKind::kStereo) {
    if (absl::Status s = ReadStereo(p, &o); !s.ok()) return s;
  }
  if (absl::Status s = ReadStages(p, &o); !s.ok()) return s;
  return o;
}

}  // namespace cloudcast::ros_bridge
