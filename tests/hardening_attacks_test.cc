// The attacks of issue 18, each against a real cloudcast-server process on loopback (directly,
// or through HAProxy with the shipped configuration), driven by cloudcast-attack (tests/attacks/)
// from other loopback addresses, beside a legitimate paced stream: 30 fps, DELIVERY_ALL, 640x480,
// its latency counted from each frame's intended send time (cloudcast-load's Fleet, free of
// coordinated omission). Each test prints its figures as a table row and checks issue 18's bar:
//   - the paced stream loses nothing and its p99 stays at most 50 ms;
//   - the server's resident memory stays under 512 MB during the attack, and is back within 64 MB
//     of its baseline 10 s after it.
// The latency bound is the acceptance criterion, measured the way the issue states it
// (the house rule against timing assertions gives way here to the criterion it was filed with).
//
// Each attack lasts CLOUDCAST_ATTACK_SECONDS (the environment's; 10 by default, what ctest runs in
// the long tier): 10 s still fails every defect's server from before its fix (the before figures
// of docs/http2-hardening.md go wrong within the first seconds: stalls of seconds, gigabytes of
// RSS, clients locked out or frozen). 20 gives the figures of that document (the RSS read exactly
// 10 s after the attack); shorter runs poll the RSS until it is back, for at most 10 s. Below 8 s
// (a quick look while working on the server) the tests that need a longer attack skip.
#include <fcntl.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/load/fleet.h"
#include "cloudcast/load/frame_store.h"
#include "cloudcast/load/probe.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/testing/metrics_scrape.h"
#include "cloudcast/v1/cloudcast.grpc.pb.h"
#include "raw_h2.h"
#include "support/proc_status.h"
#include "support/replica_support.h"

#ifndef CLOUDCAST_SOURCE_DIR
#error \
    "CLOUDCAST_SOURCE_DIR must name the checkout (the shipped HAProxy configuration is read there)"
#endif

namespace cloudcast {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;
using std::chrono::seconds;

// CLOUDCAST_ATTACK_SECONDS, 1 to 20 (issue 18's attacks last at most 20 s); 10 without it.
double AttackSecondsFromEnvironment() {
  const char* text = std::getenv("CLOUDCAST_ATTACK_SECONDS");
  if (text == nullptr || *text == '\0') return 10;
  char* end = nullptr;
  const double s = std::strtod(text, &end);
  if (*end != '\0' || !(s >= 1 && s <= 20)) {
    std::fprintf(stderr, "CLOUDCAST_ATTACK_SECONDS is '%s'; must be a number of seconds, 1 to 20\n",
                 text);
    std::exit(2);
  }
  return s;
}
const double kAttackSeconds = AttackSecondsFromEnvironment();
// The figures' runs (docs/http2-hardening.md): the RSS read exactly 10 s after the attack.
const bool kLong = kAttackSeconds >= 15;
// Long enough for every test; shorter runs skip the tests that need more (and say so).
const bool kFull = kAttackSeconds >= 8;
constexpr const char* kNeedsFull = "needs an attack of 8 s or more (CLOUDCAST_ATTACK_SECONDS)";
constexpr double kMb = 1024.0 * 1024.0;
// Issue 18's bar.
constexpr double kMaxP99Ms = 50;
constexpr double kMaxRssMb = 512;
constexpr double kMaxRetainedMb = 64;

void Sleep(Clock::duration d) { std::this_thread::sleep_for(d); }

// A raw frame of the synthetic scene (disparity + colour), as a camera stream sends one; its
// camera in `camera` when asked.
v1::Frame SyntheticRawFrame(std::uint32_t width, std::uint32_t height,
                            CameraModel* camera = nullptr) {
  SyntheticOptions o;
  o.width = width;
  o.height = height;
  const SyntheticFrame f = *SyntheticScene::Default().Render(o);
  if (camera != nullptr) *camera = f.camera;
  v1::Frame frame;
  EXPECT_TRUE(
      convert::ToProto(f.disparity_view(), "d", frame.mutable_disparity()->mutable_raw()).ok());
  EXPECT_TRUE(convert::ToProto(f.colour_view(), "c", frame.mutable_color()->mutable_raw()).ok());
  return frame;
}

using testing::ResidentBytes;

std::uint64_t FileBytes(const std::string& path) {
  struct stat st {};
  return stat(path.c_str(), &st) == 0 ? static_cast<std::uint64_t>(st.st_size) : 0;
}

// A child process: argv[0] is the program's path; `env` entries ("NAME=value") are added to ours;
// `niceness` lowers its priority.
class Child {
 public:
  Child(const std::vector<std::string>& argv, const std::string& out_path,
        const std::vector<std::string>& env = {}, int niceness = 0) {
    pid_ = fork();
    if (pid_ == 0) {
      if (niceness != 0 && nice(niceness) == -1) _exit(126);
      const int out = open(out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      dup2(out, 1);
      dup2(out, 2);
      for (const std::string& e : env) putenv(const_cast<char*>(e.c_str()));
      std::vector<char*> args;
      for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
      args.push_back(nullptr);
      execv(args[0], args.data());
      _exit(127);
    }
  }
  ~Child() { Stop(); }
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;

  // Waits for the child to end by itself, at most `timeout`; then kills it. Its exit status.
  int Wait(Clock::duration timeout) {
    const auto deadline = Clock::now() + timeout;
    while (pid_ > 0) {
      int status = 0;
      const pid_t r = waitpid(pid_, &status, WNOHANG);
      if (r == pid_) {
        pid_ = -1;
        code_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
        break;
      }
      if (Clock::now() > deadline) {
        kill(pid_, SIGKILL);
        waitpid(pid_, &status, 0);
        pid_ = -1;
        code_ = 137;
        break;
      }
      Sleep(milliseconds(20));
    }
    return code_;
  }
  void Stop() {
    if (pid_ > 0) {
      kill(pid_, SIGTERM);
      Wait(seconds(5));
    }
  }
  pid_t pid() const { return pid_; }

 private:
  pid_t pid_ = -1;
  int code_ = -1;
};

// The peak resident memory of processes, sampled every 50 ms on a thread of its own.
class PeakSampler {
 public:
  explicit PeakSampler(std::vector<pid_t> pids) : pids_(std::move(pids)), peaks_(pids_.size()) {
    thread_ = std::thread([this] {
      while (!stop_.load()) {
        for (std::size_t i = 0; i < pids_.size(); ++i) {
          peaks_[i] = std::max<std::uint64_t>(peaks_[i], ResidentBytes(pids_[i]));
        }
        Sleep(milliseconds(50));
      }
    });
  }
  ~PeakSampler() { Stop(); }
  void Stop() {
    stop_.store(true);
    if (thread_.joinable()) thread_.join();
  }
  std::uint64_t peak(std::size_t i) const { return peaks_[i]; }

 private:
  const std::vector<pid_t> pids_;
  std::vector<std::uint64_t> peaks_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

// What one attack did to the paced stream and to the server.
struct Figures {
  std::string attack, path;
  double p50_ms = 0, p99_ms = 0, max_ms = 0;
  double quiet_p99_ms = 0;  // the paced stream's p99 just before, with no attack
  std::uint64_t sent = 0, answered = 0, errors = 0;
  double rss_base_mb = 0, rss_peak_mb = 0, rss_after_mb = 0, after_s = 0;
  double proxy_peak_mb = 0;
  double log_mb = 0;
  std::vector<nlohmann::json> attackers;

