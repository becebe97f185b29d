// cloudcast-linkemu delivers the link it is told to, measured with plain transfers through it:
// a TCP bulk transfer each way for the rate, UDP echo probes for the delay, jitter, loss, burst
// loss and an outage, and the namespaces gone afterwards. The tolerances are wide (a noisy shared
// 2-core machine): each checks that the emulator does what it says, not how fast the machine is.
// Each emulator is bounded by its own --timeout. Skips without root.
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sched.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "cloudcast/linkemu/emulated_link.h"
#include "gtest/gtest.h"

namespace cloudcast::linkemu {
namespace {

using Clock = std::chrono::steady_clock;
constexpr int kPort = 5201;

double Seconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

class LinkemuSelfTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (geteuid() != 0) GTEST_SKIP() << "needs root (network namespaces, NFQUEUE)";
    if (std::system("command -v ip >/dev/null && command -v iptables >/dev/null") != 0) {
      GTEST_SKIP() << "needs iproute2 and iptables";
    }
  }

  std::unique_ptr<EmulatedLink> Start(std::vector<std::string> flags, double timeout_s = 40) {
    EmulatedLink::Options options;
    options.binary = std::string(CLOUDCAST_BIN_DIR) + "/cloudcast-linkemu";
    options.flags = std::move(flags);
    options.timeout_s = timeout_s;
    absl::StatusOr<std::unique_ptr<EmulatedLink>> link = EmulatedLink::Start(options);
    EXPECT_TRUE(link.ok()) << link.status();
    if (!link.ok()) return nullptr;
    std::printf("linkemu ready: %s\n", (*link)->ready().dump().c_str());
    return std::move(*link);
  }
};

// Runs `body` in a child process inside the network namespace `netns`; its result (a number) comes
// back through a pipe. The child is killed if it outlives `bound_s`.
class NamespaceChild {
 public:
  NamespaceChild(const std::string& netns, std::function<double(int ready_fd)> body,
                 double bound_s) {
    int fds[2];
    if (pipe(fds) != 0) return;
    pid_ = fork();
    if (pid_ == 0) {
      close(fds[0]);
      alarm(static_cast<unsigned>(bound_s) + 1);
      const int ns = open(("/run/netns/" + netns).c_str(), O_RDONLY);
      if (ns < 0 || setns(ns, CLONE_NEWNET) != 0) _exit(3);
      const double result = body(fds[1]);
      if (write(fds[1], &result, sizeof(result)) != sizeof(result)) _exit(4);
      _exit(0);
    }
    close(fds[1]);
    fd_ = fds[0];
  }
  // Waits for the child's "listening" byte (sent by the body through ready_fd).
  bool WaitReady() {
    char c = 0;
    return fd_ >= 0 && read(fd_, &c, 1) == 1;
  }
  double Result() {
    double value = -1;
    if (fd_ >= 0 && read(fd_, &value, sizeof(value)) != sizeof(value)) value = -1;
    int status = 0;
    if (pid_ > 0) waitpid(pid_, &status, 0);
    pid_ = -1;
    return value;
  }
  ~NamespaceChild() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
    if (fd_ >= 0) close(fd_);
  }

 private:
  pid_t pid_ = -1;
  int fd_ = -1;
};

sockaddr_in Address(const std::string& ip, int port) {
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  inet_pton(AF_INET, ip.c_str(), &a.sin_addr);
  return a;
}

// CUBIC, as robots run, on each socket (the namespaces' default here can only be reno or bbr).
bool UseCubic(int sock) {
  static const char kCubic[] = "cubic";
  char name[16] = {};
  socklen_t length = sizeof(name);
  return setsockopt(sock, IPPROTO_TCP, TCP_CONGESTION, kCubic, sizeof(kCubic) - 1) == 0 &&
         getsockopt(sock, IPPROTO_TCP, TCP_CONGESTION, name, &length) == 0 &&
         std::strcmp(name, kCubic) == 0;
}

void SignalReady(int fd) {
  const char c = 'r';
  (void)!write(fd, &c, 1);
}

