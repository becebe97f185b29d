// cloudcast-downlink-bench: the downlink cap (DracoConfig.max_cloud_bytes, issue 26) over
// loopback gRPC. An in-process server with the paper's setting answers Process calls for every
// New Tsukuba frame at a few caps and error bounds; the table gives the reply's cloud bytes, the
// frames over the cap, the bits the server chose, the worst position error measured against the
// uncompressed cloud, and the server's Draco encode time (median), which the cap's extra encodes
// add to. Prints a table, and JSON with --json.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "cloudcast/client/client.h"
#include "cloudcast/client/config.h"
#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/core/settings.h"
#include "cloudcast/datasets/tsukuba.h"
#include "cloudcast/server/server.h"
#include "stats.h"

namespace cloudcast::bench {
namespace {

struct Row {
  double cap_kb = 0;
  float bound = 0;             // 0: the server's default (a quarter of the leaf)
  int min_color_bits_set = 0;  // 0: the server's default (5)
  std::vector<double> bytes, encode_us;
  int frames = 0, over = 0;
  int min_position_bits = 99, max_position_bits = 0, min_color_bits = 99, max_color_bits = 0;
  double worst_error = 0, encodes = 0;
};

int Main(int argc, char** argv) {
  CLI::App app(
      "cloudcast-downlink-bench: reply bytes, bits and point error at a few downlink "
      "caps, over loopback gRPC (New Tsukuba, the paper's parameters)");
  std::string data = tsukuba::DefaultDir();
  int rounds = 5;
  std::string json_path;
  std::vector<double> caps_kb = {0, 40, 30, 20, 12};
  // (20 and 12 kB: what a 5 and a 3 Mbit/s downlink carry at 30 fps, less headroom.)
  app.add_option("--data", data, "New Tsukuba folder")->capture_default_str();
  app.add_option("--rounds", rounds, "Passes over the frames per row")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  app.add_option("--caps-kb", caps_kb, "Caps in kB (0 = none)")->capture_default_str();
  app.add_option("--json", json_path, "Also write the rows as JSON here");
  CLI11_PARSE(app, argc, argv);

  auto frames = tsukuba::LoadAll(data);
  if (!frames.ok()) {
    std::fprintf(stderr, "cloudcast-downlink-bench: %s\n",
                 std::string(frames.status().message()).c_str());
    return 1;
  }
  server::ServerOptions options;
  options.listen = "127.0.0.1:0";
  options.metrics_listen = "";
  options.threads = 1;
  if (!ApplyPreset("new_tsukuba", &options.defaults.frame).ok()) return 1;
  auto server = server::Server::Start(options);
  if (!server.ok()) {
    std::fprintf(stderr, "cloudcast-downlink-bench: server: %s\n",
                 std::string(server.status().message()).c_str());
    return 1;
  }
  auto client = client::Client::Connect((*server)->address());
  if (!client.ok()) return 1;

  // The uncompressed clouds, to measure the decoded points' error (speed 10 keeps the order).
  std::vector<PointCloud> truth(frames->size());
  Pipeline pipeline;
  for (std::size_t i = 0; i < frames->size(); ++i) {
    if (!pipeline
             .Run(PipelineOptions{}, (*frames)[i].disparity.view(), (*frames)[i].colour.view(),
                  &truth[i])
             .ok()) {
      return 1;
    }
  }

  std::vector<Row> rows;
  // The default bound and colour floor, then a looser bound (the whole leaf), then that with
  // colours allowed down to 2 bits.
  const std::vector<std::pair<float, int>> bounds = {{0.0f, 0}, {0.03f, 0}, {0.03f, 2}};
  for (const auto& [bound, min_color_bits] : bounds) {
    for (double cap_kb : caps_kb) {
      if (bound > 0 && cap_kb == 0) continue;
      Row row;
      row.cap_kb = cap_kb;
      row.bound = bound;
      row.min_color_bits_set = min_color_bits;
      client::StreamConfig config;
      const auto cap = client::MaxCloudBytesFromKb(cap_kb, "--caps-kb");
      if (!cap.ok() || !client::SetMaxCloudBytes(*cap, &config, min_color_bits).ok()) return 1;
      if (bound > 0) config.mutable_draco()->set_max_position_error(bound);
      for (int round = 0; round < rounds; ++round) {
        for (std::size_t i = 0; i < frames->size(); ++i) {
          if (truth[i].size() == 0) continue;
          auto r =
              (*client)->Process((*frames)[i].disparity.view(), (*frames)[i].colour.view(), config);
          if (!r.ok() || !r->ok() || r->cloud.size() != truth[i].size()) {
            std::fprintf(stderr, "frame %s failed\n", (*frames)[i].id.c_str());
            return 1;
          }
          const v1::CloudReply& reply = r->reply;
          row.bytes.push_back(static_cast<double>(reply.draco().size()));
          row.encode_us.push_back(reply.times().encode_us());
          ++row.frames;
          row.over += reply.has_over_cap();
          row.min_position_bits = std::min(row.min_position_bits, reply.position_bits());
          row.max_position_bits = std::max(row.max_position_bits, reply.position_bits());
          row.min_color_bits = std::min(row.min_color_bits, reply.color_bits());
          row.max_color_bits = std::max(row.max_color_bits, reply.color_bits());
          if (round == 0) {
            for (std::size_t k = 0; k < truth[i].size(); ++k) {
              const Point& a = truth[i].points[k];
              const Point& b = r->cloud.points[k];
              row.worst_error =
                  std::max({row.worst_error, std::fabs(double{a.x} - b.x),
                            std::fabs(double{a.y} - b.y), std::fabs(double{a.z} - b.z)});
            }
          }
        }
      }
      rows.push_back(std::move(row));
    }
  }

  std::printf(
      "| cap (kB) | error bound | colour floor | mean / max cloud bytes | at 30 fps | "
      "over the cap | position bits | colour bits | worst point error | Draco encode, "
      "mean / median |\n");
  std::printf("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
  nlohmann::json out = nlohmann::json::array();
  for (const Row& row : rows) {
    double sum = 0, max = 0;
    for (double b : row.bytes) {
      sum += b;
      max = std::max(max, b);
    }
    const double mean = row.frames ? sum / row.frames : 0;
    const std::string cap = row.cap_kb == 0 ? "none" : absl::StrFormat("%g", row.cap_kb);
    const std::string bound =
        row.bound == 0 ? "0.0075 (default)" : absl::StrFormat("%g", row.bound);
    auto range = [](int lo, int hi) {
      return lo == hi ? absl::StrCat(lo) : absl::StrCat(lo, "-", hi);
    };
    double encode_sum = 0;
    for (double us : row.encode_us) encode_sum += us;
    const double encode_mean = row.frames ? encode_sum / row.frames : 0;
    std::printf(
        "| %s | %s | %d | %.0f / %.0f | %.1f Mbit/s | %d of %d | %s | %s | %.4f | %.0f / "
        "%.0f us |\n",
        cap.c_str(), bound.c_str(), row.min_color_bits_set ? row.min_color_bits_set : 5, mean, max,
        mean * 8 * 30 / 1e6, row.over, row.frames,
        range(row.min_position_bits, row.max_position_bits).c_str(),
        range(row.min_color_bits, row.max_color_bits).c_str(), row.worst_error, encode_mean,
        Median(row.encode_us));
    out.push_back({{"cap_kb", row.cap_kb},
                   {"max_position_error", row.bound == 0 ? 0.0075 : row.bound},
                   {"mean_cloud_bytes", mean},
                   {"max_cloud_bytes", max},
                   {"frames", row.frames},
                   {"frames_over_cap", row.over},
                   {"position_bits", {row.min_position_bits, row.max_position_bits}},
                   {"color_bits", {row.min_color_bits, row.max_color_bits}},
                   {"worst_position_error", row.worst_error},
                   {"min_color_bits", row.min_color_bits_set ? row.min_color_bits_set : 5},
                   {"mean_encode_us", encode_mean},
                   {"median_encode_us", Median(row.encode_us)}});
  }

  // The cap's cost in the engine alone (no gRPC, no other work): EncodeDraco on each cloud,
  // uncapped and capped (30 kB, bound 0.03, colour floor 5), the median of 21 runs each.
  std::printf(
      "\nEncode cost per frame (in-process EncodeDraco, median of 21 runs; cap 30 kB, "
      "bound 0.03):\n\n");
  std::printf("| frame | points | uncapped: bytes, us | capped: bytes, bits p/c, encodes, us |\n");
  std::printf("| --- | --- | --- | --- |\n");
  nlohmann::json cost = nlohmann::json::array();
  for (std::size_t i = 0; i < frames->size(); ++i) {
    if (truth[i].size() < 1000) continue;
    auto time = [&](const DracoOptions& o, DracoEncodeInfo* info) {
      std::vector<double> us;
      std::string bytes;
      for (int run = 0; run < 21; ++run) {
        const auto t0 = std::chrono::steady_clock::now();
        if (!EncodeDraco(truth[i], o, &bytes, info).ok()) return -1.0;
        us.push_back(
            std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0)
                .count());
      }
      return Median(us);
    };
    DracoOptions plain;
    plain.max_position_error = 0.03f;
    DracoOptions capped = plain;
    capped.max_cloud_bytes = 30000;
    DracoEncodeInfo a, b;
    const double ta = time(plain, &a), tb = time(capped, &b);
    std::printf("| %s | %zu | %zu, %.0f | %zu%s, %d/%d, %d, %.0f |\n", (*frames)[i].id.c_str(),
                truth[i].size(), a.bytes, ta, b.bytes, b.over_cap ? " (over)" : "", b.position_bits,
                b.color_bits, b.encodes, tb);
    cost.push_back({{"frame", (*frames)[i].id},
                    {"points", truth[i].size()},
                    {"uncapped_bytes", a.bytes},
                    {"uncapped_us", ta},
                    {"capped_bytes", b.bytes},
                    {"over_cap", b.over_cap},
                    {"position_bits", b.position_bits},
                    {"color_bits", b.color_bits},
                    {"encodes", b.encodes},
                    {"capped_us", tb}});
  }
  if (!json_path.empty()) {
    std::ofstream(json_path) << nlohmann::json{{"rows", out}, {"encode_cost", cost}}.dump(2)
                             << "\n";
  }
  return 0;
}

}  // namespace
}  // namespace cloudcast::bench

int main(int argc, char** argv) { return cloudcast::bench::Main(argc, argv); }