  std::uint64_t lost() const { return sent - std::min(sent, answered); }
  void Print() const {
    // | attack | path | quiet p99 | p50 | p99 | max | answered / sent | lost | RSS base | peak |
    // after (when) | log MB |
    std::printf(
        "| %s | %s | %.1f | %.1f | %.1f | %.1f | %lu / %lu | %lu | %.0f | %.0f | %.0f (%.1f s) | "
        "%.2f |%s\n",
        attack.c_str(), path.c_str(), quiet_p99_ms, p50_ms, p99_ms, max_ms,
        static_cast<unsigned long>(answered), static_cast<unsigned long>(sent),
        static_cast<unsigned long>(lost() + errors), rss_base_mb, rss_peak_mb, rss_after_mb,
        after_s, log_mb,
        proxy_peak_mb > 0 ? (" proxy peak " + std::to_string(proxy_peak_mb) + " MB").c_str() : "");
    for (const nlohmann::json& a : attackers) std::printf("  attacker: %s\n", a.dump().c_str());
    std::fflush(stdout);
  }
};

// One attacker: cloudcast-attack's arguments (its --seconds and --target are added), and its
// niceness. A flood's volume is the attack: it runs at full priority (on these 2 shared cores it
// then also takes CPU from the server, a worst case). A gRPC attacker's volume is bounded by the
// server (flow control, admission, the refusal delay), and its own work (encoding, serializing,
// sending frames) would be on its own machine: it runs at nice 10, taking only what the server
// and the proxy leave.
struct Attacker {
  std::vector<std::string> args;
  int niceness = 10;
};
constexpr int kFullSpeed = 0;

class AttackTest : public ::testing::Test {
 protected:
  void TearDown() override {
    proxy_.reset();
    server_.reset();
    // Kept when the test failed (its messages quote the server's log), gone when it passed.
    std::error_code ignored;
    if (!HasFailure()) std::filesystem::remove_all(ScratchDir(), ignored);
  }

  // Where this test's files go: the server's log, HAProxy's configuration, the attackers'
  // figures. Each test is a process of its own under ctest, so the pid names it.
  static std::string ScratchDir() {
    return ::testing::TempDir() + "/cloudcast_attack_" + std::to_string(getpid());
  }
  static std::string Scratch(const std::string& name) {
    std::filesystem::create_directories(ScratchDir());
    return ScratchDir() + "/" + name;
  }

  // Measuring, not testing: CLOUDCAST_ATTACK_SERVER_BINARY runs another build of the server
  // (the one before a fix, for the before figures; the flags of issue 18's fixes are then left
  // out), and CLOUDCAST_ATTACK_SERVER_ARGS adds flags (space-separated), e.g. one transport limit.
  static const char* OtherServer() {
    const char* binary = std::getenv("CLOUDCAST_ATTACK_SERVER_BINARY");
    return binary != nullptr && *binary != '\0' ? binary : nullptr;
  }

  // A cloudcast-server process on 127.0.0.1 with `args` (2 workers unless they say otherwise).
  void StartServer(std::vector<std::string> args) {
    if (std::find(args.begin(), args.end(), "--threads") == args.end()) {
      args.insert(args.end(), {"--threads", "2"});
    }
    std::vector<std::string> prefix;
    if (OtherServer() != nullptr) {
      // Execs the other binary in place of ours (the pid stays the server's).
      prefix = {"/bin/sh", "-c", "shift; exec \"$0\" \"$@\"", OtherServer()};
    }
    if (const char* extra = std::getenv("CLOUDCAST_ATTACK_SERVER_ARGS")) {
      std::istringstream words(extra);
      for (std::string w; words >> w;) args.push_back(w);
    }
    log_ = Scratch("server.log");
    // Port 0, which the server reports; another build (from before --ready-file) gets free
    // ports picked here.
    const auto any_port = [&] {
      return "127.0.0.1:" +
             std::to_string(OtherServer() != nullptr ? testing::FreeLoopbackPort() : 0);
    };
    server_ = std::make_unique<testing::ServerProcess>(any_port(), "attacked", args, log_, "info",
                                                       any_port(), prefix);
    ASSERT_TRUE(server_->WaitUntilServing()) << "the server did not start: " << server_->log();
    metrics_port_ = server_->metrics_port();
  }

  // HAProxy in front of the server, with the shipped configuration (docker/haproxy/) and a
  // backend of the one server, as the Pod's sidecar has it. `unprotected`: the configuration the
  // load test used before issue 18 (no limits in front of the server), for the before figures.
  void StartProxy(bool unprotected = false) {
    const std::string dir = Scratch("proxy");
    std::filesystem::create_directories(dir);
    // HAProxy cannot report a port of the kernel's choosing, so one is picked here, free now; if
    // another test binds it before HAProxy does, HAProxy exits at once ("cannot bind socket")
    // and another port is tried.
    for (int attempt = 0; attempt < 4; ++attempt) {
      proxy_address_ = "127.0.0.1:" + std::to_string(testing::FreeLoopbackPort());
      std::vector<std::string> argv = {"/usr/sbin/haproxy", "-db"};
      std::vector<std::string> env = {"CLOUDCAST_PROXY_LISTEN=" + proxy_address_,
                                      "CLOUDCAST_BACKEND=" + server_->address()};
      if (unprotected) {
        std::ofstream(dir + "/unprotected.cfg")
            << UnprotectedConfig(proxy_address_, server_->address());
        argv.insert(argv.end(), {"-f", dir + "/unprotected.cfg"});
      } else {
        argv.insert(
            argv.end(),
            {"-f", std::string(CLOUDCAST_SOURCE_DIR) + "/docker/haproxy/cloudcast.cfg", "-f",
             std::string(CLOUDCAST_SOURCE_DIR) + "/docker/haproxy/backend-local.cfg"});
      }
      proxy_ = std::make_unique<Child>(argv, dir + "/haproxy.log", env);
      auto channel = grpc::CreateChannel(proxy_address_, grpc::InsecureChannelCredentials());
      if (channel->WaitForConnected(std::chrono::system_clock::now() + seconds(10))) return;
      const std::string log = testing::ReadText(dir + "/haproxy.log");
      if (log.find("cannot bind socket") == std::string::npos) {
        FAIL() << "HAProxy did not serve " << proxy_address_ << ":\n" << log;
      }
    }
    FAIL() << "HAProxy found no free port in 4 tries:\n" << testing::ReadText(dir + "/haproxy.log");
  }

  static std::string UnprotectedConfig(const std::string& listen, const std::string& backend) {
    return "global\n  maxconn 4000\n  tune.h2.initial-window-size 4194304\n"
           "  tune.h2.max-concurrent-streams 1000\n  tune.bufsize 65536\n"
           "defaults\n  mode http\n  timeout connect 5s\n  timeout client 1h\n"
           "  timeout server 1h\n  timeout tunnel 1h\n  timeout http-request 1h\n"
           "frontend grpc\n  bind " +
           listen +
           " proto h2\n  default_backend replicas\n"
           "backend replicas\n  http-reuse always\n  server s1 " +
           backend + " proto h2\n";
  }

  // The paced stream's target: the proxy when there is one.
  std::string Target() const { return proxy_ ? proxy_address_ : server_->address(); }

  // A paced stream: 30 fps DELIVERY_ALL 640x480 for `duration`, latency from the intended times.
  static const load::FrameStore& PacedFrames() {
    static const load::FrameStore store = [] {
      CameraModel camera;
      v1::Frame frame = SyntheticRawFrame(640, 480, &camera);
      return load::FrameStore::FromFrames({frame}, camera, "synthetic 640x480 raw");
    }();
    return store;
  }
  struct Paced {
    load::Totals totals;
    load::Histogram latency;
    std::map<std::string, std::uint64_t> errors;
  };
  Paced RunPaced(double duration_s) {
    load::FleetOptions o;
    o.server = Target();
    o.streams = 1;
    o.schedule.start = 30;
    o.duration = std::chrono::milliseconds(static_cast<std::int64_t>(duration_s * 1000));
    o.drain_timeout = seconds(10);
    o.connect_timeout = seconds(10);
    o.config.set_delivery(v1::DELIVERY_ALL);
    Paced p;
    auto fleet = load::Fleet::Connect(o, &PacedFrames());
    EXPECT_TRUE(fleet.ok()) << fleet.status();
    if (!fleet.ok()) return p;
    (*fleet)->Run();
    p.totals = (*fleet)->recorder().totals();
    p.latency = (*fleet)->recorder().latency();
    p.errors = (*fleet)->recorder().errors();
    return p;
  }

