// cloudcast-e2e-bench: the whole service over loopback. It starts `cloudcast-server` as a child
// process, streams New Tsukuba frames (or synthetic ones) through 1, 2 and 4 concurrent streams,
// raw, zstd-compressed (the compressed uplink) and PNG-encoded, and reports frames per second,
// latency percentiles and the server's CPU per frame, split into the share inside the core
// pipeline + Draco and the share outside them.
//
// Every stream is a robot of its own, with a Client (a connection) of its own;
// --shared-connection puts a case's streams on one connection, as one robot with several cameras.
//
// Two runs per case:
//   throughput  every stream sends as fast as the server answers (delivery "all", a window of
//               frames in flight per stream);
//   paced       every stream sends at --paced-fps (delivery "latest"), the real-time use.
// Latency: in the throughput runs (a closed loop) send to reply, on the client's steady clock;
// in the paced runs from each frame's intended send time on the schedule, so a sender that
// falls behind (flow control, a slow server) shows up in the latency instead of hiding it.
//
// --encodings h264: the colour images as H.264 pictures (the --h264-* flags, as cloudcast-client
// and cloudcast-load take them), the disparity as zstd. The pictures are encoded once, up front,
// into one sequence (10 frames cycled to a keyframe interval, an IDR first) that every stream
// sends in order from its IDR, going back to it when a reply asks for an IDR, so the robots'
// encoding stays off these shared cores (it costs 5 to 7 ms a picture: docs/video.md). Both of
// its runs use DELIVERY_ALL: the client library's stream replaces a frame that waits for the
// write slot under DELIVERY_LATEST, which would leave a hole in the bitstream.
//
// --compare-bin runs every case on a second server binary too (an older build, say), the two
// in turn and in alternating order, over --rounds rounds, and prints both sides' medians and
// their ratios: the way to measure a change on a noisy machine.
// The client does not decode the Draco replies here (a robot decodes on its own machine); the
// client and the server share this machine's cores, so the figures are a lower bound.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <thread>
#include <vector>

#include "cloudcast/cli/video_flags.h"
#include "cloudcast/client/client.h"
#include "cloudcast/client/config.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/datasets/tsukuba.h"
#include "cloudcast/io/image_io.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/sources/uplink.h"
#include "cloudcast/testing/metrics_scrape.h"
#include "cloudcast/video/frame_encoder.h"
#include "stats.h"

namespace cloudcast::bench {
namespace {

using Clock = std::chrono::steady_clock;
namespace cc = cloudcast::client;

struct Frame {
  OwnedDisparity disparity;
  OwnedColor colour;
  std::string disparity_png, colour_png;
  // The compressed uplink (row deltas + zstd, the client library's default), compressed once.
  v1::CompressedDisparity disparity_zstd;
  v1::CompressedColor colour_zstd;
};

// The client programs' uplink names; this bench encodes its frames up front (jpeg it leaves out).
using sources::Uplink;

// --encodings h264: one picture sequence, encoded up front, that each stream sends in order.
struct VideoSequence {
  std::vector<v1::VideoPicture> pictures;  // picture i goes with the disparity of frame_of[i]
  std::vector<std::size_t> frame_of;
  double encode_ms = 0;  // thread CPU per picture, median
};

double ThreadCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) / 1e6;
}

int FreePort() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  socklen_t len = sizeof a;
  if (bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 ||
      getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) != 0) {
    close(fd);
    return -1;
  }
  const int port = ntohs(a.sin_port);
  close(fd);
  return port;
}

