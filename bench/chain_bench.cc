// cloudcast-chain-bench: the fused chain alone, frame by frame, to tune it. Per New Tsukuba
// frame: the points that pass, the voxels, and milliseconds with warm caches and with the caches
// evicted before each run (as in cloudcast-bench, where PCL runs in between). Under callgrind
// (--callgrind) only the measured runs are counted, so instruction counts compare versions
// exactly. --key-order measures what emitting voxels in key order (PCL's order) does to the
// Draco bytes and times. The "depth ms" column runs the same frame as a depth camera would send
// it (16-bit millimetres of the same z, depth_image_proc's formula): the depth path's cost beside
// the disparity path's, and "u16 ms" the same frame as a matcher's 16-bit fixed-point disparity
// (1/16 pixel), the disparity path at the depth image's sample width.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/filters.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/datasets/tsukuba.h"

#if __has_include(<valgrind/callgrind.h>)
#include <valgrind/callgrind.h>
#define CLOUDCAST_HAVE_CALLGRIND 1
#endif

namespace cloudcast::bench {
namespace {

using Clock = std::chrono::steady_clock;

template <typename F>
double TimeMs(F&& f) {
  const auto t0 = Clock::now();
  f();
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// Writes over a buffer larger than L2 (and a good part of L3), as a stock-PCL run does between
// two of ours in cloudcast-bench.
void EvictCaches() {
  static std::vector<std::uint64_t> junk(std::size_t{48} << 17);  // 48 MB: more than L3
  static std::uint64_t salt = 0;
  ++salt;
  for (std::size_t i = 0; i < junk.size(); i += 8) junk[i] += salt;
}

void Check(const absl::Status& s, const char* what) {
  if (!s.ok()) {
    std::cerr << what << " failed: " << s << "\n";
    std::exit(1);
  }
}

// The frame as a depth camera would send it: z = 615 / d (the paper's conversion) in 16-bit
// millimetres, 0 where the disparity is invalid.
OwnedDepth AsDepth(const tsukuba::Frame& f) {
  OwnedDepth out;
  out.width = f.disparity.width;
  out.height = f.disparity.height;
  out.encoding = DepthEncoding::kU16;
  out.pixels.resize(std::size_t{out.width} * out.height * 2);
  const DisparityView d = f.disparity.view();
  for (std::uint32_t v = 0; v < out.height; ++v) {
    for (std::uint32_t u = 0; u < out.width; ++u) {
      const std::uint8_t disparity = d.row(v)[u];
      // Beyond 65.535 m (disparities under 10) a 16-bit camera has no reading either.
      const long mm = disparity == 0 ? 0 : std::lround(615000.0 / disparity);
      const auto sample = static_cast<std::uint16_t>(mm > 65535 ? 0 : mm);
      std::memcpy(&out.pixels[2 * (std::size_t{v} * out.width + u)], &sample, 2);
    }
  }
  return out;
}

// The frame as a stereo matcher's 16-bit fixed point (OpenCV's 1/16 pixel): the same points as
// the 8-bit map, at the depth image's sample width.
OwnedDisparity AsFixedPoint(const tsukuba::Frame& f) {
  OwnedDisparity out;
  out.width = f.disparity.width;
  out.height = f.disparity.height;
  out.encoding = DisparityEncoding::kU16;
  out.pixels.resize(std::size_t{out.width} * out.height * 2);
  const DisparityView d = f.disparity.view();
  for (std::uint32_t v = 0; v < out.height; ++v) {
    for (std::uint32_t u = 0; u < out.width; ++u) {
      const auto sample = static_cast<std::uint16_t>(d.row(v)[u] * 16);
      std::memcpy(&out.pixels[2 * (std::size_t{v} * out.width + u)], &sample, 2);
    }
  }
  return out;
}

// First-seen order against key (PCL's) order, per frame: the chain's time, and the Draco bytes and
// encode time of its output at the codec's defaults (speed 10: the sequential coder, which
// predicts each point from the one before, so order changes the bytes).
int KeyOrderTable(const std::vector<tsukuba::Frame>& frames, int iterations, int warmup) {
  Pipeline pipeline;
  PipelineOptions first_seen, key_order;
  key_order.voxel.key_order = true;
  const DracoOptions draco;  // defaults: speed 10, 10 position bits
  std::printf("%-6s %7s | %9s %9s %7s | %9s %9s %7s | %9s %9s\n", "frame", "voxels", "chain ms",
              "+key ms", "sort ms", "bytes", "key bytes", "ratio", "enc ms", "key enc");
  double sum[6] = {};
  std::size_t total_bytes[2] = {};
  for (const tsukuba::Frame& f : frames) {
    const CameraModel camera = CameraModel::PclCompatible(f.disparity.width, f.disparity.height);
    first_seen.camera = key_order.camera = camera;
    PointCloud a, b;
    std::vector<double> ta, tb, ea, eb;
    std::string bytes_a, bytes_b;
    for (int i = -warmup; i < iterations; ++i) {
      // Alternate which goes first, as cloudcast-bench does.
      const bool flip = i % 2 != 0;
      double t1 = 0, t2 = 0;
      for (int k = 0; k < 2; ++k) {
        if ((k == 0) != flip) {
          t1 = TimeMs([&] {
            Check(pipeline.Run(first_seen, f.disparity.view(), f.colour.view(), &a), "chain");
          });
        } else {
          t2 = TimeMs([&] {
            Check(pipeline.Run(key_order, f.disparity.view(), f.colour.view(), &b), "chain");
          });
        }
      }
      const double e1 = TimeMs([&] { Check(EncodeDraco(a, draco, &bytes_a), "draco"); });
      const double e2 = TimeMs([&] { Check(EncodeDraco(b, draco, &bytes_b), "draco"); });
      if (i >= 0) ta.push_back(t1), tb.push_back(t2), ea.push_back(e1), eb.push_back(e2);
    }
    const double m[4] = {Median(ta), Median(tb), Median(ea), Median(eb)};
    const double ratio = bytes_a.empty() ? 1.0 : double(bytes_b.size()) / bytes_a.size();
    std::printf("%-6s %7zu | %9.3f %9.3f %7.3f | %9zu %9zu %7.3f | %9.3f %9.3f\n", f.id.c_str(),
                a.size(), m[0], m[1], m[1] - m[0], bytes_a.size(), bytes_b.size(), ratio, m[2],
                m[3]);
    for (int k = 0; k < 4; ++k) sum[k] += m[k];
    total_bytes[0] += bytes_a.size(), total_bytes[1] += bytes_b.size();
  }
  const double n = static_cast<double>(frames.size());
  std::printf("%-6s %7s | %9.3f %9.3f %7.3f | %9zu %9zu %7.3f | %9.3f %9.3f\n", "mean", "",
              sum[0] / n, sum[1] / n, (sum[1] - sum[0]) / n, total_bytes[0] / frames.size(),
              total_bytes[1] / frames.size(),
              total_bytes[0] ? double(total_bytes[1]) / total_bytes[0] : 1.0, sum[2] / n,
              sum[3] / n);
  std::printf(
      "sort ms: key-order chain minus first-seen chain (medians); bytes: EncodeDraco at "
      "its defaults (speed 10, 10 bits); enc ms: its median time\n");
  return 0;
}

int Main(int argc, char** argv) {
  CLI::App app{
      "cloudcast-chain-bench: the fused chain (disparity + colour -> passthrough -> voxel grid)\n"
      "alone on the New Tsukuba frames, paper parameters; medians per frame."};
  std::string data_dir = tsukuba::DefaultDir();
  std::string only;
  int iterations = 51;
  int warmup = 3;
  bool callgrind = false, key_order = false;
  std::string json_path;
  app.add_option("--data", data_dir, "New Tsukuba folder")->capture_default_str();
  app.add_option("--frame", only, "only this frame id (e.g. 00001)");
  app.add_option("--iterations", iterations, "timed runs per frame")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  app.add_option("--warmup", warmup, "untimed runs first")
      ->check(CLI::Range(0, 1000))
      ->capture_default_str();
  app.add_flag("--callgrind", callgrind,
               "under valgrind --tool=callgrind --collect-atstart=no: count only the timed runs "
               "(warm), no eviction, no Draco");
  app.add_flag("--key-order", key_order,
               "compare first-seen and key (PCL) order: chain time, Draco bytes and encode time "
               "(with --callgrind: count the chain in key order)");
  app.add_option("--json", json_path, "also write the table as JSON to this file");
  CLI11_PARSE(app, argc, argv);

  auto loaded = tsukuba::LoadAll(data_dir);
  if (!loaded.ok()) {
    std::cerr << "no New Tsukuba frames at " << data_dir << ": " << loaded.status() << "\n";
    return 1;
  }
  std::vector<tsukuba::Frame> frames;
  for (tsukuba::Frame& f : *loaded) {
    if (only.empty() || f.id == only) frames.push_back(std::move(f));
  }
  if (frames.empty()) {
    std::cerr << "frame " << only << " not found\n";
    return 1;
  }

  Pipeline pipeline, depth_pipeline;
  PipelineOptions options;  // paper parameters
  PointCloud out;
  StageCounts counts;

  if (callgrind) {
    options.voxel.key_order = key_order;  // the cost of the sort, in instructions
    for (const tsukuba::Frame& f : frames) {
      options.camera = CameraModel::PclCompatible(f.disparity.width, f.disparity.height);
      for (int i = 0; i < warmup; ++i) {
        Check(pipeline.Run(options, f.disparity.view(), f.colour.view(), &out), "chain");
      }
#ifdef CLOUDCAST_HAVE_CALLGRIND
      CALLGRIND_TOGGLE_COLLECT;
#endif
      for (int i = 0; i < iterations; ++i) {
        Check(pipeline.Run(options, f.disparity.view(), f.colour.view(), &out, &counts), "chain");
      }
#ifdef CLOUDCAST_HAVE_CALLGRIND
      CALLGRIND_TOGGLE_COLLECT;
#endif
      std::printf("%s: %llu passed, %llu voxels\n", f.id.c_str(),
                  static_cast<unsigned long long>(counts.after_passthrough),
                  static_cast<unsigned long long>(counts.after_voxel));
    }
    return 0;
  }

  if (key_order) return KeyOrderTable(frames, iterations, warmup);

  std::printf("%-6s %8s %8s %9s %9s %9s | %9s | %9s %8s %8s %6s %6s\n", "frame", "passed", "voxels",
              "warm ms", "cold ms", "scan ms", "u16 ms", "depth ms", "passed", "voxels", "/u8",
              "/u16");
  double sum_warm = 0, sum_cold = 0, sum_scan = 0, sum_depth = 0, sum_u16 = 0;
  Pipeline u16_pipeline;
  PipelineOptions scan_only = options;
  scan_only.voxel.enabled = false;
  nlohmann::json rows = nlohmann::json::array();
  for (const tsukuba::Frame& f : frames) {
    options.camera = CameraModel::PclCompatible(f.disparity.width, f.disparity.height);
    scan_only.camera = options.camera;
    const OwnedDepth depth = AsDepth(f);
    const OwnedDisparity fixed = AsFixedPoint(f);
    PipelineOptions fixed_options = options;
    fixed_options.camera.disparity_scale = 1.0 / 16;
    fixed_options.camera.invalid_disparities = {0};
    std::vector<double> warm, cold, scan, depth_ms, u16_ms;
    PointCloud passed, depth_out;
    StageCounts depth_counts;
    for (int i = -warmup; i < iterations; ++i) {
      const double tw = TimeMs([&] {
        Check(pipeline.Run(options, f.disparity.view(), f.colour.view(), &out, &counts), "chain");
      });
      EvictCaches();
      const double tc = TimeMs([&] {
        Check(pipeline.Run(options, f.disparity.view(), f.colour.view(), &out, &counts), "chain");
      });
      const double ts = TimeMs([&] {
        Check(pipeline.Run(scan_only, f.disparity.view(), f.colour.view(), &passed), "scan");
      });
      const double td = TimeMs([&] {
        Check(depth_pipeline.Run(options, depth.view(), f.colour.view(), &depth_out, &depth_counts),
              "depth chain");
      });
      const double tu = TimeMs([&] {
        Check(u16_pipeline.Run(fixed_options, fixed.view(), f.colour.view(), &depth_out),
              "u16 chain");
      });
      if (i >= 0) {
        warm.push_back(tw), cold.push_back(tc), scan.push_back(ts), depth_ms.push_back(td);
        u16_ms.push_back(tu);
      }
    }
    const double mw = Median(warm), mc = Median(cold), ms = Median(scan), md = Median(depth_ms);
    const double mu = Median(u16_ms);
    sum_warm += mw, sum_cold += mc, sum_scan += ms, sum_depth += md, sum_u16 += mu;
    std::printf("%-6s %8llu %8llu %9.3f %9.3f %9.3f | %9.3f | %9.3f %8llu %8llu %5.2fx %5.2fx\n",
                f.id.c_str(), static_cast<unsigned long long>(counts.after_passthrough),
                static_cast<unsigned long long>(counts.after_voxel), mw, mc, ms, mu, md,
                static_cast<unsigned long long>(depth_counts.after_passthrough),
                static_cast<unsigned long long>(depth_counts.after_voxel), md / mw, md / mu);
    rows.push_back({{"frame", f.id},
                    {"passed", counts.after_passthrough},
                    {"voxels", counts.after_voxel},
                    {"warm_ms", mw},
                    {"cold_ms", mc},
                    {"scan_ms", ms},
                    {"depth_ms", md},
                    {"u16_disparity_ms", mu},
                    {"depth_passed", depth_counts.after_passthrough},
                    {"depth_voxels", depth_counts.after_voxel}});
  }
  const double n = static_cast<double>(frames.size());
  std::printf("%-6s %8s %8s %9.3f %9.3f %9.3f | %9.3f | %9.3f %8s %8s %5.2fx %5.2fx\n", "mean", "",
              "", sum_warm / n, sum_cold / n, sum_scan / n, sum_u16 / n, sum_depth / n, "", "",
              sum_depth / sum_warm, sum_depth / sum_u16);
  std::printf(
      "(warm: the 8-bit disparity map; u16: the same as 1/16-pixel fixed point; depth: the "
      "same as 16-bit millimetres, z = 615 / d; /u8, /u16: depth against each; medians of "
      "%d runs, all warm)\n",
      iterations);
  if (!json_path.empty()) {
    std::ofstream(json_path) << nlohmann::json{{"iterations", iterations}, {"frames", rows}}.dump(2)
                             << "\n";
  }
  return 0;
}

}  // namespace
}  // namespace cloudcast::bench

int main(int argc, char** argv) { return cloudcast::bench::Main(argc, argv); }