  // Runs the attackers for kAttackSeconds beside the paced stream (which starts `lead` later, so
  // that a standing attack is in place first) and measures. The server's RSS baseline is taken
  // after a warm-up of the paced stream (its scratch is kept by design).
  Figures Run(const std::string& name, const std::vector<Attacker>& attackers,
              Clock::duration lead = milliseconds(300), double seconds_override = 0) {
    Figures f;
    f.attack = name;
    f.path = proxy_ ? "through HAProxy" : "direct";
    // The warm-up is also the noise floor: the paced stream with no attack, on this shared machine.
    f.quiet_p99_ms = RunPaced(4.0).latency.Percentile(99) / 1e6;
    Sleep(milliseconds(1500));  // the idle housekeeping trims what the warm-up freed
    f.rss_base_mb = ResidentBytes(server_->pid()) / kMb;
    const std::uint64_t log_before = FileBytes(log_);
    std::vector<pid_t> pids = {server_->pid()};
    if (proxy_) pids.push_back(proxy_->pid());
    PeakSampler sampler(pids);
    const double seconds = seconds_override > 0 ? seconds_override : kAttackSeconds;
    std::vector<std::unique_ptr<Child>> children;
    std::vector<std::string> outputs;
    for (std::size_t i = 0; i < attackers.size(); ++i) {
      std::vector<std::string> argv = {testing::BinDir() + "/cloudcast-attack"};
      argv.insert(argv.end(), attackers[i].args.begin(), attackers[i].args.end());
      argv.insert(argv.end(), {"--target", Target(), "--seconds", std::to_string(seconds)});
      outputs.push_back(Scratch("attacker_" + std::to_string(i) + ".json"));
      children.push_back(std::make_unique<Child>(argv, outputs.back(), std::vector<std::string>{},
                                                 attackers[i].niceness));
    }
    // Each attacker says when its requests are made (encoding a 4096x4096 frame takes a second
    // or two of CPU, which is not the attack): the attack, and the measurement, start then.
    for (const std::string& out : outputs) {
      const auto give_up = Clock::now() + std::chrono::seconds(60);
      while (testing::ReadText(out).find(": ready") == std::string::npos &&
             Clock::now() < give_up) {
        Sleep(milliseconds(20));
      }
    }
    const auto attack_start = Clock::now();
    Sleep(lead);
    const double lead_s = std::chrono::duration<double>(lead).count();
    const Paced paced = RunPaced(std::max(1.0, seconds - lead_s));
    for (std::size_t i = 0; i < children.size(); ++i) {
      children[i]->Wait(std::chrono::seconds(static_cast<int>(seconds) + 30));
      const std::string text = testing::ReadText(outputs[i]);
      const std::size_t brace = text.rfind("\n{");
      try {
        f.attackers.push_back(
            nlohmann::json::parse(brace == std::string::npos ? text : text.substr(brace + 1)));
      } catch (...) {
        f.attackers.push_back({{"output", text.substr(0, 400)}});
      }
    }
    const auto attack_end = std::max(Clock::now(), attack_start);
    sampler.Stop();
    f.rss_peak_mb = sampler.peak(0) / kMb;
    if (proxy_) f.proxy_peak_mb = sampler.peak(1) / kMb;
    f.log_mb = (FileBytes(log_) - std::min(FileBytes(log_), log_before)) / kMb;
    // 10 s after the attack: read then (the figures' runs), or polled until it is back.
    const auto after_deadline = attack_end + std::chrono::seconds(10);
    for (;;) {
      f.rss_after_mb = ResidentBytes(server_->pid()) / kMb;
      const bool back = f.rss_after_mb <= f.rss_base_mb + kMaxRetainedMb;
      if (Clock::now() >= after_deadline || (!kLong && back)) break;
      Sleep(milliseconds(250));
    }
    f.after_s = std::chrono::duration<double>(Clock::now() - attack_end).count();
    f.sent = paced.totals.sent;
    f.answered = paced.totals.answered;
    f.errors = paced.totals.frame_errors + paced.totals.lost + paced.totals.unsent;
    f.p50_ms = paced.latency.Percentile(50) / 1e6;
    f.p99_ms = paced.latency.Percentile(99) / 1e6;
    f.max_ms = paced.latency.max() / 1e6;
    for (const auto& [error, n] : paced.errors) {
      std::printf("  paced stream error (%lu frames): %s\n", static_cast<unsigned long>(n),
                  error.c_str());
    }
    f.Print();
    return f;
  }

  // Issue 18's bar for every attack.
  static void ExpectUnharmed(const Figures& f) {
    EXPECT_GT(f.sent, 0u);
    EXPECT_EQ(f.answered, f.sent) << f.attack << ": the paced stream lost frames";
    EXPECT_EQ(f.errors, 0u) << f.attack;
    // Latency is judged only when the machine lets it be: with other engineers' compiles on
    // these 2 cores the paced stream alone can have a p99 past half the bar.
    if (f.quiet_p99_ms <= kMaxP99Ms / 2) {
      EXPECT_LE(f.p99_ms, kMaxP99Ms) << f.attack << ": paced p99 from the intended send time";
    } else {
      std::printf(
          "  latency not judged: the paced stream alone had a p99 of %.1f ms (machine busy)\n",
          f.quiet_p99_ms);
    }
    EXPECT_LT(f.rss_peak_mb, kMaxRssMb) << f.attack << ": server RSS during the attack";
    EXPECT_LE(f.rss_after_mb, f.rss_base_mb + kMaxRetainedMb)
        << f.attack << ": server RSS " << f.after_s << " s after the attack";
  }

  double Metric(const std::string& name) {
    return server::MetricValue(server::ScrapeMetrics(metrics_port_), name);
  }