// User + system CPU of a process (all its threads, exited ones too), seconds, from its CPU-time
// clock: nanoseconds, where /proc/PID/stat counts 10 ms ticks (a paced case of a few dozen
// frames could read 0).
double ProcessCpuSeconds(pid_t pid) {
  clockid_t clock;
  timespec t{};
  if (clock_getcpuclockid(pid, &clock) != 0 || clock_gettime(clock, &t) != 0) return -1;
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

class ServerProcess {
 public:
  ServerProcess(const std::string& binary, int threads) {
    port_ = FreePort();
    metrics_port_ = FreePort();
    pid_ = fork();
    if (pid_ == 0) {
      const std::string listen = "127.0.0.1:" + std::to_string(port_);
      const std::string metrics = "127.0.0.1:" + std::to_string(metrics_port_);
      const std::string t = std::to_string(threads);
      execl(binary.c_str(), binary.c_str(), "--listen", listen.c_str(), "--metrics-listen",
            metrics.c_str(), "--threads", t.c_str(), "--log-level", "warn", "--max-streams", "64",
            static_cast<char*>(nullptr));
      std::perror("exec cloudcast-server");
      _exit(127);
    }
  }
  ~ServerProcess() {
    if (pid_ > 0) {
      kill(pid_, SIGTERM);
      int status = 0;
      waitpid(pid_, &status, 0);
    }
  }
  pid_t pid() const { return pid_; }
  int port() const { return port_; }
  int metrics_port() const { return metrics_port_; }
  double CoreCpuSeconds() const {
    return server::MetricValue(server::ScrapeMetrics(metrics_port_),
                               "cloudcast_core_cpu_seconds_total");
  }

 private:
  pid_t pid_ = -1;
  int port_ = 0, metrics_port_ = 0;
};

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * (v.size() - 1) + 0.5)];
}

struct CaseResult {
  std::string server, encoding, mode;  // server: the contender's label
  int round = 0, streams = 0;
  double seconds = 0, fps = 0, p50 = 0, p90 = 0, p99 = 0;
  std::uint64_t frames = 0, errors = 0, dropped = 0;
  std::uint64_t keyframe_requests = 0;  // h264: replies that asked for an IDR
  double server_cpu_ms_per_frame = 0, core_cpu_ms_per_frame = 0, outside_share = 0;
  double client_cpu_ms_per_frame = 0;  // this process: the senders, gRPC's client side

  // Robots at 30 frames/s one server core carries at this case's server CPU per frame.
  double RobotsPerCore() const {
    return server_cpu_ms_per_frame > 0 ? 1000.0 / (30 * server_cpu_ms_per_frame) : 0;
  }

  nlohmann::json ToJson() const {
    return {{"server", server},
            {"round", round},
            {"encoding", encoding},
            {"mode", mode},
            {"streams", streams},
            {"seconds", seconds},
            {"fps", fps},
            {"latency_ms_p50", p50},
            {"latency_ms_p90", p90},
            {"latency_ms_p99", p99},
            {"frames", frames},
            {"errors", errors},
            {"dropped", dropped},
            {"keyframe_requests", keyframe_requests},
            {"robots_per_server_core_at_30fps", RobotsPerCore()},
            {"server_cpu_ms_per_frame", server_cpu_ms_per_frame},
            {"client_cpu_ms_per_frame", client_cpu_ms_per_frame},
            {"core_cpu_ms_per_frame", core_cpu_ms_per_frame},
            {"outside_core_share", outside_share}};
  }
};

// What every case shares.
struct CaseOptions {
  double seconds = 4;  // measured
  int window = 4;      // frames in flight per stream in the throughput runs
  // false: every stream is a robot of its own, a Client and a connection each; true: all the
  // streams on one Client (one connection), as one robot with several cameras.
  bool shared_connection = false;
};

