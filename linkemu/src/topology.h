// The emulator's network: a router namespace of its own (the emulator's process moves into it, so
// it and everything in it vanish when the process ends, however it ends), a named server
// namespace behind one veth pair, and the clients' side behind another: the host's own namespace
// (so tests can connect from their own process) or a named client namespace. The router forwards
// between the two and hands every packet to the emulator through NFQUEUE. Nothing of the host is
// touched but the host end of the client veth pair and its route to the server's /30, both gone
// with the pair.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace cloudcast::linkemu {

struct TopologyOptions {
  bool client_namespace = false;   // clients in a namespace of their own, not the host's
  std::string congestion_control;  // set in the namespaces made here; "" leaves the default
  std::uint16_t first_queue = 0;   // NFQUEUE numbers: uplink, uplink + 1 downlink
  int mtu = 1500;
};

struct TopologyInfo {
  std::string tag;           // ccl<pid>: every name made here starts with it
  std::string server_netns;  // run the server with `ip netns exec <server_netns> ...`
  std::string client_netns;  // "" = the host's namespace
  std::string server_ip, client_ip;
  std::string server_congestion_control, client_congestion_control;
};

class Topology {
 public:
  // Makes the namespaces and links, and moves the calling (single-threaded) process into the
  // router namespace, where the NFQUEUE rules are. Removes namespaces left by emulators that
  // died without cleaning up (their pid is gone).
  static absl::StatusOr<std::unique_ptr<Topology>> Create(const TopologyOptions& options);
  // Removes the named namespaces; the router namespace and both veth pairs go when the process
  // exits.
  ~Topology();
  const TopologyInfo& info() const { return info_; }

 private:
  Topology() = default;
  TopologyInfo info_;
  std::vector<std::string> named_;  // namespaces to delete
  std::vector<std::string> links_;  // the router's ends of the veth pairs
  int host_netns_fd_ = -1;
};

// Runs argv (no shell) in the network namespace `netns_fd` (-1: this process's own); the output
// is returned in the error.
absl::Status RunIn(int netns_fd, const std::vector<std::string>& argv);

}  // namespace cloudcast::linkemu