  std::unique_ptr<testing::ServerProcess> server_;
  std::unique_ptr<Child> proxy_;
  std::string proxy_address_;
  std::string log_;
  int metrics_port_ = 0;
};

// What stands in front of the server for the HTTP/2 floods: "proxy" (the shipped HAProxy
// configuration, the default), "none" (the server alone) or "unprotected-proxy" (the load test's
// HAProxy configuration before issue 18). The last two give the before figures, and fail.
std::string Front() {
  const char* front = std::getenv("CLOUDCAST_ATTACK_FRONT");
  return front != nullptr && *front != '\0' ? front : "proxy";
}

class FloodTest : public AttackTest {
 protected:
  void SetUp() override {
    // The proxy names each client in x-forwarded-for (a server from before has no such flag).
    StartServer(OtherServer() != nullptr
                    ? std::vector<std::string>{}
                    : std::vector<std::string>{"--trusted-proxy", "127.0.0.1"});
    if (Front() == "proxy") {
      StartProxy();
    } else if (Front() == "unprotected-proxy") {
      StartProxy(/*unprotected=*/true);
    } else {
      ASSERT_EQ(Front(), "none")
          << "CLOUDCAST_ATTACK_FRONT must be proxy, none or unprotected-proxy";
    }
  }
};

// Issue 18, defect 1: rapid reset (CVE-2023-44487) from one address, on the Stream method (whose
// calls reach the service) and on GetInfo (whose calls gRPC cancels before the service sees them).
// Before: the paced stream stalled for 29-42 s and the server grew to 2.3-2.6 GB.
TEST_F(FloodTest, RapidResetLeavesThePacedStreamAndTheServerAlone) {
  for (const char* method : {"Stream", "GetInfo"}) {
    const Figures f = Run(std::string("rapid reset, ") + method,
                          {{{"rapid-reset", "--source", "127.0.0.2", "--path",
                             std::string("/cloudcast.v1.CloudCast/") + method},
                            kFullSpeed}});
    ExpectUnharmed(f);
    if (!kFull) break;  // a quick look: the Stream method only
  }
}

// Issue 18, defect 2: a CONTINUATION flood (HEADERS without END_HEADERS, then 4 KB headers with
// incremental indexing, never END_HEADERS). Before: 5 GB in 20 s, freed only with the connection.
TEST_F(FloodTest, ContinuationFloodLeavesThePacedStreamAndTheServerAlone) {
  ExpectUnharmed(Run("CONTINUATION flood", {{{"continuation-flood", "--source", "127.0.0.2",
                                              "--path", "/cloudcast.v1.CloudCast/Stream"},
                                             kFullSpeed}}));
}

// A memory cgroup of its own (cgroup v1 or v2) holding processes moved into it, at most
// `limit_bytes` (the kernel's OOM killer ends a process of it that needs more): a flood that grows
// a server by gigabytes kills the server, not the machine. Needs root and a writable cgroup
// hierarchy: ok() says whether it is in place. Its processes go back to the parent group before
// it is removed.
class MemoryCgroup {
 public:
  explicit MemoryCgroup(std::uint64_t limit_bytes) {
    const std::string name = "cloudcast-attack-" + std::to_string(getpid());
    std::string limit_file;
    if (std::filesystem::exists("/sys/fs/cgroup/cgroup.controllers")) {  // v2
      parent_ = "/sys/fs/cgroup";
      limit_file = "memory.max";
    } else if (std::filesystem::exists("/sys/fs/cgroup/memory/cgroup.procs")) {  // v1
      parent_ = "/sys/fs/cgroup/memory";
      limit_file = "memory.limit_in_bytes";
    } else {
      return;
    }
    dir_ = parent_ + "/" + name;
    std::error_code ec;
    std::filesystem::create_directory(dir_, ec);
    if (ec) {
      dir_.clear();
      return;
    }
    ok_ = Write(dir_ + "/" + limit_file, std::to_string(limit_bytes));
  }
  ~MemoryCgroup() {
    if (dir_.empty()) return;
    std::istringstream pids(testing::ReadText(dir_ + "/cgroup.procs"));
    for (std::string pid; pids >> pid;) Write(parent_ + "/cgroup.procs", pid);
    std::error_code ec;
    std::filesystem::remove(dir_, ec);
  }
  MemoryCgroup(const MemoryCgroup&) = delete;
  MemoryCgroup& operator=(const MemoryCgroup&) = delete;

  bool ok() const { return ok_; }
  const std::string& dir() const { return dir_; }
  bool Add(pid_t pid) const { return ok_ && Write(dir_ + "/cgroup.procs", std::to_string(pid)); }

 private:
  static bool Write(const std::string& path, const std::string& value) {
    std::ofstream out(path);
    out << value;
    out.flush();
    return static_cast<bool>(out);
  }
  std::string parent_, dir_;
  bool ok_ = false;
};

// Whether a child process still runs (not ended, not a zombie waiting to be reaped).
bool Alive(pid_t pid) {
  std::istringstream stat(testing::ReadText("/proc/" + std::to_string(pid) + "/stat"));
  std::string id, name, state;
  stat >> id >> name >> state;  // the name is in parentheses, without spaces here
  return !state.empty() && state != "Z" && state != "X";
}

// Issue 30, defect 5: the CONTINUATION flood at its heaviest here, 4 connections at once each
// writing 16 MB batches (4,000 frames of a 4 KB header), with the server held to the Kubernetes
// Pod's memory limit (1 GiB, docker/k8s/deployment.yaml) in a cgroup of its own. gRPC 1.51 keeps
// every header of a block that never ends, and no flag of the server bounds it
// (docs/http2-hardening.md): against the server alone (CLOUDCAST_ATTACK_FRONT=none) it grew by
// gigabytes and the cgroup's OOM killer ended it (the outside tester, without a limit: gRPC's
// tcp_posix.cc:894 assertion at 2.4 to 4.5 GB), so this test fails there, as it must. Through
// the shipped proxy the header block must fit one 64 KB buffer: the server must live through the
// flood, and stay under issue 18's bar.
TEST_F(FloodTest, AHeavyContinuationFloodLeavesTheServerAliveWithinThePodsMemory) {
  MemoryCgroup cgroup(std::uint64_t{1} << 30);
  if (!cgroup.ok()) GTEST_SKIP() << "no writable memory cgroup here (needs root)";
  ASSERT_TRUE(cgroup.Add(server_->pid())) << cgroup.dir();
  const Figures f =
      Run("CONTINUATION flood, 4 connections of 16 MB batches, server in 1 GiB",
          {{{"continuation-flood", "--source", "127.0.0.2", "--path",
             "/cloudcast.v1.CloudCast/Stream", "--connections", "4", "--frames-per-write", "4000"},
            kFullSpeed}});
  EXPECT_TRUE(Alive(server_->pid()))
      << "the server died under the flood: " << testing::ReadText(log_).substr(0, 2000);
  ExpectUnharmed(f);
  // The server ends before its cgroup goes.
  proxy_.reset();
  server_.reset();
}

// Issue 18, defect 3: big frames from many connections of one address must be shared fairly per
// client (the address), not per connection, and weighed before they are decoded. Before: 32
// Process calls of 4096x4096 PNG frames let the paced stream send 5 of 300 frames.
TEST_F(AttackTest, BigFramesFromManyConnectionsOfOneAddressAreOneClient) {
  StartServer({});
  const Figures f = Run("32 Process calls of 4096x4096 PNG, one address",
                        {{{"big-frames", "--source", "127.0.0.2", "--calls", "32", "--side", "4096",
                           "--encoding", "png"}}});
  ExpectUnharmed(f);
  // Such frames can never be processed (2.3 GB of work memory); each refusal waits out
  // --refusal-delay (1 s) holding one of the client's 32 Process places, so the attacker gets
  // about 32 a second, not the 5,400 a second it got without the delay.
  const double refused = f.attackers.at(0).value("/status_codes/8"_json_pointer, 0.0);
  EXPECT_GT(refused, 0);
  EXPECT_LT(refused, 64 * kAttackSeconds) << f.attackers.at(0).dump();
}

// Defect 3, greedy streams: eight connections of one address streaming 640x640 frames as fast as
// flow control lets them. Before: the paced stream's p50 rose from 4.6 to 12.8 ms.
TEST_F(AttackTest, GreedyConnectionsOfOneAddressAreOneClient) {
  StartServer({});
  ExpectUnharmed(Run("8 greedy streams, one address", {{{"greedy-streams", "--source", "127.0.0.2",
                                                         "--calls", "8", "--side", "640"}}}));
}

// Issue 30, defect 4: 96 Process calls on 4 connections of one address, each sending a 59 MB
// message but its last byte. gRPC holds a message until it is whole, and opened each call's window
// to the length announced. Before: RSS 3,759 MB on a bare server for the whole attack, freed only
// when the client left. Now a Process call reads only once its client's read budget (two
// messages) has room, so the others hold the transport's window alone.
TEST_F(AttackTest, IncompleteProcessMessagesHoldOnlyTheirClientsReadBudget) {
  StartServer({});
  const auto attack = [&] {
    return Run("96 Process calls of 59 MB, each a byte short, one address",
               {{{"incomplete-process", "--source", "127.0.0.2", "--calls", "96", "--connections",
                  "4", "--message-mb", "59"},
                 kFullSpeed}});
  };
  Figures f = attack();
  if (f.attackers.at(0).value("calls", 0) < 96) {
    // Seen twice in a dozen runs on a loaded machine: the attacker's raw connections could not
    // open their streams (its writes found the socket closed). That is the attacker failing, not
    // the server: once more, and the attack must then have run in full.
    std::printf("  the attacker opened %d of its 96 calls: once more\n",
                f.attackers.at(0).value("calls", 0));
    f = attack();
  }
  ASSERT_EQ(f.attackers.at(0).value("calls", 0), 96) << f.attackers.at(0);
  ExpectUnharmed(f);
  // 32 calls are admitted (--max-process-per-client), 2 of them read (their client's read
  // budget: two messages) and get their messages to the last byte; the other 30 wait. Without
  // the budget all 32 did, and the server held 1.9 GB.
  EXPECT_LE(f.attackers.at(0).value("calls_sent_but_the_last_byte", 0), 2) << f.attackers.at(0);
}

// Issue 18, defect 4: memory amplification. One Process call per worker of a few KB (zstd) that
// decodes to 4096x4096 (U8 disparity, RGB8 colour). Before: RSS 63 MB -> 1,061 MB, still 996 MB
// 35 s later; --memory-budget-mb never refused them.
TEST_F(AttackTest, FramesThatDecodeHugeAreChargedBeforeDecoding) {
  StartServer({});
  ExpectUnharmed(Run("2 Process calls of 4096x4096 zstd (a few KB each)",
                     {{{"big-frames", "--source", "127.0.0.2", "--calls", "2", "--side", "4096",
                        "--encoding", "zstd"}}}));
}

// Defect 4, retention: frames big enough to need scratch far beyond a camera frame's, which the
// server does process (1440x1440: 2 MP, about 270 MB of work memory at worst, within the default
// 320 MB), leave it with what it had: the workers' scratch shrinks back.
TEST_F(AttackTest, ScratchOfBigFramesShrinksBack) {
  StartServer({});
  ExpectUnharmed(
      Run("2 Process calls of 1440x1440 zstd", {{{"big-frames", "--source", "127.0.0.2", "--calls",
                                                  "2", "--side", "1440", "--encoding", "zstd"}}}));
}

// Issue 18, defect 6: lock-out from two addresses. 32 silent streams (a StreamConfig, then
// nothing) from each of 127.0.0.2 and 127.0.0.3 took all 64 places: a new client got
// RESOURCE_EXHAUSTED until the 60 s idle timeout. The server must keep room for new clients.
TEST_F(AttackTest, SilentStreamsFromTwoAddressesDoNotLockANewClientOut) {
  StartServer({});
  const Figures f = Run("32 silent streams from each of two addresses",
                        {{{"silent-streams", "--source", "127.0.0.2", "--calls", "32"}},
                         {{"silent-streams", "--source", "127.0.0.3", "--calls", "32"}}},
                        // The silent streams have been silent longer than --shed-quiet-after
                        // (2 s) when the new client comes.
                        /*lead=*/milliseconds(2500));
  ExpectUnharmed(f);
}

// Defect 6 behind the shipped proxy: every call then comes from the proxy's address, and the
// server tells the clients apart by the proxy's x-forwarded-for (--trusted-proxy). Skipped in a
// quick look (SilentStreamsFromTwoAddresses checks the same without the proxy).
TEST_F(AttackTest, SilentStreamsThroughTheProxyDoNotLockANewClientOut) {
  if (!kFull) GTEST_SKIP() << kNeedsFull;
  StartServer({"--trusted-proxy", "127.0.0.1"});
  StartProxy();
  ExpectUnharmed(Run("32 silent streams from each of two addresses",
                     {{{"silent-streams", "--source", "127.0.0.2", "--calls", "32"}},
                      {{"silent-streams", "--source", "127.0.0.3", "--calls", "32"}}},
                     milliseconds(2500)));
}

// Issue 30, defects 2 and 7: one client behind the shipped HAProxy froze every other client, and
// its streams outlived it. HAProxy 2.6's HTTP/2 backend connection is one demultiplexer: when a
// stream's buffer on the proxy cannot drain (its client returns no window, or is gone while the
// server's frames for it are still arriving), the proxy stops reading the whole backend
// connection, and with `http-reuse always` every client's calls shared that connection. Each test
// runs an attack beside the paced stream through the shipped configuration, then, once the
// attacker has left, checks that new clients are served (health checks and Process calls through
// the proxy) and that the server's open streams fall to 0, each within 2 s. The attackers use two
// connections: HAProxy runs a thread per core (2 here), each with backend connections of its own,
// and a client's connection lands on one of them; with two, every shared backend connection gets
// the attack (with one, the tester saw one run in three freeze the others).
class ProxyIsolationTest : public AttackTest {
 protected:
  static constexpr double kServedWithinS = 2;
  static constexpr double kStreamsEndWithinS = 2;

