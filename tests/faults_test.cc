// Faults, each against real cloudcast-server processes, and what a client sees:
//   - clients that vanish mid-frame (cloudcast-load processes killed while they send 1280x960
//     frames): the server ends their streams, keeps serving, and a new robot gets every frame;
//   - the network stalls for seconds and recovers (the server in a network namespace the test
//     makes, behind a veth pair; every packet dropped for 3 s): DELIVERY_ALL loses nothing, the
//     stream only waits;
//   - the server gets SIGKILL or SIGTERM under load and is started again on its port: a
//     resilient DELIVERY_ALL stream reconnects, sends again what was not answered, and every
//     frame is answered exactly once (nothing acknowledged is lost).
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "cloudcast/client/client.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/testing/metrics_scrape.h"
#include "support/replica_support.h"
#include "support/robot.h"
#include "support/small_frames.h"
#include "support/waiting.h"

extern char** environ;

namespace cloudcast {
namespace {

namespace cc = cloudcast::client;
using std::chrono::milliseconds;
using testing::ServerProcess;

const std::vector<SyntheticFrame>& Frames() { return testing::SmallFrames(3); }

using testing::Robot;

std::unique_ptr<Robot> OpenRobot(cc::Client& client, bool resilient) {
  return testing::OpenRobot(client, resilient, milliseconds(30000));
}

// Sends `frames` frames at `fps` (a camera's pace), then finishes the stream.
void Drive(Robot* robot, int frames, double fps) {
  const auto start = testing::SteadyClock::now();
  for (int i = 0; i < frames; ++i) {
    testing::PauseUntil(start + std::chrono::duration_cast<testing::SteadyClock::duration>(
                                    std::chrono::duration<double>(i / fps)));
    const SyntheticFrame& f = Frames()[static_cast<std::size_t>(i) % Frames().size()];
    cc::FrameMeta meta;
    meta.sequence = static_cast<std::uint64_t>(i);
    {
      std::lock_guard<std::mutex> lock(robot->mu);
      robot->sent_at[static_cast<std::uint64_t>(i)] = std::chrono::steady_clock::now();
    }
    if (!robot->stream->Send(f.disparity_view(), f.colour_view(), meta).ok()) break;
  }
  robot->final_status = robot->stream->Finish();
}

std::unique_ptr<cc::Client> Connect(const std::string& target) {
  cc::ClientOptions options;
  options.decode_clouds = false;
  options.connect_timeout = milliseconds(20000);
  auto client = cc::Client::Connect(target, options);
  EXPECT_TRUE(client.ok()) << client.status();
  return client.ok() ? *std::move(client) : nullptr;
}

// A program run in the background; killed (SIGKILL) and reaped when it goes out of scope.
class Child {
 public:
  explicit Child(const std::vector<std::string>& args) {
    std::vector<char*> argv;
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", O_WRONLY, 0);
    if (posix_spawn(&pid_, argv[0], &actions, nullptr, argv.data(), environ) != 0) pid_ = 0;
    posix_spawn_file_actions_destroy(&actions);
  }
  ~Child() { Kill(); }
  void Kill() {
    if (pid_ <= 0) return;
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
    pid_ = 0;
  }
  bool started() const { return pid_ > 0; }

