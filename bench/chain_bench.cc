// cloudcast-chain-bench: the fused chain alone, frame by frame, to tune it. Per New Tsukuba
// frame: the points that pass, the voxels, and milliseconds with warm caches and with the caches
// evicted before each run (as in cloudcast-bench, where PCL runs in between). Under callgrind
// (--callgrind) only the measured runs are counted, so instruction counts compare versions
// exactly. --key-order measures what emitting voxels in key order (PCL's order) does to the
// Draco bytes and times.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/core/tsukuba.h"

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
  static std::vector<std::uint64_t> junk(8 << 17);  // 8 MB
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

int Main(int argc, char** argv) {
  CLI::App app{
      "cloudcast-chain-bench: the fused chain (disparity + colour -> passthrough -> voxel grid)\n"
      "alone on the New Tsukuba frames, paper parameters; medians per frame."};
  std::string data_dir = tsukuba::DefaultDir();
  std::string only;
  int iterations = 51;
  int warmup = 3;
  bool callgrind = false, key_order = false;
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
               "also compare Draco bytes and encode times for first-seen and key (PCL) order");
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

  Pipeline pipeline;
  PipelineOptions options;  // paper parameters
  PointCloud out;
  StageCounts counts;

  if (callgrind) {
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

  std::printf("%-6s %8s %8s %9s %9s %9s\n", "frame", "passed", "voxels", "warm ms", "cold ms",
              "scan ms");
  double sum_warm = 0, sum_cold = 0, sum_scan = 0;
  PipelineOptions scan_only = options;
  scan_only.voxel.enabled = false;
  for (const tsukuba::Frame& f : frames) {
    options.camera = CameraModel::PclCompatible(f.disparity.width, f.disparity.height);
    scan_only.camera = options.camera;
    std::vector<double> warm, cold, scan;
    PointCloud passed;
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
      if (i >= 0) warm.push_back(tw), cold.push_back(tc), scan.push_back(ts);
    }
    const double mw = Median(warm), mc = Median(cold), ms = Median(scan);
    sum_warm += mw, sum_cold += mc, sum_scan += ms;
    std::printf("%-6s %8llu %8llu %9.3f %9.3f %9.3f\n", f.id.c_str(),
                static_cast<unsigned long long>(counts.after_passthrough),
                static_cast<unsigned long long>(counts.after_voxel), mw, mc, ms);
  }
  const double n = static_cast<double>(frames.size());
  std::printf("%-6s %8s %8s %9.3f %9.3f %9.3f\n", "mean", "", "", sum_warm / n, sum_cold / n,
              sum_scan / n);
  return 0;
}

}  // namespace
}  // namespace cloudcast::bench

int main(int argc, char** argv) { return cloudcast::bench::Main(argc, argv); }
