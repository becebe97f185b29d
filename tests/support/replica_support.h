// Replicas for the scale-out tests: real cloudcast-server processes on loopback addresses
// (127.0.0.1, 127.0.0.2, ... are all loopback), which a test can kill or drain with a signal.
#pragma once

#include <arpa/inet.h>
#include <fcntl.h>
#include <grpcpp/grpcpp.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <functional>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "support/program_support.h"

namespace cloudcast::testing {

// A port that is free on 127.0.0.1 now (the kernel's pick); the replicas then bind it on their
// own addresses.
inline int FreeLoopbackPort() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = 0;
  socklen_t len = sizeof addr;
  int port = 0;
  if (fd >= 0 && bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0 &&
      getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) == 0) {
    port = ntohs(addr.sin_port);
  }
  if (fd >= 0) close(fd);
  return port;
}

// One cloudcast-server process. Its output goes to `log_path`. Metrics are off unless
// `metrics_listen` names an address. `prefix` runs it through another program that execs it in
// place (e.g. `ip netns exec NS`), so the pid is still the server's. Give port 0 in `address`
// or `metrics_listen`: the server then writes what it bound to its --ready-file, and address() and
// metrics_port() say it once WaitUntilBound() or WaitUntilServing() has returned true. (Fixed
// ports pass no --ready-file, so that a build from before the flag can be run too.)
class ServerProcess {
 public:
  ServerProcess(const std::string& address, const std::string& instance,
                const std::vector<std::string>& extra_args, const std::string& log_path,
                const std::string& log_level = "warn", const std::string& metrics_listen = "",
                const std::vector<std::string>& prefix = {})
      : address_(address), metrics_address_(metrics_listen), instance_(instance),
        log_path_(log_path),
        ready_path_(EndsWith(address, ":0") || EndsWith(metrics_listen, ":0")
                        ? UniqueReadyPath(log_path)
                        : "") {
    std::vector<std::string> args = prefix;
    for (const std::string& a :
         {BinDir() + "/cloudcast-server", std::string("--listen"), address,
          std::string("--metrics-listen"), metrics_listen, std::string("--instance"), instance,
          std::string("--log-level"), log_level,
          // The paper's camera and range as the defaults, stated: the tests stream its frames
          // (or the synthetic scene's, the same camera) without a camera of their own.
          std::string("--camera-preset"), std::string("new_tsukuba")}) {
      args.push_back(a);
    }
    if (!ready_path_.empty()) {
      std::remove(ready_path_.c_str());  // an earlier run's
      args.insert(args.end(), {"--ready-file", ready_path_});
    }
    args.insert(args.end(), extra_args.begin(), extra_args.end());
    pid_ = fork();
    if (pid_ == 0) {
      const int out = open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      dup2(out, 1);
      dup2(out, 2);
      std::vector<char*> argv;
      for (std::string& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      execv(argv[0], argv.data());
      _exit(127);
    }
  }
  ~ServerProcess() {
    if (running()) Signal(SIGKILL);
    Wait();
    if (!ready_path_.empty()) std::remove(ready_path_.c_str());
  }
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  // The --ready-file: this test process's and this server's own, whatever the log is called.
  // Named after the log alone, two tests of one binary that ctest ran at once (faults_test's
  // KILL and TERM) read each other's ports, and a robot reconnected to the wrong server.
  static std::string UniqueReadyPath(const std::string& log_path) {
    static std::atomic<int> next{0};
    return log_path + "." + std::to_string(getpid()) + "-" + std::to_string(next++) + ".ready";
  }

  // Waits until the server has bound its ports (its --ready-file), and takes the addresses it
  // bound from there; false when the process ended first or the deadline passed. A server with
  // TLS is ready to be connected to then: WaitUntilServing's plaintext probe would not be.
  bool WaitUntilBound(std::chrono::seconds timeout = std::chrono::seconds(20)) {
    if (ready_path_.empty()) return !Ended();  // fixed ports: nothing to learn
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      const std::string ready = ReadText(ready_path_);
      if (!ready.empty()) {
        address_ = ReadyValue(ready, "grpc");
        metrics_address_ = ReadyValue(ready, "metrics");
        return !address_.empty();
      }
      if (Ended()) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return false;
  }
  // Waits until the server answers on its address (gRPC channel READY), or the deadline.
  bool WaitUntilServing(std::chrono::seconds timeout = std::chrono::seconds(20)) {
    if (!WaitUntilBound(timeout)) return false;
    auto channel = grpc::CreateChannel(address_, grpc::InsecureChannelCredentials());
    return channel->WaitForConnected(std::chrono::system_clock::now() + timeout);
  }

  void Signal(int signal_number) {
    if (pid_ > 0) kill(pid_, signal_number);
  }
  // Waits for the process to end; its exit status, or nullopt when a signal ended it.
  std::optional<int> Wait() {
    if (pid_ <= 0) return exit_status_;
    int status = 0;
    if (waitpid(pid_, &status, 0) == pid_) {
      exit_status_ = WIFEXITED(status) ? std::optional<int>(WEXITSTATUS(status)) : std::nullopt;
    }
    pid_ = -1;
    return exit_status_;
  }
  bool running() const { return pid_ > 0; }
  pid_t pid() const { return pid_; }

  // The address it was asked for, or once bound (WaitUntilBound), the one it bound.
  const std::string& address() const { return address_; }
  // The port of its /metrics once bound; 0 when metrics are off.
  int metrics_port() const {
    const std::size_t colon = metrics_address_.rfind(':');
    return colon == std::string::npos ? 0 : std::stoi(metrics_address_.substr(colon + 1));
  }
  const std::string& instance() const { return instance_; }
  std::string log() const { return ReadText(log_path_); }

 private:
  static bool EndsWith(const std::string& s, const std::string& tail) {
    return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
  }
  // `key=value` from the lines of a --ready-file; "" when absent.
  static std::string ReadyValue(const std::string& text, const std::string& key) {
    std::istringstream lines(text);
    for (std::string line; std::getline(lines, line);) {
      if (line.rfind(key + "=", 0) == 0) return line.substr(key.size() + 1);
    }
    return "";
  }
  // Whether the process has ended (reaped here, its status kept for Wait).
  bool Ended() {
    if (pid_ <= 0) return true;
    int status = 0;
    if (waitpid(pid_, &status, WNOHANG) != pid_) return false;
    exit_status_ = WIFEXITED(status) ? std::optional<int>(WEXITSTATUS(status)) : std::nullopt;
    pid_ = -1;
    return true;
  }

  std::string address_;
  std::string metrics_address_;
  const std::string instance_;
  const std::string log_path_;
  const std::string ready_path_;
  pid_t pid_ = -1;
  std::optional<int> exit_status_;
};

// `n` cloudcast-server processes on 127.0.0.1, .2, ... sharing one free port (another port when
// it was taken meanwhile), each serving; instance names replica-1, replica-2, ... and logs from
// `log_path(i)`. Empty when they could not be started.
inline std::vector<std::unique_ptr<ServerProcess>> StartReplicaSet(
    int n, const std::vector<std::string>& args,
    const std::function<std::string(const std::string& id)>& log_path) {
  std::vector<std::unique_ptr<ServerProcess>> replicas;
  for (int attempt = 0; attempt < 5 && replicas.size() < static_cast<std::size_t>(n); ++attempt) {
    replicas.clear();
    const int port = FreeLoopbackPort();
    for (int i = 0; i < n; ++i) {
      const std::string id = std::to_string(i + 1);
      replicas.push_back(std::make_unique<ServerProcess>(
          "127.0.0." + id + ":" + std::to_string(port), "replica-" + id, args, log_path(id)));
    }
    for (auto& r : replicas) {
      if (!r->WaitUntilServing()) {
        replicas.clear();  // the port was taken meanwhile: another one
        break;
      }
    }
  }
  return replicas;
}

// The gRPC target that lists every replica: "ipv4:127.0.0.1:p,127.0.0.2:p,...".
inline std::string ReplicaTarget(const std::vector<std::unique_ptr<ServerProcess>>& replicas) {
  std::string t = "ipv4:";
  for (std::size_t i = 0; i < replicas.size(); ++i) {
    t += (i ? "," : "") + replicas[i]->address();
  }
  return t;
}

}  // namespace cloudcast::testing