// One case: `streams` streams, either as fast as possible with o.window frames in flight per
// stream (paced_fps == 0) or at paced_fps each.
CaseResult RunCase(const ServerProcess& server, const std::vector<Frame>& frames, Uplink uplink,
                   const VideoSequence* video, int streams, double paced_fps,
                   const CaseOptions& o) {
  CaseResult r;
  r.encoding = video != nullptr ? "h264" : Name(uplink);
  r.mode = paced_fps > 0 ? "paced " + std::to_string(static_cast<int>(paced_fps)) + " fps"
                         : "throughput";
  r.streams = streams;
  cc::ClientOptions options;
  options.decode_clouds = false;
  std::vector<std::unique_ptr<cc::Client>> clients;
  for (int c = 0; c < (o.shared_connection ? 1 : streams); ++c) {
    auto client = cc::Client::Connect("127.0.0.1:" + std::to_string(server.port()), options);
    if (!client.ok()) {
      std::cerr << "connect: " << client.status() << "\n";
      std::exit(1);
    }
    clients.push_back(*std::move(client));
  }
  std::mutex mu;
  std::vector<double> latencies;
  std::atomic<std::uint64_t> answered{0}, errors{0}, dropped{0};
  std::atomic<bool> measuring{false}, stop{false};

  struct StreamState {
    std::unique_ptr<cc::Stream> stream;
    std::mutex mu;
    std::condition_variable cv;
    int in_flight = 0;
    std::atomic<bool> restart{false};  // h264: a reply asked for an IDR
  };
  std::atomic<std::uint64_t> keyframe_requests{0};
  std::vector<std::unique_ptr<StreamState>> states;
  for (int s = 0; s < streams; ++s) {
    auto state = std::make_unique<StreamState>();
    StreamState* st = state.get();
    // The paper's setting, stated: the server assumes no camera (docs/migration.md). The
    // synthetic fallback's camera at 640 px is the same.
    cc::StreamConfig config = cc::PresetConfig("new_tsukuba").value();
    config.set_delivery(paced_fps > 0 && video == nullptr ? v1::DELIVERY_LATEST : v1::DELIVERY_ALL);
    cc::StreamOptions so;
    so.on_result = [&, st](cc::Result&& res) {
      {
        std::lock_guard<std::mutex> lock(st->mu);
        --st->in_flight;
      }
      st->cv.notify_one();
      if (video != nullptr && (!res.ok() || res.reply.keyframe_needed_size() > 0)) {
        st->restart = true;
        ++keyframe_requests;
      }
      if (!measuring.load()) return;
      ++answered;
      if (!res.ok()) ++errors;
      dropped = std::max<std::uint64_t>(dropped.load(), res.frames_dropped);
      // Paced: from the intended send time (the frame's capture time, set below).
      const double ms = std::chrono::duration<double, std::milli>(paced_fps > 0 ? res.latency()
                                                                                : res.round_trip())
                            .count();
      std::lock_guard<std::mutex> lock(mu);
      latencies.push_back(ms);
    };
    auto stream = clients[o.shared_connection ? 0 : s]->OpenStream(config, so);
    if (!stream.ok()) {
      std::cerr << "open stream: " << stream.status() << "\n";
      std::exit(1);
    }
    st->stream = *std::move(stream);
    states.push_back(std::move(state));
  }

  auto sender = [&](int s) {
    StreamState& st = *states[s];
    std::size_t i = static_cast<std::size_t>(s) * 3;  // streams start at different frames
    std::size_t picture = 0;                          // h264: every stream from the IDR
    auto next_send = Clock::now();
    // The schedule's times on the Unix clock the replies' latency() is measured in.
    const std::int64_t unix_minus_steady =
        cc::UnixNanosNow() -
        std::chrono::duration_cast<std::chrono::nanoseconds>(next_send.time_since_epoch()).count();
    const auto period = paced_fps > 0 ? std::chrono::duration_cast<Clock::duration>(
                                            std::chrono::duration<double>(1.0 / paced_fps))
                                      : Clock::duration::zero();
    while (!stop.load()) {
      cc::FrameMeta meta;
      if (paced_fps > 0) {
        std::this_thread::sleep_until(next_send);
        meta.capture_time_unix_ns =
            unix_minus_steady +
            std::chrono::duration_cast<std::chrono::nanoseconds>(next_send.time_since_epoch())
                .count();
        next_send += period;
      } else {
        std::unique_lock<std::mutex> lock(st.mu);
        st.cv.wait(lock, [&] { return st.in_flight < o.window || stop.load(); });
        if (stop.load()) break;
      }
      const Frame& f = frames[i++ % frames.size()];
      {
        std::lock_guard<std::mutex> lock(st.mu);
        ++st.in_flight;
      }
      if (video != nullptr && st.restart.exchange(false)) picture = 0;
      const std::size_t p = picture;
      picture = (picture + 1) % (video != nullptr ? video->pictures.size() : 1);
      absl::Status sent =
          video != nullptr
              ? st.stream->Send(
                    cc::PrecompressedDisparity{&frames[video->frame_of[p]].disparity_zstd},
                    cc::PrecodedVideo{&video->pictures[p]}, meta)
          : uplink == Uplink::kPng  ? st.stream->Send(cc::EncodedImage{f.disparity_png},
                                                      cc::EncodedImage{f.colour_png}, meta)
          : uplink == Uplink::kZstd ? st.stream->Send(cc::PrecompressedDisparity{&f.disparity_zstd},
                                                      cc::PrecompressedColor{&f.colour_zstd}, meta)
                                    : st.stream->Send(f.disparity.view(), f.colour.view(), meta);
      if (!sent.ok()) {
        std::cerr << "send: " << sent << "\n";
        break;
      }
    }
  };
  std::vector<std::thread> threads;
  for (int s = 0; s < streams; ++s) threads.emplace_back(sender, s);

  std::this_thread::sleep_for(std::chrono::milliseconds(800));  // warm-up
  const double cpu0 = ProcessCpuSeconds(server.pid());
  const double client0 = ProcessCpuSeconds(getpid());
  const double core0 = server.CoreCpuSeconds();
  measuring = true;
  const auto t0 = Clock::now();
  std::this_thread::sleep_for(std::chrono::duration<double>(o.seconds));
  measuring = false;
  const auto t1 = Clock::now();
  const double cpu1 = ProcessCpuSeconds(server.pid());
  const double client1 = ProcessCpuSeconds(getpid());
  const double core1 = server.CoreCpuSeconds();
  stop = true;
  for (auto& st : states) st->cv.notify_all();
  for (auto& t : threads) t.join();
  for (auto& st : states) (void)st->stream->Finish();

  r.seconds = std::chrono::duration<double>(t1 - t0).count();
  r.frames = answered.load();
  r.errors = errors.load();
  r.dropped = dropped.load();
  r.keyframe_requests = keyframe_requests.load();
  r.fps = r.frames / r.seconds;
  {
    std::lock_guard<std::mutex> lock(mu);
    r.p50 = Percentile(latencies, 0.50);
    r.p90 = Percentile(latencies, 0.90);
    r.p99 = Percentile(latencies, 0.99);
  }
  if (r.frames > 0) {
    r.server_cpu_ms_per_frame = (cpu1 - cpu0) * 1000.0 / r.frames;
    r.client_cpu_ms_per_frame = (client1 - client0) * 1000.0 / r.frames;
    r.core_cpu_ms_per_frame = core0 >= 0 ? (core1 - core0) * 1000.0 / r.frames : 0;
    r.outside_share = r.server_cpu_ms_per_frame > 0
                          ? 1.0 - r.core_cpu_ms_per_frame / r.server_cpu_ms_per_frame
                          : 0;
  }
  return r;
}

