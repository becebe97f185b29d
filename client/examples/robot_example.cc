// cloudcast-robot-example: a robot-side integration. It streams camera frames (cv::Mats) to a
// cloudcast server at 10 Hz and prints each cloud's size and end-to-end latency. A robot sends
// what its camera gives (--input):
//   disparity  a disparity map from its own stereo matcher, with the colour image (the default);
//   depth      a depth camera's image (CV_16UC1 millimetres or CV_32FC1 metres), with colour;
//   stereo     a rectified left + right pair, which the server matches (--matcher picks how).
//
//   cloudcast-robot-example [--input disparity|depth|stereo] [--matcher NAME] [--compress]
//                           [--tls-ca FILE [--tls-cert FILE --tls-key FILE]
//                           [--tls-server-name NAME]] [--token-file FILE]
//                           [TARGET [FRAMES [DIR_A DIR_B]]]
//
// Without folders it renders the synthetic scene (its exact depth, or its view from the right
// camera for a pair); with them it sends their PNGs in name order: DIR_A holds the disparity
// maps, the depth images or the left images, DIR_B the colour images or the right images (e.g.
// New Tsukuba's groundtruth/disparity_maps/left and illumination/daylight/left, or
// illumination/daylight/left and illumination/daylight/right). --compress sends the pixels
// losslessly compressed (row deltas + zstd): about a third of the raw bytes, for a robot on
// Wi-Fi. --tls-ca trusts that CA for the server's certificate (TLS); --tls-cert / --tls-key send
// a client certificate (mutual TLS); --token-file sends the bearer token in that file with every
// call (README, "Security").
#include <chrono>
#include <cinttypes>
#include <cstdio>
#include <cstdlib>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <thread>
#include <vector>

#include "cloudcast/client/client.h"
#include "cloudcast/client/opencv.h"
#include "cloudcast/core/stereo.h"
#include "cloudcast/datasets/synthetic.h"

namespace cc = cloudcast::client;

namespace {

enum class Input { kDisparity, kDepth, kStereo };

constexpr const char* kUsage =
    "usage: cloudcast-robot-example [--input disparity|depth|stereo] [--matcher NAME]\n"
    "         [--compress] [--tls-ca FILE [--tls-cert FILE --tls-key FILE]\n"
    "         [--tls-server-name NAME]] [--token-file FILE] [TARGET [FRAMES [DIR_A DIR_B]]]\n"
    "\n"
    "Streams frames to a cloudcast server (TARGET, default localhost:50051) at 10 Hz, FRAMES of\n"
    "them (default 30), and prints each cloud's points and latency.\n"
    "  --input KIND     what each frame holds: disparity (a disparity map + colour, the default),\n"
    "                   depth (a depth image + colour) or stereo (a rectified left + right pair\n"
    "                   the server matches)\n"
    "  --matcher NAME   --input stereo: the server's matcher (sgm, sgbm, sgbm-3way, hh, bm;\n"
    "                   default: the server's, sgm out of the box)\n"
    "  --compress       send the pixels losslessly compressed (row deltas + zstd)\n"
    "  --tls-ca FILE    TLS: trust this CA for the server's certificate\n"
    "  --tls-cert FILE, --tls-key FILE   mutual TLS: this client's certificate and key\n"
    "  --tls-server-name NAME            the name the server's certificate must carry\n"
    "  --token-file FILE                 send the bearer token in this file with every call\n"
    "  DIR_A DIR_B      PNGs in name order: disparity maps, depth images or left images (A),\n"
    "                   with colour images or right images (B); default: the synthetic scene\n";

// The robot's camera, stood in for by files or by the synthetic scene. Grab gives the frame's
// two images: disparity + colour, depth + colour, or left + right.
struct Camera {
  Input input = Input::kDisparity;
  std::vector<cv::String> files_a, files_b;
  cloudcast::SyntheticScene scene = cloudcast::SyntheticScene::Default();
  cloudcast::SyntheticFrame rendered, right;  // own the pixels the synthetic Mats point to

