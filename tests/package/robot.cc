// Streams one frame (a tilted plane, made here, no OpenCV) to the server named on the command
// line through the installed client library, and checks the cloud that comes back. With OUT_DIR
// (the arm64 test, tests/arm64_client_test.cc) it writes the reply's Draco bytes (cloud.drc) and
// the cloud it decoded from them (cloud.points, cloudcast::Point as is), for the test to decode
// the same bytes on amd64 and compare; and it sends the frame a second time through the lossless
// uplink codec (compressed here, decompressed by the server), whose cloud must be the same.
#include <cstdio>
#include <fstream>
#include <string>
#include <cstdint>
#include <vector>

#include "cloudcast/client/client.h"

namespace cc = cloudcast::client;

int main(int argc, char** argv) {
  if (argc != 2 && argc != 3) {
    std::fprintf(stderr, "usage: robot HOST:PORT [OUT_DIR]\n");
    return 2;
  }
  const std::string out_dir = argc == 3 ? argv[2] : "";
  auto client = cc::Client::Connect(argv[1]);
  if (!client.ok()) {
    std::fprintf(stderr, "connect: %s\n", client.status().ToString().c_str());
    return 1;
  }
  // 64x48, disparity 100..163 across the rows (z = 615 / d in [3.8, 6.2]: inside [3, 12]).
  const std::uint32_t w = 64, h = 48;
  std::vector<std::uint8_t> disparity(w * h), colour(w * h * 3);
  for (std::uint32_t v = 0; v < h; ++v) {
    for (std::uint32_t u = 0; u < w; ++u) {
      disparity[v * w + u] = static_cast<std::uint8_t>(100 + u);
      colour[(v * w + u) * 3 + 2] = static_cast<std::uint8_t>(4 * v);
    }
  }
  cloudcast::DisparityView d{disparity.data(), disparity.size(), w, h, w,
                             cloudcast::DisparityEncoding::kU8};
  cloudcast::ColorView c{colour.data(), colour.size(), w, h, w * 3,
                         cloudcast::ColorEncoding::kBGR8};

  auto config = cc::MakeStreamConfig(cloudcast::PipelineOptions{});
  // MakeStreamConfig states the default camera's 640x480 principal point; unset, it follows
  // each frame's centre instead.
  config.mutable_camera()->clear_cx();
  config.mutable_camera()->clear_cy();
  config.set_delivery(cloudcast::v1::DELIVERY_ALL);
  auto stream = (*client)->OpenStream(config);
  if (!stream.ok()) {
    std::fprintf(stderr, "open: %s\n", stream.status().ToString().c_str());
    return 1;
  }
  cc::FrameMeta meta;
  meta.frame_id = "package_test";
  if (auto s = (*stream)->Send(d, c, meta); !s.ok()) {
    std::fprintf(stderr, "send: %s\n", s.ToString().c_str());
    return 1;
  }
  const int frames = out_dir.empty() ? 1 : 2;
  if (frames == 2) {
    if (auto s = (*stream)->Send(cc::Compressed(d), cc::Compressed(c), meta); !s.ok()) {
      std::fprintf(stderr, "send compressed: %s\n", s.ToString().c_str());
      return 1;
    }
  }
  (*stream)->CloseSend().IgnoreError();
  cc::Result result;
  int clouds = 0;
  std::string first_draco;
  while ((*stream)->Read(&result)) {
    if (!result.ok()) {
      std::fprintf(stderr, "frame error: %s\n", result.status.ToString().c_str());
      return 1;
    }
    std::printf("frame %lu from %s: %zu points, %zu Draco bytes\n",
                static_cast<unsigned long>(result.sequence),
                result.reply.server_instance().c_str(), result.cloud.size(), result.draco_bytes());
    if (result.cloud.size() == 0) return 1;
    if (clouds == 1 && result.reply.draco() != first_draco) {
      std::fprintf(stderr, "the compressed frame gave another cloud than the raw one\n");
      return 1;
    }
    if (clouds == 0 && !out_dir.empty()) {
      first_draco = result.reply.draco();
      std::ofstream(out_dir + "/cloud.drc", std::ios::binary) << result.reply.draco();
      std::ofstream(out_dir + "/cloud.points", std::ios::binary)
          .write(reinterpret_cast<const char*>(result.cloud.points.data()),
                 static_cast<std::streamsize>(result.cloud.size() * sizeof(cloudcast::Point)));
    }
    ++clouds;
  }
  const absl::Status done = (*stream)->Finish();
  if (!done.ok() || clouds != frames) {
    std::fprintf(stderr, "stream: %s, %d clouds\n", done.ToString().c_str(), clouds);
    return 1;
  }
  std::printf("ok\n");
  return 0;
}