  void SetUp() override {
    StartServer({"--trusted-proxy", "127.0.0.1"});
    if (!HasFatalFailure()) StartProxy();
  }

  // What new clients met after the attacker left (seconds after it left; -1: not within 10 s).
  struct Recovery {
    double served_s = -1;  // from then on, every new client was served (4 rounds in a row)
    int failed_rounds = 0;
    double streams_zero_s = -1;
    double streams_when_left = -1;  // the server's open streams as the attacker left
    std::string health_error, process_error;
    void Print() const {
      std::printf(
          "  after the attacker left: every new client served from %.2f s (%d rounds failed), "
          "server streams %.0f when it left, 0 after %.2f s (-1: not within 10 s)%s%s\n",
          served_s, failed_rounds, streams_when_left, streams_zero_s,
          health_error.empty() ? "" : ("; last health error: " + health_error).c_str(),
          process_error.empty() ? "" : ("; last Process error: " + process_error).c_str());
      std::fflush(stdout);
    }
  };

  // A Process call through the proxy from a new client (a channel, and so a connection, of its
  // own), at most `timeout`.
  grpc::Status ProcessOnce(int n, milliseconds timeout) {
    static const v1::ProcessRequest request = [] {
      v1::ProcessRequest r;
      *r.mutable_frame() = SyntheticRawFrame(160, 120);
      return r;
    }();
    grpc::ChannelArguments args;
    args.SetInt("cloudcast.test.probe", n);  // no connection shared with another channel
    auto stub = v1::CloudCast::NewStub(
        grpc::CreateCustomChannel(Target(), grpc::InsecureChannelCredentials(), args));
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + timeout);
    v1::CloudReply reply;
    return stub->Process(&ctx, request, &reply);
  }

  // Runs the attack (Run) and, on a thread of its own, waits for the first attacker to leave (its
  // JSON summary is written after its sockets are closed), then probes in rounds, for at most 10
  // s: a round is a health check and a Process call, each from a new client (a connection of its
  // own: HAProxy spreads them over its threads, each with backend connections of its own), each
  // at most 1 s, until 4 rounds in a row are served and the server's open streams are 0.
  Figures RunAndWatch(const std::string& name, const std::vector<Attacker>& attackers,
                      Recovery* recovery, double seconds_override = 0) {
    const std::string out = Scratch("attacker_0.json");
    std::filesystem::remove(out);  // Run writes it anew; an older one must not count
    std::atomic<bool> give_up{false};
    std::thread watcher([&] {
      const auto wait_until = Clock::now() + seconds(static_cast<int>(kAttackSeconds) + 120);
      while (testing::ReadText(out).find('{') == std::string::npos) {
        if (give_up.load() || Clock::now() > wait_until) return;
        Sleep(milliseconds(10));
      }
      const auto left = Clock::now();
      auto since = [&] { return std::chrono::duration<double>(Clock::now() - left).count(); };
      recovery->streams_when_left = Metric("cloudcast_active_streams");
      int in_a_row = 0;
      double served_from = 0;
      for (int n = 0; since() < 10; ++n) {
        if (recovery->streams_zero_s < 0 && Metric("cloudcast_active_streams") == 0) {
          recovery->streams_zero_s = since();
        }
        if (recovery->served_s < 0) {
          const absl::Status h = load::ProbeHealth(Target(), "", milliseconds(1000));
          if (!h.ok()) recovery->health_error = std::string(h.message());
          const grpc::Status p = ProcessOnce(n, milliseconds(1000));
          if (!p.ok()) {
            recovery->process_error =
                std::to_string(p.error_code()) + " " + p.error_message().substr(0, 120);
          }
          if (h.ok() && p.ok()) {
            ++in_a_row;
          } else {
            ++recovery->failed_rounds;
            in_a_row = 0;
            served_from = since();
          }
          if (in_a_row >= 4) recovery->served_s = served_from;
        }
        if (recovery->served_s >= 0 && recovery->streams_zero_s >= 0) break;
        // A few new connections a second: far below the proxy's 200 in 10 s per address.
        Sleep(milliseconds(200));
      }
    });
    Figures f = Run(name, attackers, milliseconds(300), seconds_override);
    give_up.store(true);
    watcher.join();
    recovery->Print();
    return f;
  }

