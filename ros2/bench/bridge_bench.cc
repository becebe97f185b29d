// cloudcast-ros2-bridge-bench: the ROS 2 bridge's cost per frame and its latency, measured as
// ros/bench/bridge_bench.py measures the ROS 1 bridge (docs/ros.md), on the same New Tsukuba
// frames, so that the two tables sit side by side (docs/ros2.md).
//
// In a network namespace of its own (root): a cloudcast-server and the bridge as processes, a
// Cyclone camera in this process publishing disparity + colour + camera_info at each rate
// (stamped with the wall clock at publishing), and a subscriber of the clouds. Per consumer and
// rate: frames published, clouds out, clouds/s (first to last cloud), latency (stamp to arrival
// here; median), CPU ms per cloud of the bridge and the server together (from /proc ticks of
// 10 ms) and of the bridge alone, points and bytes per cloud (medians).
//
//   cloudcast-ros2-bridge-bench --bin-dir build/bin --data ../shared/data/new_tsukuba
//       [--frames 100] [--rates 10,20,30] [--uplinks raw,zstd,h264] [--json]
//
// --uplinks: the paper-filter bridge once per ~encoding instead of the two filter settings, with
// the uplink's bytes per cloud and kbit/s (the bridge's /diagnostics: what the server counted).
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "cloudcast/datasets/tsukuba.h"
#include "dds_node.h"
#include "ros2_harness.h"
#include "ros2_inputs.h"
#include "tsukuba_samples.h"

