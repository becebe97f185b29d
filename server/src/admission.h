// Who may open a call now: the server-wide limits on streams and on Process calls in flight,
// and each client's share of them, so that one client (a robot, a misbehaving script, or an
// attacker) cannot take every slot. A client is its peer address without the port, or, with
// bearer tokens (--tokens-file), its tenant, whose own limits replace the per-client shares.
#pragma once

#include <atomic>
#include <cstdint>
#include <mutex>
#include <string>
#include <string_view>
#include <unordered_map>

#include "absl/status/statusor.h"

namespace cloudcast::server {

class Admission {
 public:
  enum class Kind { kStream, kProcess };

  struct Limits {
    std::uint32_t max_streams = 64;
    std::uint32_t max_streams_per_client = 32;
    std::uint32_t max_process = 64;
    std::uint32_t max_process_per_client = 32;
  };

  // A place held for one call; giving it back (destruction) frees it.
  class Ticket {
   public:
    Ticket() = default;
    Ticket(Ticket&& other) noexcept { *this = std::move(other); }
    Ticket& operator=(Ticket&& other) noexcept;
    ~Ticket() { Release(); }
    void Release();

   private:
    friend class Admission;
    Admission* admission_ = nullptr;
    Kind kind_ = Kind::kStream;
    std::string client_;
  };

  // Whom a call counts against, and that client's own shares.
  struct Client {
    std::string key;     // the peer host (PeerHost), or with tokens "tenant:" + the tenant
    std::string tenant;  // the tenant's name, for messages; "" without tokens
    // The tenant's own limits (--tokens-file); 0: the server's per-client share.
    std::uint32_t max_streams = 0;
    std::uint32_t max_process = 0;
  };

  explicit Admission(const Limits& limits) : limits_(limits) {}
  Admission(const Admission&) = delete;
  Admission& operator=(const Admission&) = delete;

  // Which limit a refused call hit.
  enum class Refusal { kNone, kServerFull, kClientShare };

  // A place for `client`, or RESOURCE_EXHAUSTED saying which limit (and its flag, or its key in
  // the tokens file) it hit; `refusal`, when given, gets which.
  absl::StatusOr<Ticket> Admit(Kind kind, const Client& client, Refusal* refusal = nullptr);
  absl::StatusOr<Ticket> Admit(Kind kind, const std::string& peer_host) {
    return Admit(kind, Client{peer_host, "", 0, 0});
  }

  std::uint32_t open(Kind kind) const;

 private:
  struct Counts {
    std::uint32_t streams = 0;
    std::uint32_t process = 0;
  };
  void Give(Kind kind, const std::string& client);

  const Limits limits_;
  mutable std::mutex mu_;
  Counts total_;
  std::unordered_map<std::string, Counts> clients_;
};

// The bytes of the frames the server holds (read and not yet processed), against a server-wide
// budget: past it, new frames are refused (RESOURCE_EXHAUSTED) instead of memory growing.
class MemoryBudget {
 public:
  explicit MemoryBudget(std::uint64_t limit) : limit_(limit) {}
  // Takes `bytes`; false, taking nothing, when they do not fit.
  bool TryTake(std::uint64_t bytes) {
    std::uint64_t held = held_.load(std::memory_order_relaxed);
    do {
      if (held + bytes > limit_) return false;
    } while (!held_.compare_exchange_weak(held, held + bytes, std::memory_order_relaxed));
    return true;
  }
  void Give(std::uint64_t bytes) { held_.fetch_sub(bytes, std::memory_order_relaxed); }
  std::uint64_t held() const { return held_.load(std::memory_order_relaxed); }
  std::uint64_t limit() const { return limit_; }

 private:
  const std::uint64_t limit_;
  std::atomic<std::uint64_t> held_{0};
};

// The client of a call: gRPC's peer string without its port ("ipv4:10.1.2.3:40123" ->
// "ipv4:10.1.2.3", "ipv6:[::1]:40123" -> "ipv6:[::1]").
std::string PeerHost(std::string_view peer);

}  // namespace cloudcast::server