std::vector<Frame> LoadFrames(const std::string& dir) {
  std::vector<Frame> frames;
  if (auto loaded = tsukuba::LoadAll(dir); loaded.ok()) {
    for (tsukuba::Frame& t : *loaded) {
      frames.push_back(Frame{std::move(t.disparity), std::move(t.colour), {}, {}, {}, {}});
    }
  }
  if (frames.empty()) {
    for (std::uint64_t i = 0; i < 10; ++i) {
      SyntheticOptions o;
      o.frame = i * 36;
      o.disparity_encoding = DisparityEncoding::kU8;
      auto r = SyntheticScene::Default().Render(o);
      Frame f;
      f.disparity =
          OwnedDisparity{std::move(r->disparity), o.width, o.height, DisparityEncoding::kU8};
      f.colour = OwnedColor{std::move(r->colour), o.width, o.height, ColorEncoding::kBGR8};
      frames.push_back(std::move(f));
    }
  }
  // The PNG uplink: encoded once, as a camera driver would hand them over.
  for (Frame& f : frames) {
    std::vector<std::uint8_t> buf;
    cv::Mat d(static_cast<int>(f.disparity.height), static_cast<int>(f.disparity.width), CV_8UC1,
              f.disparity.pixels.data());
    cv::imencode(".png", d, buf, {cv::IMWRITE_PNG_COMPRESSION, 1});
    f.disparity_png.assign(buf.begin(), buf.end());
    cv::Mat c(static_cast<int>(f.colour.height), static_cast<int>(f.colour.width), CV_8UC3,
              f.colour.pixels.data());
    cv::imencode(".png", c, buf, {cv::IMWRITE_PNG_COMPRESSION, 1});
    f.colour_png.assign(buf.begin(), buf.end());
    (void)convert::ToProto(f.disparity.view(), convert::Compression{}, "disparity",
                           &f.disparity_zstd);
    (void)convert::ToProto(f.colour.view(), convert::Compression{}, "colour", &f.colour_zstd);
  }
  return frames;
}

