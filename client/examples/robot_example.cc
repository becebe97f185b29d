// cloudcast-robot-example: a robot-side integration. It streams stereo frames (cv::Mats, as a
// stereo matcher delivers them) to a cloudcast server at 10 Hz and prints each cloud's size and
// end-to-end latency.
//
//   cloudcast-robot-example [--compress] [--tls-ca FILE [--tls-cert FILE --tls-key FILE]
//                           [--tls-server-name NAME]] [--token-file FILE]
//                           [TARGET [FRAMES [DISPARITY_DIR COLOUR_DIR]]]
//
// Without folders it renders the synthetic scene; with them it sends their PNGs in name order
// (e.g. New Tsukuba's groundtruth/disparity_maps/left and illumination/daylight/left).
// --compress sends the pixels losslessly compressed (row deltas + zstd): about a third of the
// raw bytes, for a robot on Wi-Fi. --tls-ca trusts that CA for the server's certificate (TLS);
// --tls-cert / --tls-key send a client certificate (mutual TLS); --token-file sends the bearer
// token in that file with every call (README, "Security").
#include <chrono>
#include <cinttypes>
#include <cstdio>
#include <cstdlib>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <thread>
#include <vector>

#include "cloudcast/client/client.h"
#include "cloudcast/client/opencv.h"
#include "cloudcast/datasets/synthetic.h"

namespace cc = cloudcast::client;

namespace {

// The robot's camera, stood in for by files or by the synthetic scene.
struct Camera {
  std::vector<cv::String> disparity_files, colour_files;
  cloudcast::SyntheticScene scene = cloudcast::SyntheticScene::Default();
  cloudcast::SyntheticFrame rendered;  // owns the pixels the synthetic Mats point to

  bool Grab(int i, cv::Mat* disparity, cv::Mat* colour) {
    if (!disparity_files.empty() && !colour_files.empty()) {
      const std::size_t k = i % std::min(disparity_files.size(), colour_files.size());
      *disparity = cv::imread(disparity_files[k], cv::IMREAD_UNCHANGED);  // 8/16-bit as stored
      *colour = cv::imread(colour_files[k], cv::IMREAD_COLOR);            // BGR
      return !disparity->empty() && !colour->empty();
    }
    cloudcast::SyntheticOptions options;
    options.frame = i;
    auto frame = scene.Render(options);
    if (!frame.ok()) return false;
    rendered = *std::move(frame);
    *disparity = cv::Mat(rendered.height, rendered.width, CV_32FC1, rendered.disparity.data());
    *colour = cv::Mat(rendered.height, rendered.width, CV_8UC3, rendered.colour.data());
    return true;
  }
};

int Fail(const absl::Status& status) {
  std::fprintf(stderr, "%s\n", status.ToString().c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> args;
  bool compress = false;
  cc::TlsFiles tls_files;
  std::string token_file;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    std::string* value = arg == "--tls-ca"            ? &tls_files.ca_file
                         : arg == "--tls-cert"        ? &tls_files.cert_file
                         : arg == "--tls-key"         ? &tls_files.key_file
                         : arg == "--tls-server-name" ? &tls_files.server_name
                         : arg == "--token-file"      ? &token_file
                                                      : nullptr;
    if (value != nullptr && i + 1 < argc) {
      *value = argv[++i];
    } else if (arg == "--compress") {
      compress = true;
    } else {
      args.push_back(arg);
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
  Camera camera;
  if (args.size() > 3) {
    cv::glob(args[2] + "/*.png", camera.disparity_files);
    cv::glob(args[3] + "/*.png", camera.colour_files);
  }

  // --- The integration: about 30 lines. ---
  auto client = cc::Client::Connect(target, client_options);  // waits up to 5 s for the server
  if (!client.ok()) return Fail(client.status());

  cc::StreamOptions options;  // replies arrive on the library's receiver thread, in order
  options.on_result = [](cc::Result&& r) {
    if (!r.ok()) {
      std::printf("frame %" PRIu64 ": %s\n", r.sequence, r.status.ToString().c_str());
      return;
    }
    std::printf("frame %" PRIu64 ": %zu points, %zu Draco bytes, latency %.1f ms\n", r.sequence,
                r.cloud.size(), r.draco_bytes(), r.latency().count() / 1e6);
  };
  // f = 615 px (New Tsukuba's camera), passthrough z in [3, 12], 3 cm voxels: core's defaults.
  auto stream = (*client)->OpenStream(cc::MakeStreamConfig(cloudcast::PipelineOptions{}), options);
  if (!stream.ok()) return Fail(stream.status());

  for (int i = 0; i < frames; ++i) {
    cv::Mat disparity, colour;
    if (!camera.Grab(i, &disparity, &colour)) return Fail(absl::NotFoundError("no frame"));
    cc::FrameMeta meta;
    meta.frame_id = "camera_left";
    meta.capture_time_unix_ns = cc::UnixNanosNow();  // a real robot passes its camera's stamp
    const absl::Status s = compress ? cc::SendMats(**stream, disparity, colour, meta, {})
                                    : cc::SendMats(**stream, disparity, colour, meta);
    if (!s.ok()) return Fail(s);
    std::this_thread::sleep_for(std::chrono::milliseconds(100));  // a 10 Hz camera
  }
  const absl::Status done = (*stream)->Finish();  // waits for the last replies
  std::printf("stream finished: %s\n", done.ToString().c_str());
  return done.ok() ? 0 : 1;
}