// Payload bytes received in the window [from, to] seconds after the first byte, as bits/s.
double ReceiveRate(int sock, double from, double to) {
  std::vector<char> buffer(1 << 16);
  Clock::time_point first;
  bool started = false;
  double counted = 0;
  for (;;) {
    const ssize_t n = recv(sock, buffer.data(), buffer.size(), 0);
    if (n <= 0) break;
    if (!started) {
      started = true;
      first = Clock::now();
    }
    const double t = Seconds(first);
    if (t >= from && t <= to) counted += static_cast<double>(n);
    if (t > to) break;
  }
  return counted * 8 / (to - from);
}

void SendFor(int sock, double seconds) {
  std::vector<char> buffer(1 << 16, 'x');
  const auto start = Clock::now();
  while (Seconds(start) < seconds) {
    if (send(sock, buffer.data(), buffer.size(), MSG_NOSIGNAL) <= 0) break;
  }
}

// TCP bulk each way: the goodput is the configured rate less the TCP/IP headers (1448 of 1500
// bytes), and never above the rate: 4 Mbit/s up, 8 Mbit/s down, 10 ms each way.
TEST_F(LinkemuSelfTest, TcpBulkTransferRunsAtTheConfiguredRateEachWay) {
  auto link = Start({"--up-rate", "4mbit", "--down-rate", "8mbit", "--delay", "10ms"});
  ASSERT_NE(link, nullptr);
  const std::string ip = link->server_ip();
  // Uplink: the namespace's end receives and measures.
  NamespaceChild sink(
      link->server_netns(),
      [&](int ready) {
        const int s = socket(AF_INET, SOCK_STREAM, 0);
        const int one = 1;
        setsockopt(s, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
        sockaddr_in a = Address(ip, kPort);
        if (!UseCubic(s) || bind(s, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0 ||
            listen(s, 1) != 0) {
          return -1.0;
        }
        SignalReady(ready);
        const int c = accept(s, nullptr, nullptr);
        return ReceiveRate(c, 1.5, 4.5);
      },
      20);
  ASSERT_TRUE(sink.WaitReady());
  {
    const int c = socket(AF_INET, SOCK_STREAM, 0);
    ASSERT_TRUE(UseCubic(c));
    sockaddr_in a = Address(ip, kPort);
    ASSERT_EQ(connect(c, reinterpret_cast<sockaddr*>(&a), sizeof(a)), 0) << std::strerror(errno);
    SendFor(c, 5.5);
    close(c);
  }
  const double up = sink.Result();
  // Downlink: the namespace's end sends, this end measures.
  NamespaceChild source(
      link->server_netns(),
      [&](int ready) {
        const int s = socket(AF_INET, SOCK_STREAM, 0);
        const int one = 1;
        setsockopt(s, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
        sockaddr_in a = Address(ip, kPort + 1);
        if (!UseCubic(s) || bind(s, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0 ||
            listen(s, 1) != 0) {
          return -1.0;
        }
        SignalReady(ready);
        const int c = accept(s, nullptr, nullptr);
        SendFor(c, 5.5);
        close(c);
        return 0.0;
      },
      20);
  ASSERT_TRUE(source.WaitReady());
  const int c = socket(AF_INET, SOCK_STREAM, 0);
  ASSERT_TRUE(UseCubic(c));
  sockaddr_in a = Address(ip, kPort + 1);
  ASSERT_EQ(connect(c, reinterpret_cast<sockaddr*>(&a), sizeof(a)), 0) << std::strerror(errno);
  const double down = ReceiveRate(c, 1.5, 4.5);
  close(c);
  source.Result();
  absl::StatusOr<nlohmann::json> stats = link->Stop();
  ASSERT_TRUE(stats.ok()) << stats.status();
  std::printf(
      "TCP goodput (cubic, set per socket): up %.2f Mbit/s of 4, down %.2f of 8\n"
      "stats: %s\n",
      up / 1e6, down / 1e6, stats->dump().c_str());
  EXPECT_GT(up, 0.75 * 4e6);
  EXPECT_LT(up, 1.01 * 4e6);
  EXPECT_GT(down, 0.75 * 8e6);
  EXPECT_LT(down, 1.01 * 8e6);
}

// Downloads from the server namespace for `seconds` (its end sends as fast as TCP lets it; CUBIC
// on both sockets) and returns the goodput in each window, in seconds since `origin`.
std::vector<double> DownloadRates(EmulatedLink& link, Clock::time_point origin, double seconds,
                                  const std::vector<std::pair<double, double>>& windows) {
  const std::string ip = link.server_ip();
  NamespaceChild source(
      link.server_netns(),
      [&](int ready) {
        const int s = socket(AF_INET, SOCK_STREAM, 0);
        const int one = 1;
        setsockopt(s, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
        sockaddr_in a = Address(ip, kPort + 3);
        if (!UseCubic(s) || bind(s, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0 ||
            listen(s, 1) != 0) {
          return -1.0;
        }
        SignalReady(ready);
        const int c = accept(s, nullptr, nullptr);
        SendFor(c, seconds);
        close(c);
        return 0.0;
      },
      seconds + 10);
  std::vector<double> bytes(windows.size(), 0.0);
  if (!source.WaitReady()) return bytes;
  const int c = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a = Address(ip, kPort + 3);
  if (!UseCubic(c) || connect(c, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0) return bytes;
  std::vector<char> buffer(1 << 16);
  for (;;) {
    const ssize_t n = recv(c, buffer.data(), buffer.size(), 0);
    if (n <= 0) break;
    const double t = Seconds(origin);
    for (std::size_t i = 0; i < windows.size(); ++i) {
      if (t >= windows[i].first && t <= windows[i].second) bytes[i] += static_cast<double>(n);
    }
  }
  close(c);
  source.Result();
  for (std::size_t i = 0; i < windows.size(); ++i) {
    bytes[i] = bytes[i] * 8 / (windows[i].second - windows[i].first);
  }
  return bytes;
}

// A rate schedule: 8 Mbit/s, then 2 from 4 s after the ready line; TCP's goodput follows, and
// never exceeds the rate in force.
TEST_F(LinkemuSelfTest, TcpFollowsARateStep) {
  auto link =
      Start({"--down-schedule", "0s=8mbit,4s=2mbit", "--delay", "10ms", "--down-queue", "60kB"});
  ASSERT_NE(link, nullptr);
  const std::vector<double> rates =
      DownloadRates(*link, Clock::now(), 7.5, {{1.5, 3.8}, {5.0, 7.3}});
  std::printf("rate step 8 -> 2 Mbit/s at 4 s: goodput %.2f then %.2f Mbit/s\n", rates[0] / 1e6,
              rates[1] / 1e6);
  EXPECT_GT(rates[0], 0.75 * 8e6);
  EXPECT_LT(rates[0], 1.01 * 8e6);
  EXPECT_GT(rates[1], 0.5 * 2e6);  // CUBIC halves its window at the step's queue drops
  EXPECT_LT(rates[1], 1.05 * 2e6);
}

// A Mahimahi trace: one 1504-byte delivery opportunity every 2 ms (6.0 Mbit/s), repeating.
TEST_F(LinkemuSelfTest, TcpFollowsAMahimahiTrace) {
  const std::string trace = ::testing::TempDir() + "/linkemu_trace_" + std::to_string(getpid());
  {
    FILE* f = std::fopen(trace.c_str(), "w");
    ASSERT_NE(f, nullptr);
    for (int ms = 2; ms <= 100; ms += 2) std::fprintf(f, "%d\n", ms);
    std::fclose(f);
  }
  auto link = Start({"--down-trace", trace, "--delay", "10ms"});
  std::remove(trace.c_str());
  ASSERT_NE(link, nullptr);
  const double mean = link->ready()["down"]["trace"]["mean_rate_bps"].get<double>();
  EXPECT_NEAR(mean, 1504 * 8 / 0.002, 1);
  const std::vector<double> rates = DownloadRates(*link, Clock::now(), 5, {{1.5, 4.5}});
  std::printf("Mahimahi trace of %.2f Mbit/s: goodput %.2f Mbit/s\n", mean / 1e6, rates[0] / 1e6);
  EXPECT_GT(rates[0], 0.75 * mean);
  EXPECT_LT(rates[0], 1.01 * mean);
}

struct Probes {
  std::vector<double> rtt_ms;  // -1: no echo
  bool in_order = true;
  double LossRate() const {
    return static_cast<double>(std::count(rtt_ms.begin(), rtt_ms.end(), -1.0)) /
           static_cast<double>(rtt_ms.size());
  }
  std::vector<double> Answered() const {
    std::vector<double> out;
    for (double r : rtt_ms) {
      if (r >= 0) out.push_back(r);
    }
    std::sort(out.begin(), out.end());
    return out;
  }
  double MeanBurst() const {
    int lost = 0, bursts = 0;
    bool previous = false;
    for (double r : rtt_ms) {
      const bool now = r < 0;
      lost += now;
      bursts += now && !previous;
      previous = now;
    }
    return bursts == 0 ? 0 : static_cast<double>(lost) / bursts;
  }
};

double Percentile(const std::vector<double>& sorted, double p) {
  if (sorted.empty()) return -1;
  return sorted[static_cast<std::size_t>(p * static_cast<double>(sorted.size() - 1))];
}

// A UDP echo in the server namespace and `count` probes `gap_ms` apart from here; each probe's
// round trip, or -1 when no echo came within `linger_s` after the last.
Probes Echo(EmulatedLink& link, int count, double gap_ms, double linger_s = 1.5) {
  const std::string ip = link.server_ip();
  NamespaceChild echo(
      link.server_netns(),
      [&](int ready) {
        const int s = socket(AF_INET, SOCK_DGRAM, 0);
        sockaddr_in a = Address(ip, kPort + 2);
        if (bind(s, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0) return -1.0;
        SignalReady(ready);
        char buffer[2048];
        for (;;) {
          sockaddr_in from{};
          socklen_t len = sizeof(from);
          const ssize_t n =
              recvfrom(s, buffer, sizeof(buffer), 0, reinterpret_cast<sockaddr*>(&from), &len);
          if (n <= 0) break;
          if (n == 1) return 0.0;  // the end
          sendto(s, buffer, static_cast<std::size_t>(n), 0, reinterpret_cast<sockaddr*>(&from),
                 len);
        }
        return 0.0;
      },
      count * gap_ms / 1000 + linger_s + 10);
  Probes probes;
  probes.rtt_ms.assign(static_cast<std::size_t>(count), -1.0);
  if (!echo.WaitReady()) return probes;
  const int s = socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in a = Address(ip, kPort + 2);
  connect(s, reinterpret_cast<sockaddr*>(&a), sizeof(a));
  const auto start = Clock::now();
  std::vector<Clock::time_point> sent(static_cast<std::size_t>(count));
  int next = 0, last_seen = -1;
  auto receive = [&](int timeout_ms) {
    pollfd p{s, POLLIN, 0};
    while (poll(&p, 1, timeout_ms) > 0) {
      struct {
        std::int32_t seq;
        char pad[196];
      } message{};
      if (recv(s, &message, sizeof(message), 0) <= 0) break;
      const int seq = message.seq;
      if (seq < 0 || seq >= count) continue;
      if (seq < last_seen) probes.in_order = false;
      last_seen = std::max(last_seen, seq);
      probes.rtt_ms[static_cast<std::size_t>(seq)] =
          std::chrono::duration<double, std::milli>(Clock::now() -
                                                    sent[static_cast<std::size_t>(seq)])
              .count();
      timeout_ms = 0;
    }
  };
  while (next < count) {
    const auto due = start + std::chrono::microseconds(static_cast<long>(next * gap_ms * 1000));
    if (Clock::now() >= due) {
      struct {
        std::int32_t seq;
        char pad[196];
      } message{};
      message.seq = next;
      sent[static_cast<std::size_t>(next)] = Clock::now();
      send(s, &message, sizeof(message), 0);
      ++next;
    }
    receive(std::max<int>(
        0, static_cast<int>(
               std::chrono::duration_cast<std::chrono::milliseconds>(due - Clock::now()).count())));
  }
  const auto linger_until = Clock::now() + std::chrono::duration<double>(linger_s);
  while (Clock::now() < linger_until) receive(50);
  const char end = 'e';
  for (int i = 0; i < 20; ++i) send(s, &end, 1, 0);  // the link may lose some
  close(s);
  echo.Result();
  return probes;
}

// 30 ms up and 10 ms down: no echo comes back before 40 ms (the emulator never releases early),
// nor much after it on an idle link.
TEST_F(LinkemuSelfTest, ProbesSeeTheConfiguredDelayAndNoLoss) {
  auto link = Start({"--rate", "20mbit", "--up-delay", "30ms", "--down-delay", "10ms"});
  ASSERT_NE(link, nullptr);
  const Probes probes = Echo(*link, 200, 10);
  const std::vector<double> rtt = probes.Answered();
  std::printf("delay 30 + 10 ms: round trips min %.2f, p50 %.2f, p90 %.2f ms; %zu of 200 back\n",
              Percentile(rtt, 0), Percentile(rtt, 0.5), Percentile(rtt, 0.9), rtt.size());
  EXPECT_EQ(probes.LossRate(), 0.0);
  EXPECT_TRUE(probes.in_order);
  EXPECT_GE(Percentile(rtt, 0), 40.0);
  EXPECT_LE(Percentile(rtt, 0.5), 40.0 + 25.0);
}

// Jitter of 8 ms each way spreads the round trips (two normals: a standard deviation of 11 ms)
// around 40 ms, without reordering a single probe.
TEST_F(LinkemuSelfTest, JitterSpreadsTheDelayWithoutReordering) {
  auto link = Start({"--delay", "20ms", "--jitter", "8ms"});
  ASSERT_NE(link, nullptr);
  const Probes probes = Echo(*link, 300, 5);
  const std::vector<double> rtt = probes.Answered();
  const double spread = Percentile(rtt, 0.9) - Percentile(rtt, 0.1);
  std::printf("delay 20 ms, jitter 8 ms each way: round trips p10 %.2f, p50 %.2f, p90 %.2f ms\n",
              Percentile(rtt, 0.1), Percentile(rtt, 0.5), Percentile(rtt, 0.9));
  EXPECT_EQ(probes.LossRate(), 0.0);
  EXPECT_TRUE(probes.in_order);
  EXPECT_GT(spread, 10.0);
  EXPECT_GT(Percentile(rtt, 0.5), 30.0);
  EXPECT_LT(Percentile(rtt, 0.5), 40.0 + 30.0);
}

// 10 % random loss on the uplink loses about one probe in ten, one at a time; the emulator's
// counts add up.
TEST_F(LinkemuSelfTest, RandomLossLosesTheConfiguredShare) {
  auto link = Start({"--up-loss", "10%", "--delay", "2ms", "--seed", "11"});
  ASSERT_NE(link, nullptr);
  const Probes probes = Echo(*link, 2000, 1);
  absl::StatusOr<nlohmann::json> stats = link->Stop();
  ASSERT_TRUE(stats.ok()) << stats.status();
  std::printf("10%% loss up: %.2f%% of probes lost, mean burst %.2f; stats %s\n",
              100 * probes.LossRate(), probes.MeanBurst(), stats->dump().c_str());
  EXPECT_GT(probes.LossRate(), 0.07);
  EXPECT_LT(probes.LossRate(), 0.13);
  EXPECT_LT(probes.MeanBurst(), 1.6);
  const nlohmann::json& up = (*stats)["up"];
  EXPECT_EQ(up["packets"].get<int>(),
            up["delivered"].get<int>() + up["lost"].get<int>() + up["queue_drops"].get<int>());
  EXPECT_EQ((*stats)["down"]["lost"].get<int>(), 0);
}

// Gilbert-Elliott p=2 %, r=20 %: 9.1 % lost in bursts of 5 on average.
TEST_F(LinkemuSelfTest, BurstLossLosesInBursts) {
  auto link = Start({"--up-burst-loss", "p=2%,r=20%", "--delay", "2ms", "--seed", "5"});
  ASSERT_NE(link, nullptr);
  const Probes probes = Echo(*link, 3000, 1);
  std::printf(
      "burst loss p=2%% r=20%%: %.2f%% of probes lost, mean burst %.2f (expected 9.1%%, "
      "5)\n",
      100 * probes.LossRate(), probes.MeanBurst());
  EXPECT_GT(probes.LossRate(), 0.04);
  EXPECT_LT(probes.LossRate(), 0.16);
  EXPECT_GT(probes.MeanBurst(), 2.5);
}

// A 400 ms outage 1.5 s in: probes sent into it wait in the queue (none lost) and come back after
// it; probes sent long after it see the plain delay again.
TEST_F(LinkemuSelfTest, AnOutageHoldsPacketsThenTheLinkRecovers) {
  auto link = Start({"--rate", "10mbit", "--delay", "5ms", "--outage", "1500ms:400ms"});
  ASSERT_NE(link, nullptr);
  const Probes probes = Echo(*link, 300, 10);  // 3 s
  const std::vector<double> rtt = probes.Answered();
  std::vector<double> tail(probes.rtt_ms.end() - 50, probes.rtt_ms.end());
  std::sort(tail.begin(), tail.end());
  std::printf(
      "outage 400 ms: worst round trip %.1f ms, median of the last 50 %.1f ms, lost %.1f%%\n",
      rtt.empty() ? -1 : rtt.back(), Percentile(tail, 0.5), 100 * probes.LossRate());
  EXPECT_EQ(probes.LossRate(), 0.0);
  EXPECT_TRUE(probes.in_order);
  ASSERT_FALSE(rtt.empty());
  EXPECT_GT(rtt.back(), 300.0);
  EXPECT_LT(rtt.back(), 400.0 + 200.0);
  EXPECT_LT(Percentile(tail, 0.5), 10.0 + 30.0);
}

// A bad flag: the emulator names it on stderr and exits before making anything; Start says it
// gave no ready line instead of hanging.
TEST_F(LinkemuSelfTest, ABadFlagEndsTheStartClearly) {
  EmulatedLink::Options options;
  options.binary = std::string(CLOUDCAST_BIN_DIR) + "/cloudcast-linkemu";
  options.flags = {"--up-delay", "20"};
  absl::StatusOr<std::unique_ptr<EmulatedLink>> link = EmulatedLink::Start(options);
  ASSERT_FALSE(link.ok());
  EXPECT_NE(std::string(link.status().message()).find("no ready line"), std::string::npos)
      << link.status();
}

// Two emulators at once get their own namespaces and addresses and both carry traffic (the
// second with its clients in a namespace too, both ends set to reno); when they stop, nothing of
// theirs is left in the host's namespace or in /run/netns.
TEST_F(LinkemuSelfTest, TwoAtOnceDoNotCollideAndLeaveNothingBehind) {
  auto first = Start({"--delay", "1ms"});
  auto second = Start({"--delay", "1ms", "--client-netns", "--cc", "reno"});
  ASSERT_NE(first, nullptr);
  ASSERT_NE(second, nullptr);
  EXPECT_NE(first->server_netns(), second->server_netns());
  EXPECT_NE(first->server_ip(), second->server_ip());
  EXPECT_FALSE(second->client_netns().empty());
  EXPECT_EQ(second->ready()["congestion_control"]["server"], "reno");
  EXPECT_EQ(second->ready()["congestion_control"]["client"], "reno");
  EXPECT_EQ(Echo(*first, 20, 5, 0.5).LossRate(), 0.0);
  const std::string names[] = {first->server_netns(), second->server_netns(),
                               second->client_netns()};
  const std::string tag = first->server_netns().substr(0, first->server_netns().size() - 1);
  ASSERT_TRUE(first->Stop().ok());
  ASSERT_TRUE(second->Stop().ok());
  for (const std::string& name : names) {
    EXPECT_FALSE(std::filesystem::exists("/run/netns/" + name)) << name;
  }
  EXPECT_NE(std::system(("ip link show " + tag + "c0 >/dev/null 2>&1").c_str()), 0)
      << "the host end of the client veth pair is still there";
}

}  // namespace
}  // namespace cloudcast::linkemu