  // `streams_within`: how soon after the attacker left the server's streams must be 0.
  static void ExpectRecovered(const Figures& f, const Recovery& r,
                              double streams_within = kStreamsEndWithinS) {
    EXPECT_GE(r.served_s, 0) << f.attack << ": new clients through the proxy were not all served "
                             << "within 10 s of the attacker leaving (" << r.failed_rounds
                             << " rounds failed; health: " << r.health_error
                             << "; Process: " << r.process_error << ")";
    EXPECT_LE(r.served_s, kServedWithinS) << f.attack << ": other clients served again after";
    EXPECT_GE(r.streams_zero_s, 0)
        << f.attack << ": the server still had open streams 10 s after "
        << "the attacker left (" << r.streams_when_left << " when it left)";
    EXPECT_LE(r.streams_zero_s, streams_within) << f.attack << ": the server's streams ended after";
  }
};

// Defect 2, trigger A: DELIVERY_ALL streams whose client advertises HTTP/2's default 64 KB window
// and stops giving it back (4 streams on 2 connections). Before: every client behind the proxy
// timed out (the tester: 4 streams, 1 of 1 runs, not back within 36 s).
TEST_F(ProxyIsolationTest, StalledWindowsOfOneClientFreezeNoOtherClient) {
  Recovery r;
  // At least 6 s: longer than the proxy's `timeout client` (5 s), so that what is checked after
  // the attacker leaves is what a stalled client leaves behind, whatever the build's attack time.
  const Figures f = RunAndWatch(
      "4 streams that never give window back",
      {{{"stalled-window", "--source", "127.0.0.2", "--calls", "4", "--connections", "2"}}}, &r,
      std::max(kAttackSeconds, 6.0));
  ExpectUnharmed(f);
  ExpectRecovered(f, r);
}

// Trigger A, slowly: 32 streams whose window comes back at 4 KB/s (the tester: 3 of 3 runs froze
// every client, not back within 84 s). Frames of 320x320: with 640x640 ones the server holds 128
// of them (200 MB) for this client, and the paced stream's p99 went past the bar in 2 of 3 runs
// (66 and 202 ms) on these shared cores, which is issue 18's business, not this one's. Skipped
// in a quick look.
TEST_F(ProxyIsolationTest, WindowsReturnedAt4KBPerSecondFreezeNoOtherClient) {
  if (!kFull) GTEST_SKIP() << kNeedsFull;
  Recovery r;
  const Figures f =
      RunAndWatch("32 streams giving window back at 4 KB/s",
                  {{{"stalled-window", "--source", "127.0.0.2", "--calls", "32", "--connections",
                     "2", "--window-rate", "4096", "--side", "320"}}},
                  &r);
  ExpectUnharmed(f);
  ExpectRecovered(f, r);
}

// Defect 2, trigger B: a client that sends a new StreamConfig before every frame, as fast as flow
// control lets it (4 calls on 2 connections; its frames zstd-compressed, a few hundred bytes each
// that decode to 640x640), reading every reply, then leaves. It locks its own calls up: HAProxy 2.6
// reads its connection in order and stops at a stream whose buffer is full, so its WINDOW_UPDATEs
// wait behind the frames it sent ahead while the server waits for its window. Before: every
// client behind the proxy frozen (the tester: about 120 s, 3 of 3 runs), and 3 to 4 of its streams
// still open on the server meanwhile. Now its calls alone stall, and the server closes the
// connection the proxy stopped reading (--ping-after, --ping-timeout: defect 7, below). At least
// 15 s: the client's first second (some 40,000 messages before its calls lock up) once cost the
// paced stream a hiccup of about 100 ms, which a 6 s attack's 171 frames put into the p99 (57 and
// 64 ms in 2 of 3 such runs; 13 and 17 ms in the 20 s runs); skipped in a quick look.
TEST_F(ProxyIsolationTest, AConfigChurningClientThatLeavesFreezesNoOtherClient) {
  if (!kFull) GTEST_SKIP() << kNeedsFull;
  Recovery r;
  const Figures f = RunAndWatch("config churn, then the client leaves",
                                {{{"config-churn", "--source", "127.0.0.2", "--calls", "4",
                                   "--connections", "2", "--encoding", "zstd"}}},
                                &r, std::max(kAttackSeconds, 15.0));
  ExpectUnharmed(f);
  ExpectRecovered(f, r);
}

// Defect 7's mechanism, without the proxy: a peer that stops reading its connection (a raw HTTP/2
// client that opens a Stream call, sends its StreamConfig, then reads nothing more, so answers no
// PING) loses it, with its call, within --ping-after + --ping-timeout (1.5 s) when the server is
// behind a trusted proxy; the server without the PINGs (--ping-after 0, as before) holds the call
// until its idle timeout (60 s).
TEST_F(AttackTest, AConnectionWhosePeerStopsReadingIsClosedWithItsCalls) {
  for (const bool pings : {false, true}) {
    std::vector<std::string> args = {"--trusted-proxy", "127.0.0.1"};
    if (!pings) args.insert(args.end(), {"--ping-after", "0"});
    StartServer(args);
    if (HasFatalFailure()) return;
    const std::string address = server_->address();
    const std::size_t colon = address.rfind(':');
    // Once more when the first try fails (seen once in 5 runs, on a loaded machine, just after
    // the server started): the connection is the test's means, not what it checks.
    auto connect = [&] {
      return attacks::RawH2Connection::Connect(address.substr(0, colon),
                                               std::stoi(address.substr(colon + 1)), "");
    };
    auto conn = connect();
    if (!conn.ok()) {
      std::printf("  connecting failed (%s): once more\n", conn.status().ToString().c_str());
      Sleep(milliseconds(500));
      conn = connect();
    }
    ASSERT_TRUE(conn.ok()) << conn.status();
    const auto deadline = Clock::now() + seconds(10);
    v1::StreamRequest config;
    config.mutable_config()->set_delivery(v1::DELIVERY_ALL);
    ASSERT_TRUE((*conn)->OpenStream(
        1, attacks::GrpcRequestHeaders("/cloudcast.v1.CloudCast/Stream", address), false,
        deadline));
    ASSERT_TRUE(
        (*conn)->SendData(1, attacks::GrpcMessage(config.SerializeAsString()), false, deadline));
    while (Metric("cloudcast_active_streams") < 1 && Clock::now() < deadline) {
      Sleep(milliseconds(20));
    }
    ASSERT_EQ(Metric("cloudcast_active_streams"), 1) << "the call did not open";
    (*conn)->StopReading();
    const auto stopped = Clock::now();
    // Watched for 4 s: the PINGs' 1.5 s, with room for a loaded machine.
    double gone_s = -1;
    while (Clock::now() - stopped < seconds(4)) {
      if (Metric("cloudcast_active_streams") == 0) {
        gone_s = std::chrono::duration<double>(Clock::now() - stopped).count();
        break;
      }
      Sleep(milliseconds(50));
    }
    std::printf(
        "| pings %s | the call ended %.2f s after its client stopped reading (-1: not "
        "within 4 s) |\n",
        pings ? "on (--trusted-proxy)" : "off (--ping-after 0)", gone_s);
    std::fflush(stdout);
    if (pings) {
      EXPECT_GE(gone_s, 0) << "the call outlived its unread connection by 4 s";
      EXPECT_LE(gone_s, 2.5);
    } else {
      EXPECT_EQ(gone_s, -1) << "without PINGs nothing should end a call whose client is silent "
                               "for 4 s (the idle timeout is 60 s)";
    }
    conn->reset();
    server_.reset();
  }
}

// Issue 30, defect 7: the streams of a client that leaves end on the server within 2 s, however it
// leaves. The churning client of trigger B locks its calls up within its first second; it leaves
// 1.5 s in, while its calls are young, either as a program exits (`close`: END_STREAM, then a FIN,
// or a TCP reset when replies came in after it stopped reading) or with a TCP reset at once
// (`abort`). HAProxy 2.6 reads neither: it has stopped reading the client's connection (a stream
// buffer full), and stops reading the server's connection too (the replies have nowhere to go).
// Before, the streams lasted until the proxy's timeouts: `timeout client` (5 s after their last
// progress: 2.8 to 3.8 s after the exit in the runs here) for `close`, and for `abort` longer than
// the 10 s watched (a call with request bytes the server does not read waits out `timeout
// server`, 2 minutes). Now the server pings a connection that has sent nothing for 0.5 s and
// closes it, with its calls, when the PING is not answered within 1 s (--ping-after and
// --ping-timeout, on by default with --trusted-proxy): the proxy has stopped reading it. The
// paced stream's latency is not judged here: the churning client's first second can cost it one
// hiccup of about 100 ms, the p99 of a 1.5 s stream (the long test above judges it over 20 s).
TEST_F(ProxyIsolationTest, TheStreamsOfAClientThatLeavesEndWithin2Seconds) {
  for (const char* exit : {"abort", "close"}) {
    Recovery r;
    const Figures f =
        RunAndWatch(std::string("config churn, leaving 1.5 s in (--exit ") + exit + ")",
                    {{{"config-churn", "--source", "127.0.0.2", "--calls", "4", "--connections",
                       "2", "--encoding", "zstd", "--exit", exit}}},
                    &r, /*seconds_override=*/1.5);
    EXPECT_GT(f.sent, 0u);
    EXPECT_EQ(f.answered, f.sent) << f.attack << ": the paced stream lost frames";
    EXPECT_EQ(f.errors, 0u) << f.attack;
    EXPECT_LT(f.rss_peak_mb, kMaxRssMb) << f.attack << ": server RSS during the attack";
    ASSERT_FALSE(f.attackers.empty());
    // The attack ran: its calls were opened and sent.
    EXPECT_EQ(f.attackers[0].value("calls", 0), 4) << f.attackers[0];
    EXPECT_GT(f.attackers[0].value("frames_sent", 0), 0) << f.attackers[0];
    ExpectRecovered(f, r);
  }
}

// Defect 1 against the server alone (no proxy): gRPC 1.51 cannot bound the streams a rapid reset
// makes it create (docs/http2-hardening.md: no deployment without the proxy is safe from it), but
// the server's own part is bounded: its log (26 MB in 20 s before: two lines per stream) and the
// streams it holds (a cancelled stream keeps its place until gRPC is done with it), at most
// --max-streams.
TEST_F(AttackTest, RapidResetAgainstTheServerAloneDoesNotFloodItsLog) {
  StartServer({"--max-streams", "64"});
  // The streams the service holds (admitted, not yet done), sampled through the attack.
  std::atomic<bool> stop{false};
  std::atomic<double> most_streams{0};
  std::thread sampler([&] {
    while (!stop.load()) {
      most_streams.store(std::max(most_streams.load(), Metric("cloudcast_active_streams")));
      Sleep(milliseconds(50));
    }
  });
  const Figures f =
      Run("rapid reset, Stream, no proxy (log only)",
          {{{"rapid-reset", "--source", "127.0.0.2", "--path", "/cloudcast.v1.CloudCast/Stream"},
            kFullSpeed}},
          milliseconds(300), /*seconds_override=*/3);
  stop.store(true);
  sampler.join();
  std::printf("  streams held at most: %.0f\n", most_streams.load());
  // Every stream holds its place until gRPC is done with it, however gRPC reports the reset:
  // before, a reset reported as a failed read gave its place back at once, and the server held
  // 10,233 streams against --max-streams 64 (33 after).
  EXPECT_LE(most_streams.load(), 64);
  EXPECT_LT(f.log_mb, 0.25) << "the server's log grew " << f.log_mb << " MB in 3 s";
  EXPECT_GT(Metric("cloudcast_log_lines_suppressed_total"), 0);
  EXPECT_GT(Metric("cloudcast_streams_cancelled_total"), 0);
}

// Issue 30, defect 6: SIGTERM during a rapid reset against the server alone. The tester's run: the
// shutdown took 9.1 s against a 5 s grace, and the paced DELIVERY_ALL stream ended with "Cancelling
// all calls", 2 frames it had sent before the signal unanswered. The bar: the process exits 0
// within its grace plus kShutdownToleranceS (the server promises grace + 0.5 s), and every frame
// the paced stream had sent before the signal is answered, or left to the client library's resend
// (below: only a frame the flood kept the server from reading).
//
// The paced stream is a plain synchronous client (not the Fleet): the test must know, frame by
// frame, whether its client had sent it (its Write returned) before the signal.
constexpr double kShutdownToleranceS = 1.0;

class SignalledStream {
 public:
  SignalledStream(const std::string& target, double fps, std::uint64_t max_frames)
      : period_(
            std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1 / fps))),
        frames_(max_frames) {
    grpc::ChannelArguments args;
    args.SetInt("cloudcast.test.signalled_stream", 1);  // a connection of its own
    stub_ = v1::CloudCast::NewStub(
        grpc::CreateCustomChannel(target, grpc::InsecureChannelCredentials(), args));
    context_.set_deadline(std::chrono::system_clock::now() + seconds(120));
    stream_ = stub_->Stream(&context_);
    v1::StreamRequest config;
    config.mutable_config()->set_delivery(v1::DELIVERY_ALL);
    stream_->Write(config);
    reader_ = std::thread([this] { Read(); });
    writer_ = std::thread([this] { WriteFrames(); });
  }
  ~SignalledStream() { Finish(); }

