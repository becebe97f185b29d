#include "topology.h"

#include <dirent.h>
#include <fcntl.h>
#include <sched.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/strip.h"

namespace cloudcast::linkemu {
namespace {

constexpr char kPrefix[] = "ccl";
constexpr char kLockFile[] = "/run/lock/cloudcast-linkemu.lock";

absl::StatusOr<std::string> Capture(int netns_fd, const std::vector<std::string>& argv, bool* ok) {
  int pipe_fds[2];
  if (pipe2(pipe_fds, O_CLOEXEC) != 0) return absl::InternalError("pipe failed");
  const pid_t pid = fork();
  if (pid < 0) return absl::InternalError(absl::StrCat("fork: ", std::strerror(errno)));
  if (pid == 0) {
    dup2(pipe_fds[1], 1);
    dup2(pipe_fds[1], 2);
    if (netns_fd >= 0 && setns(netns_fd, CLONE_NEWNET) != 0) _exit(126);
    std::vector<char*> args;
    for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    execvp(args[0], args.data());
    _exit(127);
  }
  close(pipe_fds[1]);
  std::string output;
  char buffer[4096];
  for (;;) {
    const ssize_t n = read(pipe_fds[0], buffer, sizeof(buffer));
    if (n > 0) {
      output.append(buffer, static_cast<std::size_t>(n));
    } else if (n == 0 || errno != EINTR) {
      break;
    }
  }
  close(pipe_fds[0]);
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  *ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
  return output;
}

std::string ReadCongestionControl(int netns_fd) {
  bool ok = false;
  absl::StatusOr<std::string> out =
      Capture(netns_fd, {"sysctl", "-n", "net.ipv4.tcp_congestion_control"}, &ok);
  if (!out.ok() || !ok) return "unknown";
  return std::string(absl::StripAsciiWhitespace(*out));
}

int OpenNetns(const std::string& path) { return open(path.c_str(), O_RDONLY | O_CLOEXEC); }

bool ProcessAlive(long pid) { return kill(static_cast<pid_t>(pid), 0) == 0 || errno == EPERM; }

// Namespaces named ccl<pid>c / ccl<pid>s whose emulator is gone (it was killed).
void RemoveStaleNamespaces() {
  DIR* dir = opendir("/run/netns");
  if (dir == nullptr) return;
  std::vector<std::string> stale;
  while (dirent* entry = readdir(dir)) {
    const std::string name = entry->d_name;
    if (name.rfind(kPrefix, 0) != 0 || name.size() < 5) continue;
    const char kind = name.back();
    const std::string digits = name.substr(3, name.size() - 4);
    if ((kind != 'c' && kind != 's') || digits.empty() ||
        digits.find_first_not_of("0123456789") != std::string::npos) {
      continue;
    }
    if (!ProcessAlive(std::stol(digits))) stale.push_back(name);
  }
  closedir(dir);
  for (const std::string& name : stale) (void)RunIn(-1, {"ip", "netns", "del", name});
}

// A /29 in 10.215.0.0/16 that no route of the host's namespace uses yet: the client leg's /30 and
// the server leg's /30.
absl::StatusOr<int> FreeSlot(int host_fd, long pid) {
  bool ok = false;
  absl::StatusOr<std::string> routes = Capture(host_fd, {"ip", "-4", "route", "show"}, &ok);
  if (!routes.ok() || !ok) return absl::InternalError("cannot list the host's routes");
  constexpr int kSlots = 8192;
  for (int i = 0; i < kSlots; ++i) {
    const int slot = static_cast<int>((pid + i) % kSlots);
    const std::string base = absl::StrCat("10.215.", slot / 32, ".", (slot % 32) * 8);
    const std::string server = absl::StrCat("10.215.", slot / 32, ".", (slot % 32) * 8 + 4);
    if (routes->find(base + "/30") == std::string::npos &&
        routes->find(server + "/30") == std::string::npos) {
      return slot;
    }
  }
  return absl::ResourceExhaustedError("no free 10.215.x.y/29 for the emulator's links");
}

}  // namespace

absl::Status RunIn(int netns_fd, const std::vector<std::string>& argv) {
  bool ok = false;
  absl::StatusOr<std::string> output = Capture(netns_fd, argv, &ok);
  if (!output.ok()) return output.status();
  if (!ok) {
    return absl::InternalError(absl::StrCat("'", absl::StrJoin(argv, " "),
                                            "' failed: ", absl::StripAsciiWhitespace(*output)));
  }
  return absl::OkStatus();
}

absl::StatusOr<std::unique_ptr<Topology>> Topology::Create(const TopologyOptions& options) {
  if (geteuid() != 0) {
    return absl::PermissionDeniedError("the link emulator needs root (network namespaces)");
  }
  RemoveStaleNamespaces();
  std::unique_ptr<Topology> topology(new Topology());
  const long pid = getpid();
  TopologyInfo& info = topology->info_;
  info.tag = absl::StrCat(kPrefix, pid);
  info.server_netns = info.tag + "s";
  if (options.client_namespace) info.client_netns = info.tag + "c";

  topology->host_netns_fd_ = OpenNetns("/proc/self/ns/net");
  const int host_fd = topology->host_netns_fd_;
  if (host_fd < 0) return absl::InternalError("cannot open this process's network namespace");

  // One emulator at a time picks its addresses and sets up the host's side.
  mkdir("/run/lock", 0755);
  const int lock_fd = open(kLockFile, O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (lock_fd >= 0) flock(lock_fd, LOCK_EX);
  struct Unlock {
    int fd;
    ~Unlock() {
      if (fd >= 0) close(fd);  // releases the flock
    }
  } unlock{lock_fd};

  absl::StatusOr<int> slot = FreeSlot(host_fd, pid);
  if (!slot.ok()) return slot.status();
  const std::string net = absl::StrCat("10.215.", *slot / 32, ".");
  const int base = (*slot % 32) * 8;
  info.client_ip = net + std::to_string(base + 1);
  const std::string router_client_ip = net + std::to_string(base + 2);
  const std::string router_server_ip = net + std::to_string(base + 5);
  info.server_ip = net + std::to_string(base + 6);
  const std::string server_leg = net + std::to_string(base + 4) + "/30";

  for (const std::string& name : {info.server_netns, info.client_netns}) {
    if (name.empty()) continue;
    if (absl::Status s = RunIn(-1, {"ip", "netns", "add", name}); !s.ok()) return s;
    topology->named_.push_back(name);
  }
  const int server_fd = OpenNetns("/run/netns/" + info.server_netns);
  const int client_fd =
      options.client_namespace ? OpenNetns("/run/netns/" + info.client_netns) : host_fd;
  if (server_fd < 0 || client_fd < 0) return absl::InternalError("cannot open the namespaces");

  // This process becomes the router.
  if (unshare(CLONE_NEWNET) != 0) {
    return absl::InternalError(absl::StrCat("unshare(CLONE_NEWNET): ", std::strerror(errno)));
  }
  const std::string me = std::to_string(pid);
  const std::string client_if = info.tag + "c0", router_client_if = info.tag + "rc";
  const std::string server_if = info.tag + "s0", router_server_if = info.tag + "rs";
  const std::string mtu = std::to_string(options.mtu);
  const std::vector<std::pair<int, std::vector<std::string>>> steps = {
      {client_fd,
       {"ip", "link", "add", client_if, "mtu", mtu, "type", "veth", "peer", "name",
        router_client_if, "mtu", mtu, "netns", me}},
      {server_fd,
       {"ip", "link", "add", server_if, "mtu", mtu, "type", "veth", "peer", "name",
        router_server_if, "mtu", mtu, "netns", me}},
      {client_fd, {"ip", "addr", "add", info.client_ip + "/30", "dev", client_if}},
      {client_fd, {"ip", "link", "set", client_if, "up"}},
      {client_fd, {"ip", "route", "add", server_leg, "via", router_client_ip, "dev", client_if}},
      {server_fd, {"ip", "link", "set", "lo", "up"}},
      {server_fd, {"ip", "addr", "add", info.server_ip + "/30", "dev", server_if}},
      {server_fd, {"ip", "link", "set", server_if, "up"}},
      {server_fd, {"ip", "route", "add", "default", "via", router_server_ip}},
      {-1, {"ip", "link", "set", "lo", "up"}},
      {-1, {"ip", "addr", "add", router_client_ip + "/30", "dev", router_client_if}},
      {-1, {"ip", "addr", "add", router_server_ip + "/30", "dev", router_server_if}},
      {-1, {"ip", "link", "set", router_client_if, "up"}},
      {-1, {"ip", "link", "set", router_server_if, "up"}},
      {-1, {"sysctl", "-q", "-w", "net.ipv4.ip_forward=1"}},
      {-1,
       {"iptables", "-A", "FORWARD", "-i", router_client_if, "-j", "NFQUEUE", "--queue-num",
        std::to_string(options.first_queue)}},
      {-1,
       {"iptables", "-A", "FORWARD", "-i", router_server_if, "-j", "NFQUEUE", "--queue-num",
        std::to_string(options.first_queue + 1)}},
  };
  for (const auto& [fd, argv] : steps) {
    if (absl::Status s = RunIn(fd, argv); !s.ok()) return s;
    if (argv[1] == "link" && argv[2] == "add") topology->links_.push_back(argv[10]);
  }
  if (options.client_namespace) {
    if (absl::Status s = RunIn(client_fd, {"ip", "link", "set", "lo", "up"}); !s.ok()) return s;
  }
  if (!options.congestion_control.empty()) {
    const std::string setting = "net.ipv4.tcp_congestion_control=" + options.congestion_control;
    for (int fd : {server_fd, options.client_namespace ? client_fd : -2}) {
      if (fd == -2) continue;
      if (absl::Status s = RunIn(fd, {"sysctl", "-q", "-w", setting}); !s.ok()) {
        bool ok = false;
        absl::StatusOr<std::string> allowed =
            Capture(-1, {"sysctl", "-n", "net.ipv4.tcp_allowed_congestion_control"}, &ok);
        return absl::FailedPreconditionError(absl::StrCat(
            "--cc ", options.congestion_control,
            ": the kernel lets a network namespace make only the host's allowed algorithms its "
            "default (net.ipv4.tcp_allowed_congestion_control = ",
            allowed.ok() ? absl::StripAsciiWhitespace(*allowed) : "?",
            "), and the host's setting is not changed here. Use one of those, or set it per "
            "socket: LD_PRELOAD=<bin>/libcloudcast_tcp_cc.so CLOUDCAST_TCP_CC=",
            options.congestion_control, " (docs/links.md)"));
      }
    }
  }
  info.server_congestion_control = ReadCongestionControl(server_fd);
  info.client_congestion_control = ReadCongestionControl(client_fd);
  close(server_fd);
  if (client_fd != host_fd) close(client_fd);
  return topology;
}

Topology::~Topology() {
  // Now rather than when the router namespace is torn down (the kernel does that later, in the
  // background): deleting one end of a veth pair deletes the other.
  for (const std::string& name : links_) (void)RunIn(-1, {"ip", "link", "del", name});
  for (const std::string& name : named_) (void)RunIn(-1, {"ip", "netns", "del", name});
  if (host_netns_fd_ >= 0) close(host_netns_fd_);
}

}  // namespace cloudcast::linkemu
