// The packet path: the kernel hands every forwarded packet of the router namespace to this
// process through two NFQUEUE queues (one per direction); LinkDirection decides each packet's
// fate and time, and the relay gives the kernel its verdict (accept or drop) at that time. The
// packets stay in the kernel meanwhile; only their headers and length cross to userspace.
#pragma once

#include <atomic>
#include <cstdint>
#include <deque>
#include <memory>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/linkemu/clock.h"
#include "cloudcast/linkemu/direction.h"

struct nfq_handle;
struct nfq_q_handle;
struct nfgenmsg;
struct nfq_data;

namespace cloudcast::linkemu {

class NfqueueRelay {
 public:
  // Binds queue `first_queue` (uplink) and `first_queue + 1` (downlink) in the calling thread's
  // network namespace.
  static absl::StatusOr<std::unique_ptr<NfqueueRelay>> Open(LinkDirection* up, LinkDirection* down,
                                                            std::uint16_t first_queue);
  ~NfqueueRelay();
  NfqueueRelay(const NfqueueRelay&) = delete;
  NfqueueRelay& operator=(const NfqueueRelay&) = delete;

  // Relays until `stop` is set or the link's clock reaches `until` (link time: ns since Run
  // began, the time the schedules count from).
  absl::Status Run(const std::atomic<bool>& stop, Nanos until);
  // Netlink messages the kernel could not hand over (socket buffer full): those packets dropped.
  std::int64_t overruns() const { return overruns_; }
  // Packets the kernel handed over and the relay has not yet released or dropped.
  std::int64_t held() const {
    return static_cast<std::int64_t>(up_.held.size() + down_.held.size());
  }

 private:
  struct Held {
    std::uint32_t id;
    Nanos release_at;
    bool accept;
  };
  struct Side {
    NfqueueRelay* relay = nullptr;
    LinkDirection* model = nullptr;
    nfq_q_handle* queue = nullptr;
    std::deque<Held> held;  // release times never decrease (LinkDirection keeps FIFO order)
  };
  static int OnPacket(nfq_q_handle* queue, ::nfgenmsg* message, ::nfq_data* data, void* side);
  NfqueueRelay() = default;
  Nanos Now() const;
  void ReleaseDue(Side* side, Nanos now);

  nfq_handle* handle_ = nullptr;
  Side up_, down_;
  std::int64_t t0_ = 0;  // CLOCK_MONOTONIC at Run's start, ns
  std::int64_t overruns_ = 0;
};

}  // namespace cloudcast::linkemu