  // Waits until `n` frames were answered (or the stream ended, or `timeout`).
  bool WaitForAnswers(std::uint64_t n, Clock::duration timeout) {
    std::unique_lock<std::mutex> lock(mu_);
    cv_.wait_for(lock, timeout, [&] { return answered_ >= n || read_done_; });
    return answered_ >= n;
  }
  // Runs `signal` (it sends the signal) with the book closed: every frame recorded as sent
  // before it had its Write return before the signal went.
  template <typename Signal>
  void MarkSignal(Signal signal) {
    std::lock_guard<std::mutex> lock(mu_);
    signalled_ = true;
    signal();
  }
  // Waits for the server to end the call (bounded by the call's deadline), then its status.
  grpc::Status Finish() {
    if (reader_.joinable()) reader_.join();
    stop_.store(true);
    if (writer_.joinable()) writer_.join();
    if (!finished_) {
      finished_ = true;
      status_ = stream_->Finish();
    }
    return status_;
  }

  // The frames sent before the signal: answered (with a FrameError among them; answered during
  // the drain, after the signal), or not (their sequences).
  struct Account {
    std::uint64_t sent_before = 0, answered_before = 0, errors_before = 0, drained = 0;
    std::uint64_t last_answered = 0;  // the highest sequence answered, of any frame
    std::vector<std::uint64_t> unanswered_before;
  };
  Account account() {
    std::lock_guard<std::mutex> lock(mu_);
    Account a;
    for (std::size_t i = 0; i < frames_.size(); ++i) {
      const FrameState& f = frames_[i];
      if (f.answered) a.last_answered = i + 1;
      if (!f.sent || !f.before) continue;
      ++a.sent_before;
      if (f.answered) {
        ++a.answered_before;
        a.errors_before += f.error ? 1 : 0;
        a.drained += f.answered_after ? 1 : 0;
      } else {
        a.unanswered_before.push_back(i + 1);
      }
    }
    return a;
  }

