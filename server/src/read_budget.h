// The bytes of request messages each client may have arriving at once (issue 30, defect 4).
//
// gRPC holds a message until its last byte has arrived, and once a call has a read in progress it
// opens the call's flow-control window as wide as the message announces (up to
// --max-message-bytes; the limit is checked only when the message is whole). A client that sends
// every message but its last byte therefore holds a whole message of server memory per call, for
// as long as it keeps the connection: 96 Process calls of 59 MB held 3.7 GB. So a Process call
// starts its read only once it has reserved a whole message's worth of its client's share here;
// the calls that wait hold only the transport's per-stream window, and a client that will not
// finish its messages only delays its own calls.
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <unordered_map>
#include <vector>

namespace cloudcast::server {

class ReadBudget {
 public:
  // Runs when a queued reservation is granted, on the thread whose Release made room.
  using Grant = std::function<void()>;
  static constexpr std::uint64_t kGranted = 0;

  // `per_client_bytes`: each client's share. A read larger than the share is still granted when
  // its client has nothing else reserved, so that every client can always read one message.
  explicit ReadBudget(std::uint64_t per_client_bytes) : per_client_bytes_(per_client_bytes) {}

  // Reserves `bytes` of `client`'s share. kGranted when they fit now (`grant` is not called);
  // otherwise the reservation waits behind the client's earlier ones and this returns its id,
  // for Cancel, and `grant` runs once it is granted.
  std::uint64_t Reserve(std::uint64_t client, std::uint64_t bytes, Grant grant);
  // Gives back a granted reservation, and grants the client's waiting ones that now fit.
  void Release(std::uint64_t client, std::uint64_t bytes);
  // Withdraws a waiting reservation; false when it was granted meanwhile (its grant runs, or ran).
  bool Cancel(std::uint64_t client, std::uint64_t id);

  std::uint64_t reserved(std::uint64_t client) const;
  std::uint64_t waiting(std::uint64_t client) const;
  std::uint64_t per_client_bytes() const { return per_client_bytes_; }

 private:
  struct Waiter {
    std::uint64_t id;
    std::uint64_t bytes;
    Grant grant;
  };
  struct Share {
    std::uint64_t reserved = 0;
    std::deque<Waiter> waiting;  // in the order they came
  };
  // Under mu_: grants the share's waiting reservations that fit, in order; their grants, to run
  // once mu_ is released.
  std::vector<Grant> GrantWhatFits(Share* share);
  bool Fits(const Share& share, std::uint64_t bytes) const {
    return share.reserved == 0 || share.reserved + bytes <= per_client_bytes_;
  }

  const std::uint64_t per_client_bytes_;
  mutable std::mutex mu_;
  std::unordered_map<std::uint64_t, Share> shares_;  // clients with something reserved or waiting
  std::uint64_t next_id_ = 1;
};

}  // namespace cloudcast::server
