// For tests and benchmarks in C++: starts cloudcast-linkemu as a child process, waits for its
// ready line (the server namespace and addresses), and stops it (SIGTERM, then the stats line).
// The child gets SIGTERM if the thread that started it dies, and exits by itself after its
// --timeout, so a crashed test leaves nothing behind for long.
#pragma once

#include <sys/types.h>

#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "nlohmann/json.hpp"

namespace cloudcast::linkemu {

class EmulatedLink {
 public:
  struct Options {
    std::string binary;              // the cloudcast-linkemu program
    std::vector<std::string> flags;  // link flags, e.g. {"--rate", "10mbit", "--delay", "20ms"}
    double timeout_s = 120;          // the emulator's own bound (--timeout)
    double ready_within_s = 30;      // how long to wait for the ready line
  };
  static absl::StatusOr<std::unique_ptr<EmulatedLink>> Start(const Options& options);
  ~EmulatedLink();
  EmulatedLink(const EmulatedLink&) = delete;
  EmulatedLink& operator=(const EmulatedLink&) = delete;

  const nlohmann::json& ready() const { return ready_; }
  std::string server_ip() const { return ready_.value("server_ip", ""); }
  std::string server_netns() const { return ready_.value("server_netns", ""); }
  std::string client_netns() const { return ready_.value("client_netns", ""); }
  // Runs a command inside the server's namespace: prefix its argv with these.
  std::vector<std::string> ServerPrefix() const {
    return {"/usr/sbin/ip", "netns", "exec", server_netns()};
  }
  // Ends the emulator (it removes its namespaces) and returns its stats line.
  absl::StatusOr<nlohmann::json> Stop();

 private:
  EmulatedLink() = default;
  absl::StatusOr<std::string> ReadLine(double within_s);

  pid_t pid_ = -1;
  int out_fd_ = -1;
  std::string buffered_;
  nlohmann::json ready_;
};

}  // namespace cloudcast::linkemu