 private:
  struct FrameState {
    bool sent = false, before = false, answered = false, error = false, answered_after = false;
  };

  static const v1::Frame& PacedFrame() {
    static const v1::Frame frame = SyntheticRawFrame(640, 480);
    return frame;
  }

  // 30 fps on a fixed schedule (a late write goes at once), frame i with sequence i + 1.
  void WriteFrames() {
    v1::StreamRequest request;
    *request.mutable_frame() = PacedFrame();
    const auto t0 = Clock::now();
    for (std::size_t i = 0; i < frames_.size() && !stop_.load(); ++i) {
      std::this_thread::sleep_until(t0 + period_ * static_cast<int>(i));  // the pace, not a wait
      request.mutable_frame()->set_sequence(i + 1);
      if (!stream_->Write(request)) return;  // the call is over
      std::lock_guard<std::mutex> lock(mu_);
      frames_[i].sent = true;
      frames_[i].before = !signalled_;
    }
  }

  void Read() {
    v1::StreamReply reply;
    while (stream_->Read(&reply)) {
      const std::uint64_t sequence =
          reply.has_cloud() ? reply.cloud().sequence() : reply.error().sequence();
      std::lock_guard<std::mutex> lock(mu_);
      if (sequence >= 1 && sequence <= frames_.size() && !frames_[sequence - 1].answered) {
        frames_[sequence - 1].answered = true;
        frames_[sequence - 1].answered_after = signalled_;
        frames_[sequence - 1].error = reply.has_error();
        ++answered_;
      }
      cv_.notify_all();
    }
    std::lock_guard<std::mutex> lock(mu_);
    read_done_ = true;
    cv_.notify_all();
  }

  const Clock::duration period_;
  std::unique_ptr<v1::CloudCast::Stub> stub_;
  grpc::ClientContext context_;
  std::unique_ptr<grpc::ClientReaderWriter<v1::StreamRequest, v1::StreamReply>> stream_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::vector<FrameState> frames_;  // under mu_
  std::uint64_t answered_ = 0;      // under mu_
  bool read_done_ = false;          // under mu_
  bool signalled_ = false;          // under mu_
  std::atomic<bool> stop_{false};
  bool finished_ = false;
  grpc::Status status_;
  std::thread reader_, writer_;
};

TEST_F(AttackTest, SigtermDuringARapidResetEndsWithinTheGraceAndLosesNoFrameSent) {
  // The tester's 5 s grace after 10 s of attack (a quick look: 3 s after 3 s). The attack goes on
  // past the end of the grace and its tolerance (at most 20 s in all).
  const double grace_s = kFull ? 5 : 3;
  const double lead_s = kFull ? 10 : 3;
  const double attack_s = std::min(20.0, lead_s + grace_s + kShutdownToleranceS + 3);
  StartServer({"--shutdown-grace", std::to_string(grace_s)});
  if (HasFatalFailure()) return;
  // The paced stream answers before the attack starts.
  SignalledStream paced(server_->address(), 30, 30 * 120);
  ASSERT_TRUE(paced.WaitForAnswers(3, seconds(30))) << "the paced stream got no answer";

  const std::string out = Scratch("attacker.json");
  Child attacker({testing::BinDir() + "/cloudcast-attack", "rapid-reset", "--source", "127.0.0.2",
                  "--path", "/cloudcast.v1.CloudCast/Stream", "--target", server_->address(),
                  "--seconds", std::to_string(attack_s)},
                 out, {}, kFullSpeed);
  const auto give_up = Clock::now() + seconds(60);
  while (testing::ReadText(out).find(": ready") == std::string::npos && Clock::now() < give_up) {
    Sleep(milliseconds(20));
  }
  // The attack builds its backlog in the server for lead_s, then the signal.
  Sleep(std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(lead_s)));
  Clock::time_point signalled;
  paced.MarkSignal([&] {
    signalled = Clock::now();
    server_->Signal(SIGTERM);
  });
  // The exit, waited for on a thread of its own; SIGKILL 30 s past the bar turns a hang into a
  // failure.
  std::mutex mu;
  std::condition_variable cv;
  bool exited = false;
  std::optional<int> code;
  Clock::time_point exit_time;
  const pid_t pid = server_->pid();
  std::thread waiter([&] {
    const std::optional<int> c = server_->Wait();
    std::lock_guard<std::mutex> lock(mu);
    code = c;
    exit_time = Clock::now();
    exited = true;
    cv.notify_all();
  });
  {
    std::unique_lock<std::mutex> lock(mu);
    if (!cv.wait_for(lock, seconds(static_cast<int>(grace_s + kShutdownToleranceS) + 30),
                     [&] { return exited; })) {
      kill(pid, SIGKILL);
    }
  }
  waiter.join();
  const double shutdown_s = std::chrono::duration<double>(exit_time - signalled).count();
  const grpc::Status status = paced.Finish();
  const SignalledStream::Account a = paced.account();
  attacker.Wait(seconds(static_cast<int>(attack_s) + 30));
  const std::string log = testing::ReadText(log_);
  std::string shut_down_line;
  if (const std::size_t at = log.rfind("shut down in"); at != std::string::npos) {
    shut_down_line = log.substr(at, log.find('\n', at) - at);
  }
  // | grace s | shutdown s | exit | sent before the signal | answered (during the drain; as
  // FrameErrors) | unanswered | the paced stream's status | the server's last words |
  std::printf("| %.0f | %.2f | %s | %lu | %lu (%lu; %lu) | %lu | %d %s | %s |\n", grace_s,
              shutdown_s, code ? std::to_string(*code).c_str() : "signal",
              static_cast<unsigned long>(a.sent_before),
              static_cast<unsigned long>(a.answered_before), static_cast<unsigned long>(a.drained),
              static_cast<unsigned long>(a.errors_before),
              static_cast<unsigned long>(a.unanswered_before.size()), status.error_code(),
              status.error_message().c_str(), shut_down_line.c_str());
  std::printf("  attacker: %s\n", testing::ReadText(out).substr(0, 600).c_str());
  std::fflush(stdout);
  EXPECT_EQ(code, std::optional<int>(0)) << log.substr(log.size() > 4000 ? log.size() - 4000 : 0);
  EXPECT_LE(shutdown_s, grace_s + kShutdownToleranceS)
      << "from SIGTERM to the exit, against a grace of " << grace_s << " s";
  EXPECT_GT(a.sent_before, 0u);
  // The shutdown ended the stream with a status on which the client library moves the stream and
  // sends its unanswered frames again (client.cc, EndedByTheServerSide).
  EXPECT_TRUE(status.error_code() == grpc::StatusCode::UNAVAILABLE ||
              status.error_code() == grpc::StatusCode::CANCELLED)
      << status.error_code() << " " << status.error_message();
  // Every frame sent before the signal is answered, unless the server never read it: a rapid
  // reset against the server alone can starve a connection's reads for seconds (gRPC 1.51,
  // docs/http2-hardening.md), and a frame still in the server's socket at the end is left to the
  // client library. Those must come after the last frame answered: the library's ResendLedger
  // sends them again, where a frame answered after them would have it book them as skipped.
  if (!a.unanswered_before.empty()) {
    std::string missing;
    for (std::uint64_t s : a.unanswered_before) missing += " " + std::to_string(s);
    EXPECT_GT(a.unanswered_before.front(), a.last_answered)
        << "frames sent before the signal were left unanswered before frame " << a.last_answered
        << ", which was answered:" << missing;
    std::printf(
        "  not answered when the server ended the call, left to the client library's "
        "resend:%s\n",
        missing.c_str());
  }
}

}  // namespace
}  // namespace cloudcast