 private:
  pid_t pid_ = 0;
};

// Clients vanish mid-frame: cloudcast-load processes sending 1280x960 frames (1.2 MB raw, many
// HTTP/2 frames each) are killed while frames are on the wire. Their TCP connections close (or
// reset) with a message half read. The server ends those streams, frees them, and carries on.
// Each test's logs in a folder of its own (ctest runs two of this binary's at once).
using FaultsTest = testing::ScratchDirTest;

TEST_F(FaultsTest, ClientsVanishingMidFrameLeaveNoStreamAndOthersCarryOn) {
  ServerProcess server("127.0.0.1:0", "faults", {}, Path("server.log"), "warn", "127.0.0.1:0");
  ASSERT_TRUE(server.WaitUntilServing());
  const int metrics = server.metrics_port();
  auto metric = [&](const std::string& name) {
    return server::MetricValue(server::ScrapeMetrics(metrics), name);
  };
  constexpr int kRounds = 4;
  for (int round = 0; round < kRounds; ++round) {
    const double received_before = metric("cloudcast_bytes_received_total");
    Child load({testing::BinDir() + "/cloudcast-load", "--server", server.address(), "--synthetic",
                "1280x960", "--synthetic-frames", "2", "--streams", "3", "--fps", "200",
                "--lossless", "--duration", "60", "--quiet"});
    ASSERT_TRUE(load.started());
    // Once its frames are arriving (a server counter: nothing announces it).
    ASSERT_TRUE(testing::Eventually([&] {
      return metric("cloudcast_active_streams") >= 3 &&
             metric("cloudcast_bytes_received_total") > received_before + 4e6;
    })) << server.log();
    load.Kill();
    // The server notices the vanished connections and ends their streams.
    EXPECT_TRUE(testing::Eventually([&] { return metric("cloudcast_active_streams") == 0; }))
        << "round " << round << ": " << metric("cloudcast_active_streams") << " streams left";
  }
  std::printf("%d rounds of 3 streams killed mid-frame: %.0f frames processed, %.0f MB read\n",
              kRounds, metric("cloudcast_frames_processed_total"),
              metric("cloudcast_bytes_received_total") / 1e6);
  EXPECT_TRUE(server.running());
  // A new robot is served in full.
  auto client = Connect(server.address());
  ASSERT_NE(client, nullptr);
  auto robot = OpenRobot(*client, false);
  ASSERT_NE(robot->stream, nullptr);
  Drive(robot.get(), 30, 100);
  robot->ExpectEveryFrameOnce(30);
}

// A network namespace with one end of a veth pair, made by the test and removed after. The
// server runs inside it; the test talks to it across the pair. Its /30 is one that no route of
// the host uses: a pair left by a killed run (or anything else on 10.213/16) holding the same
// subnet would take the test's packets, and the server would never be reached.
class Namespace {
 public:
  Namespace() {
    RemoveStale();
    name_ = "ccfault" + std::to_string(getpid());
    host_if_ = "ccf" + std::to_string(getpid()) + "h";
    ns_if_ = "ccf" + std::to_string(getpid()) + "n";
    const int slot = FreeSlot();
    if (slot < 0) return;
    host_ip_ = Address(slot, 1);
    ns_ip_ = Address(slot, 2);
    ok_ = Run("ip netns add " + name_) &&
          Run("ip link add " + host_if_ + " type veth peer name " + ns_if_ + " netns " + name_) &&
          Run("ip addr add " + host_ip_ + "/30 dev " + host_if_) &&
          Run("ip link set " + host_if_ + " up") &&
          Run(Exec("ip addr add " + ns_ip_ + "/30 dev " + ns_if_)) &&
          Run(Exec("ip link set " + ns_if_ + " up")) && Run(Exec("ip link set lo up"));
  }
  ~Namespace() {
    Run("ip link del " + host_if_ + " 2>/dev/null");
    Run("ip netns del " + name_ + " 2>/dev/null");
  }
  bool ok() const { return ok_; }
  std::string Exec(const std::string& command) const {
    return "ip netns exec " + name_ + " " + command;
  }
  std::vector<std::string> Prefix() const { return {"/usr/sbin/ip", "netns", "exec", name_}; }
  const std::string& ns_ip() const { return ns_ip_; }
  const std::string& ns_if() const { return ns_if_; }

  // What a failure to reach the server needs to be told apart: the routes to the namespace's
  // address, and what listens inside it.
  std::string Diagnose() const {
    return "route to " + ns_ip_ + ": " + Capture("ip -4 route get " + ns_ip_) +
           "host routes on 10.213/16:\n" + Capture("ip -4 route show | grep '^10\\.213\\.'") +
           "listening in " + name_ + ":\n" + Capture(Exec("ss -ltn")) +
           "link: " + Capture("ip -br link show " + host_if_);
  }