// One server binary under test, started once and kept for every round.
struct Contender {
  std::string label, binary;
  std::unique_ptr<ServerProcess> server;
};

// Starts the contender's server and waits until it answers.
bool Start(Contender& c, int threads) {
  c.server = std::make_unique<ServerProcess>(c.binary, threads);
  cc::ClientOptions o;
  o.connect_timeout = std::chrono::seconds(10);
  auto client = cc::Client::Connect("127.0.0.1:" + std::to_string(c.server->port()), o);
  if (!client.ok()) {
    std::cerr << c.binary << " did not come up: " << client.status() << "\n";
    return false;
  }
  std::cout << c.label << ": " << c.binary << ", pid " << c.server->pid()
            << ", 127.0.0.1:" << c.server->port() << "\n";
  return true;
}

// The medians over the rounds of each case on each server, in the results' order of first
// appearance: one CaseResult per case and server, round 0, every figure the median of its
// rounds' (frames and errors summed, dropped the most of any round).
std::vector<CaseResult> MediansOf(const std::vector<CaseResult>& results) {
  std::vector<CaseResult> out;
  std::vector<std::vector<const CaseResult*>> groups;
  for (const CaseResult& r : results) {
    auto same = [&](const CaseResult& m) {
      return m.server == r.server && m.encoding == r.encoding && m.mode == r.mode &&
             m.streams == r.streams;
    };
    const auto at =
        static_cast<std::size_t>(std::find_if(out.begin(), out.end(), same) - out.begin());
    if (at == out.size()) {
      CaseResult m;
      m.server = r.server;
      m.encoding = r.encoding;
      m.mode = r.mode;
      m.streams = r.streams;
      out.push_back(m);
      groups.emplace_back();
    }
    groups[at].push_back(&r);
  }
  for (std::size_t i = 0; i < out.size(); ++i) {
    CaseResult& m = out[i];
    for (double CaseResult::*field :
         {&CaseResult::seconds, &CaseResult::fps, &CaseResult::p50, &CaseResult::p90,
          &CaseResult::p99, &CaseResult::server_cpu_ms_per_frame,
          &CaseResult::core_cpu_ms_per_frame, &CaseResult::outside_share,
          &CaseResult::client_cpu_ms_per_frame}) {
      std::vector<double> v;
      for (const CaseResult* r : groups[i]) v.push_back(r->*field);
      m.*field = Median(v);
    }
    for (const CaseResult* r : groups[i]) {
      m.frames += r->frames;
      m.errors += r->errors;
      m.dropped = std::max(m.dropped, r->dropped);
    }
  }
  return out;
}

// The medians table: one row per case, each server's figures side by side and, with two, the
// first one's over the second's.
void PrintMedians(const std::vector<CaseResult>& medians, const std::vector<Contender>& servers,
                  int rounds) {
  const bool pair = servers.size() == 2;
  std::cout << "\nmedians over " << rounds << " round" << (rounds == 1 ? "" : "s");
  if (pair) {
    std::cout << " (" << servers[0].label << " and " << servers[1].label
              << " in turn, alternating which goes first; x: " << servers[0].label << " / "
              << servers[1].label << ")";
  }
  std::cout << ":\n";
  auto name = [](const std::string& label) { return label.substr(0, 10); };
  char line[320];
  // Three column groups (frames/s, server CPU per frame, p99 latency), each with one column per
  // server and, for a pair, their ratio.
  const int group = static_cast<int>(servers.size()) * 11 + (pair ? 7 : 0);
  std::snprintf(line, sizeof line, "%-4s %7s %-14s |", "", "", "");
  std::string top = line;
  std::snprintf(line, sizeof line, "%-4s %7s %-14s |", "enc", "streams", "mode");
  std::string header = line;
  for (const char* figure : {"frames/s", "srv CPU ms", "p99 ms"}) {
    std::snprintf(line, sizeof line, " %-*s |", group - 1, figure);
    top += line;
    for (const Contender& c : servers) {
      std::snprintf(line, sizeof line, " %10s", name(c.label).c_str());
      header += line;
    }
    header += pair ? "      x |" : " |";
  }
  top.erase(top.find_last_not_of(" |") + 1);
  header.resize(header.size() - 2);
  std::cout << top << "\n" << header << "\n";
  for (std::size_t i = 0; i < medians.size(); i += servers.size()) {
    const CaseResult& a = medians[i];
    std::snprintf(line, sizeof line, "%-4s %7d %-14s |", a.encoding.c_str(), a.streams,
                  a.mode.c_str());
    std::string row = line;
    for (double CaseResult::*field :
         {&CaseResult::fps, &CaseResult::server_cpu_ms_per_frame, &CaseResult::p99}) {
      for (std::size_t s = 0; s < servers.size(); ++s) {
        std::snprintf(line, sizeof line, field == &CaseResult::fps ? " %10.1f" : " %10.3f",
                      medians[i + s].*field);
        row += line;
      }
      if (pair) {
        const double b = medians[i + 1].*field;
        std::snprintf(line, sizeof line, " %5.2fx", b > 0 ? a.*field / b : 0.0);
        row += line;
      }
      row += " |";
    }
    row.resize(row.size() - 2);
    std::cout << row << "\n";
    // An error reply is answered fast and costs next to nothing: such figures measure the
    // refusal (a server that does not know the uplink encoding, say), not clouds.
    for (std::size_t s = 0; s < servers.size(); ++s) {
      const CaseResult& m = medians[i + s];
      if (m.errors == 0) continue;
      std::cout << "  (" << name(m.server) << ": " << m.errors << " of " << m.frames
                << " replies were frame errors: its figures in this row are not clouds)\n";
    }
  }
}