  bool Grab(int i, cv::Mat* a, cv::Mat* b) {
    if (!files_a.empty() && !files_b.empty()) {
      const std::size_t k = i % std::min(files_a.size(), files_b.size());
      // Disparity and depth as stored (8/16-bit, float); colour images as BGR.
      *a =
          cv::imread(files_a[k], input == Input::kStereo ? cv::IMREAD_COLOR : cv::IMREAD_UNCHANGED);
      *b = cv::imread(files_b[k], cv::IMREAD_COLOR);
      return !a->empty() && !b->empty();
    }
    cloudcast::SyntheticOptions options;
    options.frame = i;
    auto frame = scene.Render(options);
    if (!frame.ok()) return false;
    rendered = *std::move(frame);
    const int h = static_cast<int>(rendered.height), w = static_cast<int>(rendered.width);
    const cv::Mat disparity(h, w, CV_32FC1, rendered.disparity.data());
    const cv::Mat colour(h, w, CV_8UC3, rendered.colour.data());
    switch (input) {
      case Input::kDisparity:
        *a = disparity;
        *b = colour;
        return true;
      case Input::kDepth: {
        // What a depth camera gives: z = f * baseline / d (float, the scene's unit), 0 = none.
        const double fb = rendered.camera.fx * rendered.camera.baseline;
        cv::Mat depth;
        cv::divide(fb, disparity, depth);
        depth.setTo(0, disparity == 0);
        *a = depth;
        *b = colour;
        return true;
      }
      case Input::kStereo: {
        // The right camera, one stereo baseline to the right (the stream's camera says so).
        options.eye_x = cloudcast::kSyntheticStereoBaseline;
        auto r = scene.Render(options);
        if (!r.ok()) return false;
        right = *std::move(r);
        *a = colour;
        *b = cv::Mat(h, w, CV_8UC3, right.colour.data());
        return true;
      }
    }
    return false;
  }
};

int Fail(const absl::Status& status) {
  std::fprintf(stderr, "%s\n", status.ToString().c_str());
  return 1;
}

int Usage(const std::string& message) {
  std::fprintf(stderr, "cloudcast-robot-example: %s\n%s", message.c_str(), kUsage);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> args;
  bool compress = false;
  cc::TlsFiles tls_files;
  std::string token_file, input_name = "disparity", matcher_name;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    std::string* value = arg == "--tls-ca"            ? &tls_files.ca_file
                         : arg == "--tls-cert"        ? &tls_files.cert_file
                         : arg == "--tls-key"         ? &tls_files.key_file
                         : arg == "--tls-server-name" ? &tls_files.server_name
                         : arg == "--token-file"      ? &token_file
                         : arg == "--input"           ? &input_name
                         : arg == "--matcher"         ? &matcher_name
                                                      : nullptr;
    if (value != nullptr) {
      if (i + 1 >= argc) return Usage(arg + " needs a value");
      *value = argv[++i];
    } else if (arg == "--help" || arg == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (arg == "--compress") {
      compress = true;
    } else if (arg.rfind("--", 0) == 0) {
      return Usage("unknown flag " + arg);
    } else {
      args.push_back(arg);
    }
  }
  Camera camera;
  if (input_name == "disparity") {
    camera.input = Input::kDisparity;
  } else if (input_name == "depth") {
    camera.input = Input::kDepth;
  } else if (input_name == "stereo") {
    camera.input = Input::kStereo;
  } else {
    return Usage("--input must be disparity, depth or stereo, got '" + input_name + "'");
  }
  // Unset, every matcher setting is the server's (its defaults are core's StereoParams).
  cloudcast::StereoParams stereo;
  if (!matcher_name.empty()) {
    if (camera.input != Input::kStereo) return Usage("--matcher applies to --input stereo only");
    if (!cloudcast::ParseStereoMatcher(matcher_name, &stereo.matcher)) {
      return Usage("--matcher must be sgm, sgbm, sgbm-3way, hh or bm, got '" + matcher_name + "'");
    }
  }
  // Connection security: TLS when a CA (or a client certificate) is given, and the token.
  cc::ClientOptions client_options;
  if (!tls_files.ca_file.empty() || !tls_files.cert_file.empty()) {
    auto tls = cc::LoadTlsFiles(tls_files);
    if (!tls.ok()) return Fail(tls.status());
    client_options.security.tls = *std::move(tls);
  }
  if (!token_file.empty()) {
    auto token = cc::ReadTokenFile(token_file);
    if (!token.ok()) return Fail(token.status());
    client_options.security.bearer_token = *std::move(token);
  }
  const std::string target = args.size() > 0 ? args[0] : cc::kDefaultTarget;
  const int frames = args.size() > 1 ? std::atoi(args[1].c_str()) : 30;
  if (args.size() > 3) {
    cv::glob(args[2] + "/*.png", camera.files_a);
    cv::glob(args[3] + "/*.png", camera.files_b);
  }

  // --- The integration: about 40 lines. ---
  auto client = cc::Client::Connect(target, client_options);  // waits up to 5 s for the server
  if (!client.ok()) return Fail(client.status());

  cc::StreamOptions options;  // replies arrive on gRPC's callback threads, one at a time, in order
  options.on_result = [](cc::Result&& r) {
    if (!r.ok()) {
      std::printf("frame %" PRIu64 ": %s\n", r.sequence, r.status.ToString().c_str());
      return;
    }
    std::printf("frame %" PRIu64 ": %zu points, %zu Draco bytes, latency %.1f ms", r.sequence,
                r.cloud.size(), r.draco_bytes(), r.latency().count() / 1e6);
    if (r.reply.times().match_us() > 0) {
      std::printf(", server matched the pair in %.1f ms", r.reply.times().match_us() / 1e3);
    }
    std::printf("\n");
  };
  // The server assumes no camera: this stand-in camera is New Tsukuba's, the paper's preset
  // (f = 615 px, baseline 1, passthrough z in [3, 12]). A real robot sends its CameraInfo's.
  cc::StreamConfig config = cc::PresetConfig("new_tsukuba").value();
  if (!matcher_name.empty()) cc::SetStereo(stereo, &config);  // how the server matches pairs
  if (camera.input == Input::kStereo && camera.files_a.empty()) {
    config.mutable_camera()->set_baseline(cloudcast::kSyntheticStereoBaseline);
  }
  auto stream = (*client)->OpenStream(config, options);
  if (!stream.ok()) return Fail(stream.status());

  for (int i = 0; i < frames; ++i) {
    cv::Mat a, b;
    if (!camera.Grab(i, &a, &b)) return Fail(absl::NotFoundError("no frame"));
    // The Mats as one frame of the robot's kind (views: nothing is copied before Send).
    absl::StatusOr<cc::FrameInput> input =
        camera.input == Input::kDepth    ? cc::DepthFrameFromMats(a, b)
        : camera.input == Input::kStereo ? cc::StereoFrameFromMats(a, b)
                                         : absl::StatusOr<cc::FrameInput>();
    if (camera.input == Input::kDisparity) {
      auto disparity = cc::DisparityFromMat(a);
      if (!disparity.ok()) return Fail(disparity.status());
      auto colour = cc::ColorFromMat(b);
      if (!colour.ok()) return Fail(colour.status());
      input = cc::FrameInput(cc::DisparityFrame{*disparity, *colour});
    }
    if (!input.ok()) return Fail(input.status());
    cc::FrameMeta meta;
    meta.frame_id = "camera_left";
    meta.capture_time_unix_ns = cc::UnixNanosNow();  // a real robot passes its camera's stamp
    const absl::Status s = (*stream)->Send(compress ? cc::CompressRaw(*input) : *input, meta);
    if (!s.ok()) return Fail(s);
    std::this_thread::sleep_for(std::chrono::milliseconds(100));  // a 10 Hz camera
  }
  const absl::Status done = (*stream)->Finish();  // waits for the last replies
  std::printf("stream finished: %s\n", done.ToString().c_str());
  return done.ok() ? 0 : 1;
}