  // Every packet in and out of the namespace dropped, or let through again: netem's "loss 100%"
  // where the kernel has netem, else the same with iptables inside the namespace.
  bool Stall(bool on) {
    if (netem_ || (on && Run(Exec("tc qdisc add dev " + ns_if_ + " root netem loss 100%") +
                             " 2>/dev/null"))) {
      netem_ = on;
      return on || Run(Exec("tc qdisc del dev " + ns_if_ + " root"));
    }
    const std::string op = on ? "-I" : "-D";
    return Run(Exec("iptables " + op + " INPUT -i " + ns_if_ + " -j DROP")) &&
           Run(Exec("iptables " + op + " OUTPUT -o " + ns_if_ + " -j DROP"));
  }
  const char* how() const { return netem_ ? "tc netem loss 100%" : "iptables DROP"; }

  static bool Run(const std::string& command) { return std::system(command.c_str()) == 0; }

 private:
  static std::string Capture(const std::string& command) {
    std::string out;
    if (FILE* pipe = popen((command + " 2>&1").c_str(), "r")) {
      char buffer[512];
      while (std::fgets(buffer, sizeof buffer, pipe) != nullptr) out += buffer;
      pclose(pipe);
    }
    return out;
  }
  // The first /30 in 10.213/16 from this process's own start that no host route holds, as its
  // slot (10.213.slot/64.(slot%64)*4); -1 when all 16,384 are taken.
  static int FreeSlot() {
    const std::string routes = Capture("ip -4 route show");
    constexpr int kSlots = 16384;
    for (int i = 0; i < kSlots; ++i) {
      const int slot = (static_cast<int>(getpid()) + i) % kSlots;
      if (routes.find(Address(slot, 0) + "/30") == std::string::npos) return slot;
    }
    return -1;
  }
  static std::string Address(int slot, int host) {
    return "10.213." + std::to_string(slot / 64) + "." + std::to_string(slot % 64 * 4 + host);
  }
  // Namespaces and host ends this test made in a run that was killed before its destructor.
  static void RemoveStale() {
    std::istringstream names(Capture("ip netns list | sed -n 's/^ccfault\\([0-9]*\\).*/\\1/p'"));
    for (std::string pid; std::getline(names, pid);) {
      if (!pid.empty() && kill(std::stoi(pid), 0) != 0 && errno == ESRCH) {
        Run("ip netns del ccfault" + pid + " 2>/dev/null");
      }
    }
    std::istringstream links(
        Capture("ip -o link show | sed -n 's/^[0-9]*: ccf\\([0-9]*\\)h[@:].*/\\1/p'"));
    for (std::string pid; std::getline(links, pid);) {
      if (!pid.empty() && kill(std::stoi(pid), 0) != 0 && errno == ESRCH) {
        Run("ip link del ccf" + pid + "h 2>/dev/null");
      }
    }
  }