int Main(int argc, char** argv) {
  CLI::App app{
      "cloudcast-e2e-bench: the gRPC service end to end over loopback. Starts cloudcast-server,\n"
      "streams frames through 1, 2 and 4 concurrent streams (raw, zstd, PNG), and prints\n"
      "frames/s, latency p50/p90/p99 and the server's CPU per frame, inside the core pipeline\n"
      "+ Draco and outside them. --compare-bin measures a second server binary side by side\n"
      "(scripts/bench-against REV builds one from any commit)."};
  std::string data_dir = tsukuba::DefaultDir();
  std::string server_bin =
      (std::filesystem::read_symlink("/proc/self/exe").parent_path() / "cloudcast-server").string();
  std::string label = "this", compare_bin, compare_label = "other";
  CaseOptions case_options;
  double paced_fps = 30;
  int threads = 0, rounds = 1;
  std::vector<int> stream_counts = {1, 2, 4};
  std::vector<std::string> encodings = {"raw", "png"};
  std::string json_path;
  app.add_option("--data", data_dir, "New Tsukuba folder; synthetic frames when absent")
      ->capture_default_str();
  app.add_option("--server-bin", server_bin, "the cloudcast-server binary")->capture_default_str();
  app.add_option("--label", label, "the --server-bin's name in the tables")->capture_default_str();
  app.add_option("--compare-bin", compare_bin,
                 "a second cloudcast-server binary, measured in turn with --server-bin on every "
                 "case of every round");
  app.add_option("--compare-label", compare_label, "the --compare-bin's name in the tables")
      ->capture_default_str();
  app.add_option("--rounds", rounds,
                 "rounds over all cases (medians over them are printed when more than one, or "
                 "with --compare-bin)")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  app.add_option("--seconds", case_options.seconds, "measured seconds per case")
      ->check(CLI::Range(0.5, 600.0))
      ->capture_default_str();
  app.add_option("--streams", stream_counts, "concurrent stream counts")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  app.add_option(
         "--encodings,--encoding", encodings,
         "raw, zstd (the compressed uplink, compressed once up front), png and/or h264 (colour "
         "as H.264 pictures encoded once up front, --h264-* flags; disparity zstd)")
      ->check(CLI::IsMember({"raw", "zstd", "png", "h264"}))
      ->capture_default_str();
  app.add_option("--window", case_options.window,
                 "frames in flight per stream in the throughput runs")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  app.add_flag("--shared-connection", case_options.shared_connection,
               "all streams of a case on one connection (one robot with several cameras); by "
               "default every stream is a robot of its own, with its own connection");
  app.add_option("--paced-fps", paced_fps, "frames/s per stream in the paced runs (0: skip)")
      ->check(CLI::Range(0.0, 1000.0))
      ->capture_default_str();
  app.add_option("--threads", threads, "server worker threads (0: one per core)")
      ->capture_default_str();
  app.add_option("--json", json_path, "also write the results as JSON");
  const cli::VideoFlags h264(app, "H.264 (--encodings h264)");
  CLI11_PARSE(app, argc, argv);
  signal(SIGPIPE, SIG_IGN);

  std::vector<Contender> servers;
  servers.push_back({label, server_bin, nullptr});
  if (!compare_bin.empty()) {
    if (compare_label == label) {
      std::cerr << "--compare-label must differ from --label (both are '" << label << "')\n";
      return 1;
    }
    servers.push_back({compare_label, compare_bin, nullptr});
  }
  for (const auto& [flag, path] :
       {std::pair<const char*, const std::string&>{"--server-bin", server_bin},
        {"--compare-bin", compare_bin}}) {
    if (!path.empty() && !std::filesystem::exists(path)) {
      std::cerr << "no cloudcast-server at " << path << " (" << flag << ")\n";
      return 1;
    }
  }
  const std::vector<Frame> frames = LoadFrames(data_dir);
  std::size_t raw_bytes = 0, png_bytes = 0, zstd_bytes = 0, zstd_disparity_bytes = 0;
  for (const Frame& f : frames) {
    raw_bytes += f.disparity.pixels.size() + f.colour.pixels.size();
    png_bytes += f.disparity_png.size() + f.colour_png.size();
    zstd_bytes += f.disparity_zstd.payload().size() + f.colour_zstd.payload().size();
    zstd_disparity_bytes += f.disparity_zstd.payload().size();
  }
  std::cout << frames.size() << " frames of " << frames[0].disparity.width << "x"
            << frames[0].disparity.height << ": " << raw_bytes / frames.size() / 1024 << " KB raw, "
            << zstd_bytes / frames.size() / 1024 << " KB as zstd, "
            << png_bytes / frames.size() / 1024 << " KB as PNG per frame\n";
  VideoSequence video;
  if (std::find(encodings.begin(), encodings.end(), "h264") != encodings.end()) {
    const video::FrameEncoderOptions vo = h264.Options(paced_fps > 0 ? paced_fps : 30);
    video::FrameEncoder encoder(vo);
    const int interval = vo.encoder.keyframe_interval > 0 ? vo.encoder.keyframe_interval : 60;
    const std::size_t length =
        std::max(frames.size(), (frames.size() + interval - 1) / interval * interval);
    std::vector<double> ms;
    double bytes = 0;
    for (std::size_t i = 0; i < length; ++i) {
      const Frame& f = frames[i % frames.size()];
      const double before = ThreadCpuMs();
      auto coded = encoder.Encode(cc::DisparityFrame{f.disparity.view(), f.colour.view()}, i);
      ms.push_back(ThreadCpuMs() - before);
      if (!coded.ok()) {
        std::cerr << "--encodings h264: " << coded.status() << "\n";
        return 1;
      }
      const auto& colour = std::get<cc::DisparityFrame>(*coded).colour;
      video.pictures.push_back(*std::get<cc::PrecodedVideo>(colour).message);
      video.frame_of.push_back(i % frames.size());
      bytes += static_cast<double>(video.pictures.back().access_unit().size());
    }
    video.encode_ms = Median(ms);
    std::printf(
        "h264: a sequence of %zu pictures (preset %s, crf %g <= %g Mbit/s, IDR every %d), %.1f KB "
        "a picture + %.1f KB of zstd disparity a frame; encoded up front in %.2f ms a picture "
        "(median thread CPU)\n",
        length, vo.encoder.preset.c_str(), vo.encoder.crf, vo.encoder.bitrate_bps / 1e6, interval,
        bytes / static_cast<double>(length) / 1024,
        static_cast<double>(zstd_disparity_bytes) / static_cast<double>(frames.size()) / 1024,
        video.encode_ms);
    std::fflush(stdout);
  }
  for (Contender& c : servers) {
    if (!Start(c, threads)) return 1;
  }
  std::cout << std::thread::hardware_concurrency()
            << " cores, shared by the server(s) and this client; "
            << (case_options.shared_connection ? "all streams on one connection"
                                               : "a connection per stream")
            << "\n\n";

  const bool labelled = servers.size() > 1 || rounds > 1;
  std::vector<CaseResult> results;
  char line[256];
  std::snprintf(
      line, sizeof line, "%s%-4s %-7s %-14s %8s %7s %7s %7s %8s %11s %10s %8s %11s %14s\n",
      labelled ? "round server     " : "", "enc", "streams", "mode", "frames/s", "p50 ms", "p90 ms",
      "p99 ms", "dropped", "srv CPU ms", "core+Draco", "outside", "cli CPU ms", "robots/core@30");
  std::cout << line;
  for (int round = 1; round <= rounds; ++round) {
    for (const std::string& enc : encodings) {
      for (int n : stream_counts) {
        Uplink uplink = Uplink::kRaw;
        sources::ParseUplink(enc, &uplink);
        std::vector<double> modes = {0.0};  // throughput
        if (paced_fps > 0) modes.push_back(paced_fps);
        for (const double fps : modes) {
          // Even rounds run the servers in the other order: whoever runs second finds the
          // machine warmed (or heated) by the first.
          for (std::size_t k = 0; k < servers.size(); ++k) {
            const std::size_t s = round % 2 == 0 ? servers.size() - 1 - k : k;
            CaseResult r = RunCase(*servers[s].server, frames, uplink,
                                   enc == "h264" ? &video : nullptr, n, fps, case_options);
            r.server = servers[s].label;
            r.round = round;
            std::snprintf(line, sizeof line, "%5d %-10s ", round, r.server.substr(0, 10).c_str());
            std::cout << (labelled ? line : "");
            std::snprintf(
                line, sizeof line,
                "%-4s %7d %-14s %8.1f %7.2f %7.2f %7.2f %8lu %11.3f %10.3f %7.0f%% %11.3f %14.1f\n",
                r.encoding.c_str(), r.streams, r.mode.c_str(), r.fps, r.p50, r.p90, r.p99,
                static_cast<unsigned long>(r.dropped), r.server_cpu_ms_per_frame,
                r.core_cpu_ms_per_frame, 100 * r.outside_share, r.client_cpu_ms_per_frame,
                r.RobotsPerCore());
            std::cout << line << std::flush;
            if (r.errors > 0) std::cout << "  (" << r.errors << " frame errors)\n";
            if (r.keyframe_requests > 0) {
              std::cout << "  (" << r.keyframe_requests << " replies asked for an IDR)\n";
            }
            results.push_back(r);
          }
        }
      }
    }
  }
  std::cout
      << "\nlatency: send to reply in the throughput runs (a closed loop), intended send time "
         "to reply in the paced ones; srv CPU ms: server process CPU (user + system) per "
         "answered frame; core+Draco: the part inside Pipeline::Run and EncodeDraco (thread "
         "CPU time); outside: the rest (gRPC, protobuf, PNG / zstd decoding, scheduling); "
         "cli CPU ms: this process (the senders and gRPC's client side; the client does "
         "not decode the replies) per answered frame; robots/core@30: robots at 30 frames/s "
         "one server core carries at that server CPU per frame (1000 / (30 x srv CPU ms)).\n";
  // Medians per case and server, in the first round's order: the servers in turn, in their
  // order, within each case (what PrintMedians expects).
  const std::vector<CaseResult> medians = MediansOf(results);
  if (labelled) PrintMedians(medians, servers, rounds);
  if (!json_path.empty()) {
    nlohmann::json j;
    j["rounds"] = rounds;
    j["shared_connection"] = case_options.shared_connection;
    j["servers"] = nlohmann::json::array();
    for (const Contender& c : servers) {
      j["servers"].push_back({{"label", c.label}, {"binary", c.binary}});
    }
    j["cases"] = nlohmann::json::array();
    for (const CaseResult& r : results) j["cases"].push_back(r.ToJson());
    j["medians"] = nlohmann::json::array();
    for (const CaseResult& m : medians) j["medians"].push_back(m.ToJson());
    std::ofstream(json_path) << j.dump(2) << "\n";
    std::cout << "wrote " << json_path << "\n";
  }
  return 0;
}

}  // namespace
}  // namespace cloudcast::bench

int main(int argc, char** argv) { return cloudcast::bench::Main(argc, argv); }