namespace {

using namespace cloudcast;
using namespace cloudcast::ros2_bridge;
using Clock = std::chrono::steady_clock;

// utime + stime of a process, in clock ticks.
long long CpuTicks(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto close = text.rfind(')');
  if (close == std::string::npos) return 0;
  std::istringstream rest(text.substr(close + 2));
  std::string field;
  long long utime = 0, stime = 0;
  for (int i = 3; i <= 15 && rest >> field; ++i) {
    if (i == 14) utime = std::stoll(field);
    if (i == 15) stime = std::stoll(field);
  }
  return utime + stime;
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

struct Row {
  std::string consumer;
  int rate = 0, published = 0, clouds = 0;
  double clouds_per_s = 0, latency_ms = 0, cpu_ms = 0, bridge_cpu_ms = 0, points = 0, bytes = 0;
  // From the bridge's last /diagnostics: frames the server skipped (delivery latest), sets the
  // inputs refused or could not pair, and the last error.
  std::string dropped = "-", input_errors = "-", last_error;
  // The uplink (median over the /diagnostics periods with clouds): bytes per cloud, kbit/s.
  double uplink_bytes = 0, uplink_kbps = 0;
};

double WallSeconds() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

Row Run(const std::string& bin, const std::string& scratch, const std::string& consumer,
        const std::vector<std::string>& params, int rate, int frames,
        std::vector<std::unique_ptr<testing::TsukubaSamples>>& samples) {
  Row row;
  row.consumer = consumer;
  row.rate = rate;
  const int port = testing::FreePort();
  const std::string address = "127.0.0.1:" + std::to_string(port);
  testing::ChildProcess server({bin + "/cloudcast-server", "--listen", address,
                                "--metrics-listen", "", "--log-level", "warn"},
                               scratch + "/server.log");
  if (!testing::WaitForPort(port, 20)) {
    std::fprintf(stderr, "bench: the server did not start:\n%s\n", server.Log().c_str());
    return row;
  }
  std::vector<std::string> argv = {bin + "/cloudcast-ros2-bridge", "--ros-args", "-r",
                                   "__ns:=/stereo", "-p", "server:=" + address, "-p",
                                   "input_qos:=default"};
  for (const auto& p : params) {
    argv.push_back("-p");
    argv.push_back(p);
  }
  testing::ChildProcess bridge(argv, scratch + "/bridge.log");
  auto node = DdsNode::Create(0);
  if (!node.ok()) return row;
  auto wd = (*node)->CreateWriter(kDisparityImageType, "/stereo/disparity", DefaultQos());
  auto wc = (*node)->CreateWriter(kImageType, "/stereo/left/image_rect_color", DefaultQos());
  auto wi = (*node)->CreateWriter(kCameraInfoType, "/stereo/left/camera_info", DefaultQos());
  auto rp = (*node)->CreateReader(kPointCloud2Type, "/stereo/points2", DefaultQos());
  auto rd = (*node)->CreateReader(kDiagnosticArrayType, "/diagnostics", DefaultQos());
  if (!wd.ok() || !wc.ok() || !wi.ok() || !rp.ok() || !rd.ok()) return row;

  struct Arrival {
    double latency_ms;
    double points, bytes;
    Clock::time_point at;
  };
  std::vector<Arrival> arrivals;
  auto take = [&](bool record) {
    for (;;) {
      TakenSample s(kPointCloud2Type);
      void* buf[1] = {s.get()};
      dds_sample_info_t info;
      if (dds_take(*rp, buf, &info, 1, 1) <= 0) break;
      if (!info.valid_data || !record) continue;
      const auto& c = s.as<sensor_msgs_msg_dds__PointCloud2_>();
      const double stamp = c.header.stamp.sec + c.header.stamp.nanosec / 1e9;
      arrivals.push_back({(WallSeconds() - stamp) * 1000.0, static_cast<double>(c.width),
                          static_cast<double>(c.data._length), Clock::now()});
    }
  };
  std::vector<double> uplink_bytes, uplink_kbps;
  auto take_diagnostics = [&](bool record) {
    for (;;) {
      TakenSample s(kDiagnosticArrayType);
      void* buf[1] = {s.get()};
      dds_sample_info_t info;
      if (dds_take(*rd, buf, &info, 1, 1) <= 0) break;
      if (!info.valid_data) continue;
      const auto& a = s.as<diagnostic_msgs_msg_dds__DiagnosticArray_>();
      for (std::uint32_t i = 0; i < a.status._length; ++i) {
        const auto& values = a.status._buffer[i].values;
        std::map<std::string, std::string> v;
        for (std::uint32_t j = 0; j < values._length; ++j) {
          v[values._buffer[j].key] = values._buffer[j].value;
        }
        if (v.count("frames_dropped")) row.dropped = v["frames_dropped"];
        if (v.count("input_errors")) row.input_errors = v["input_errors"];
        if (v.count("last_error")) row.last_error = v["last_error"];
        const double per_cloud = v.count("uplink_bytes_per_cloud")
                                     ? std::atof(v["uplink_bytes_per_cloud"].c_str())
                                     : 0.0;
        if (record && per_cloud > 0) {
          uplink_bytes.push_back(per_cloud);
          uplink_kbps.push_back(std::atof(v["uplink_kbps"].c_str()));
        }
      }
    }
  };
  auto publish = [&](int k) {
    testing::TsukubaSamples& s = *samples[static_cast<std::size_t>(k) % samples.size()];
    const double now = WallSeconds();
    const auto sec = static_cast<std::int32_t>(now);
    s.Stamp(sec, static_cast<std::uint32_t>((now - sec) * 1e9));
    dds_write(*wd, &s.disparity);
    dds_write(*wc, &s.colour);
    dds_write(*wi, &s.info);
  };
  // Warm-up: until a cloud comes back (discovery, the stream opened), not counted.
  const auto warm_end = Clock::now() + std::chrono::seconds(30);
  int k = 0;
  while (Clock::now() < warm_end && arrivals.empty()) {
    publish(k++);
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    take(true);
  }
  if (arrivals.empty()) {
    std::fprintf(stderr, "bench: no cloud in 30 s:\n%s\n", bridge.Log().c_str());
    return row;
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  take(false);
  take_diagnostics(false);
  arrivals.clear();
  const long long cpu0 = CpuTicks(bridge.pid()) + CpuTicks(server.pid());
  const long long bridge0 = CpuTicks(bridge.pid());
  const auto period = std::chrono::duration<double>(1.0 / rate);
  auto next = Clock::now();
  for (int i = 0; i < frames; ++i) {
    publish(k++);
    next += std::chrono::duration_cast<Clock::duration>(period);
    while (Clock::now() < next) {
      take(true);
      take_diagnostics(true);
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }
  row.published = frames;
  const auto drain_end = Clock::now() + std::chrono::seconds(3);
  while (Clock::now() < drain_end && static_cast<int>(arrivals.size()) < frames) {
    take(true);
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  const long long cpu1 = CpuTicks(bridge.pid()) + CpuTicks(server.pid());
  std::this_thread::sleep_for(std::chrono::milliseconds(1200));  // one more diagnostics period
  take_diagnostics(false);
  row.uplink_bytes = Median(uplink_bytes);
  row.uplink_kbps = Median(uplink_kbps);
  const long long bridge1 = CpuTicks(bridge.pid());
  row.clouds = static_cast<int>(arrivals.size());
  if (row.clouds == 0) return row;
  const double tick_ms = 1000.0 / static_cast<double>(sysconf(_SC_CLK_TCK));
  row.cpu_ms = (cpu1 - cpu0) * tick_ms / row.clouds;
  row.bridge_cpu_ms = (bridge1 - bridge0) * tick_ms / row.clouds;
  std::vector<double> lat, pts, bytes;
  for (const auto& a : arrivals) {
    lat.push_back(a.latency_ms);
    pts.push_back(a.points);
    bytes.push_back(a.bytes);
  }
  row.latency_ms = Median(lat);
  row.points = Median(pts);
  row.bytes = Median(bytes);
  const double span = std::chrono::duration<double>(arrivals.back().at - arrivals.front().at).count();
  row.clouds_per_s = span > 0 ? (row.clouds - 1) / span : 0;
  return row;
}

int Usage(const char* why) {
  std::fprintf(stderr,
               "cloudcast-ros2-bridge-bench: %s\nusage: cloudcast-ros2-bridge-bench --bin-dir DIR "
               "--data DIR [--frames 100] [--rates 10,20,30] [--uplinks raw,zstd,h264] [--json]\n",
               why);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  std::string bin, data = tsukuba::DefaultDir();
  int frames = 100;
  std::vector<int> rates = {10, 20, 30};
  bool json = false;
  std::vector<std::string> uplinks;
  for (int i = 1; i < argc; ++i) {
    const std::string f = argv[i];
    if (f == "--help" || f == "-h") return Usage("the ROS 2 bridge's CPU per cloud and latency");
    if (f == "--json") {
      json = true;
      continue;
    }
    if (i + 1 >= argc) return Usage(("missing value of " + f).c_str());
    const std::string v = argv[++i];
    if (f == "--bin-dir") {
      bin = v;
    } else if (f == "--data") {
      data = v;
    } else if (f == "--frames") {
      frames = std::atoi(v.c_str());
    } else if (f == "--uplinks") {
      std::stringstream ss(v);
      for (std::string u; std::getline(ss, u, ',');) {
        if (u != "raw" && u != "zstd" && u != "h264") {
          return Usage(("--uplinks: '" + u + "' is not raw, zstd or h264").c_str());
        }
        uplinks.push_back(u);
      }
    } else if (f == "--rates") {
      rates.clear();
      std::stringstream ss(v);
      for (std::string r; std::getline(ss, r, ',');) rates.push_back(std::atoi(r.c_str()));
    } else {
      return Usage(("unknown flag " + f).c_str());
    }
  }
  if (bin.empty()) return Usage("--bin-dir is required");
  if (frames < 1) return Usage("--frames must be >= 1");
  for (int r : rates) {
    if (r < 1) return Usage("--rates must be >= 1 each");
  }
  if (const std::string why = testing::EnterNetworkNamespace(); !why.empty()) {
    return Usage(why.c_str());
  }
  std::vector<tsukuba::Frame> loaded;
  for (const std::string& id : tsukuba::FrameIds()) {
    auto f = tsukuba::Load(data, id);
    if (!f.ok()) return Usage(std::string(f.status().message()).c_str());
    loaded.push_back(*std::move(f));
  }
  std::vector<std::unique_ptr<testing::TsukubaSamples>> samples;
  for (const auto& f : loaded) samples.push_back(std::make_unique<testing::TsukubaSamples>(f));
  char scratch_template[] = "/tmp/cloudcast-ros2-bench-XXXXXX";
  const std::string scratch = mkdtemp(scratch_template);
  // The ROS 1 benchmark's two bridge configurations (ros/bench/bridge_bench.py).
  std::vector<std::pair<std::string, std::vector<std::string>>> consumers = {
      {"ROS 2 bridge, no filters",
       {"passthrough.enabled:=false", "voxel.enabled:=false", "draco.position_bits:=16"}},
      {"ROS 2 bridge, paper filters",
       {"passthrough.enabled:=true", "passthrough.min:=0.3", "passthrough.max:=8.0",
        "voxel.enabled:=true", "voxel.leaf:=0.03"}},
  };
  if (!uplinks.empty()) {
    // The paper-filter bridge once per ~encoding (h264 at the rate's VBV: h264.fps per run).
    const auto paper = consumers[1].second;
    consumers.clear();
    for (const std::string& u : uplinks) {
      std::vector<std::string> params = paper;
      params.push_back("encoding:=" + u);
      consumers.emplace_back("ROS 2 bridge, paper filters, encoding " + u, params);
    }
  }
  std::vector<Row> rows;
  for (int rate : rates) {
    for (const auto& [name, params] : consumers) {
      std::vector<std::string> with = params;
      if (std::find(with.begin(), with.end(), "encoding:=h264") != with.end()) {
        with.push_back("h264.fps:=" + std::to_string(rate) + ".0");
      }
      rows.push_back(Run(bin, scratch, name, with, rate, frames, samples));
      std::fprintf(stderr, "bench: %s at %d Hz: %d clouds; the bridge: %s dropped by the server, "
                   "%s input errors%s%s\n", name.c_str(), rate, rows.back().clouds,
                   rows.back().dropped.c_str(), rows.back().input_errors.c_str(),
                   rows.back().last_error.empty() ? "" : "; last: ",
                   rows.back().last_error.c_str());
    }
  }
  std::printf(
      "| consumer | publisher rate | published | clouds | clouds/s | latency ms (median) | CPU ms "
      "/ cloud (bridge + server) | CPU ms / cloud (bridge) | points (median) | cloud bytes "
      "(median) | uplink bytes / cloud | uplink kbit/s | server-skipped | input errors |\n"
      "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
  for (const Row& r : rows) {
    std::printf(
        "| %s | %d Hz | %d | %d | %.1f | %.1f | %.1f | %.1f | %.0f | %.0f | %.0f | %.0f | %s | %s "
        "|\n",
        r.consumer.c_str(), r.rate, r.published, r.clouds, r.clouds_per_s, r.latency_ms, r.cpu_ms,
        r.bridge_cpu_ms, r.points, r.bytes, r.uplink_bytes, r.uplink_kbps, r.dropped.c_str(),
        r.input_errors.c_str());
  }
  if (json) {
    std::printf("[");
    for (std::size_t i = 0; i < rows.size(); ++i) {
      const Row& r = rows[i];
      std::printf(
          "%s{\"consumer\": \"%s\", \"rate_hz\": %d, \"published\": %d, \"clouds\": %d, "
          "\"clouds_per_s\": %.2f, \"latency_ms_median\": %.2f, \"cpu_ms_per_cloud\": %.2f, "
          "\"bridge_cpu_ms_per_cloud\": %.2f, \"points_median\": %.0f, \"bytes_median\": %.0f, "
          "\"uplink_bytes_per_cloud_median\": %.0f, \"uplink_kbps_median\": %.0f}",
          i ? ", " : "", r.consumer.c_str(), r.rate, r.published, r.clouds, r.clouds_per_s,
          r.latency_ms, r.cpu_ms, r.bridge_cpu_ms, r.points, r.bytes, r.uplink_bytes,
          r.uplink_kbps);
    }
    std::printf("]\n");
  }
  std::filesystem::remove_all(scratch);
  return 0;
}