  std::string name_, host_if_, ns_if_, host_ip_, ns_ip_;
  bool ok_ = false, netem_ = false;
};

// The network stalls for 3 s mid-stream (no packet passes either way), then recovers. TCP
// retransmits; the DELIVERY_ALL stream waits and then every frame is answered, on the same call.
TEST_F(FaultsTest, NetworkStallOfSecondsThenRecoveryLosesNothing) {
  if (geteuid() != 0 || !Namespace::Run("command -v ip >/dev/null && ip netns list >/dev/null")) {
    GTEST_SKIP() << "needs root and iproute2 to make a network namespace";
  }
  Namespace ns;
  if (!ns.ok()) GTEST_SKIP() << "could not make a network namespace with a veth pair here";
  // Port 0: the server's --ready-file says what it bound, and whether it started at all.
  ServerProcess server(ns.ns_ip() + ":0", "stalled", {}, Path("server.log"), "warn", "",
                       ns.Prefix());
  ASSERT_TRUE(server.WaitUntilServing()) << (server.running() ? "running" : "ended") << ", bound '"
                                         << server.address() << "'\n--- log:\n"
                                         << server.log() << "--- network:\n"
                                         << ns.Diagnose();
  const std::string address = server.address();
  auto client = Connect(address);
  ASSERT_NE(client, nullptr);
  auto robot = OpenRobot(*client, false);
  ASSERT_NE(robot->stream, nullptr);
  constexpr int kFrames = 240;  // 8 s at 30 fps
  std::thread driver(Drive, robot.get(), kFrames, 30.0);
  ASSERT_TRUE(robot->WaitForAnswers(45));
  ASSERT_TRUE(ns.Stall(true));
  const std::size_t at_stall = robot->answered();
  testing::PauseFor(std::chrono::seconds(3));  // the fault's length: a clock, not a wait
  const std::size_t during = robot->answered() - at_stall;
  ASSERT_TRUE(ns.Stall(false));
  driver.join();
  std::printf(
      "network stalled 3 s (%s) at frame %zu: %zu answers during the stall, then all %zu "
      "answered; worst send-to-answer %.0f ms, reconnects %zu\n",
      ns.how(), at_stall, during, robot->answered(), robot->MaxLatencyMs(),
      robot->reconnects.size());
  EXPECT_LE(during, 2u);  // nothing passes while stalled (an answer already on the wire may)
  robot->ExpectEveryFrameOnce(kFrames);
  EXPECT_TRUE(robot->reconnects.empty());
}

// The server is killed (SIGKILL) or stopped (SIGTERM, which drains) under load, then started again
// on the same port, as a supervisor or Kubernetes would. A resilient DELIVERY_ALL stream sees
// UNAVAILABLE, reconnects once the server is back, sends again every frame not answered, and
// every frame is answered exactly once.
class ServerStopTest : public testing::ScratchDirTest,
                       public ::testing::WithParamInterface<int> {};

TEST_P(ServerStopTest, ResilientStreamLosesNothingAcrossAServerRestart) {
  const int signal_number = GetParam();
  // The second server comes back on the address the first one bound. A loopback address of this
  // test's own: on 127.0.0.1 the port, free again once the first server is gone, was taken
  // meanwhile by another test's server asking for port 0, and the robot reconnected to it.
  const std::string own_ip = "127.88." + std::to_string(getpid() / 250 % 250 + 1) + "." +
                             std::to_string(getpid() % 250 + 1);
  auto server = std::make_unique<ServerProcess>(own_ip + ":0", "first", std::vector<std::string>{},
                                                Path("first.log"));
  ASSERT_TRUE(server->WaitUntilServing());
  const std::string address = server->address();
  auto client = Connect(address);
  ASSERT_NE(client, nullptr);
  auto robot = OpenRobot(*client, true);
  ASSERT_NE(robot->stream, nullptr);
  constexpr int kFrames = 300;
  std::thread driver(Drive, robot.get(), kFrames, 60.0);
  ASSERT_TRUE(robot->WaitForAnswers(60));
  server->Signal(signal_number);
  const std::optional<int> status = server->Wait();
  const std::size_t at_stop = robot->answered();
  server = std::make_unique<ServerProcess>(address, "second", std::vector<std::string>{},
                                           Path("second.log"));
  ASSERT_TRUE(server->WaitUntilServing());
  driver.join();
  std::string took;
  for (const cc::Reconnect& e : robot->reconnects) {
    took += std::to_string(e.took.count()) + " ";
    std::printf("  reconnect %d: cause %s, took %lld ms\n", e.attempt, e.cause.ToString().c_str(),
                static_cast<long long>(e.took.count()));
  }
  std::printf("  stream ended: %s\n", robot->final_status.ToString().c_str());
  std::printf(
      "SIG%s under load at %zu answers, restarted: %zu reconnects (%sms), %lu frames "
      "sent again, %zu of %d answered\n",
      sigabbrev_np(signal_number), at_stop, robot->reconnects.size(), took.c_str(),
      static_cast<unsigned long>(robot->stream->frames_resent()), robot->answered(), kFrames);
  robot->ExpectEveryFrameOnce(kFrames);
  ASSERT_GE(robot->reconnects.size(), 1u);
  EXPECT_EQ(robot->reconnects.front().cause.code(), absl::StatusCode::kUnavailable)
      << robot->reconnects.front().cause;
  if (signal_number == SIGTERM) {
    EXPECT_EQ(status, std::optional<int>(0));
  }
}

INSTANTIATE_TEST_SUITE_P(Signals, ServerStopTest, ::testing::Values(SIGKILL, SIGTERM),
                         [](const ::testing::TestParamInfo<int>& info) {
                           return std::string(sigabbrev_np(info.param));
                         });

}  // namespace
}  // namespace cloudcast
