#include "nfqueue_relay.h"

// clang-format off: libnetfilter_queue's header needs these first.
#include <arpa/inet.h>
#include <libnetfilter_queue/libnetfilter_queue.h>
#include <linux/netfilter.h>
// clang-format on
#include <errno.h>
#include <poll.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <time.h>

#include <algorithm>
#include <cstring>
#include <vector>

#include "absl/strings/str_cat.h"

namespace cloudcast::linkemu {
namespace {

std::int64_t MonotonicNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * kSecond + ts.tv_nsec;
}

// Packets held in the kernel at once, per queue: the emulated queue plus a delay's worth in
// flight (40 Mbit/s x 200 ms is 700 full-size packets).
constexpr std::uint32_t kKernelQueuePackets = 16384;
constexpr int kSocketBufferBytes = 16 << 20;
constexpr unsigned kHeaderBytes = 64;

// The packet's whole length from its IP header (the copy is cut to kHeaderBytes).
int PacketLength(const unsigned char* ip, int copied) {
  if (copied >= 4 && (ip[0] >> 4) == 4) return (ip[2] << 8) | ip[3];
  if (copied >= 6 && (ip[0] >> 4) == 6) return 40 + ((ip[4] << 8) | ip[5]);
  return copied;
}

}  // namespace

absl::StatusOr<std::unique_ptr<NfqueueRelay>> NfqueueRelay::Open(LinkDirection* up,
                                                                 LinkDirection* down,
                                                                 std::uint16_t first_queue) {
  std::unique_ptr<NfqueueRelay> relay(new NfqueueRelay());
  relay->handle_ = nfq_open();
  if (relay->handle_ == nullptr) {
    return absl::UnavailableError(absl::StrCat("nfq_open: ", std::strerror(errno),
                                               " (needs root and the kernel's nfnetlink_queue)"));
  }
  Side* sides[2] = {&relay->up_, &relay->down_};
  LinkDirection* models[2] = {up, down};
  for (int i = 0; i < 2; ++i) {
    Side* side = sides[i];
    side->relay = relay.get();
    side->model = models[i];
    const auto number = static_cast<std::uint16_t>(first_queue + i);
    side->queue = nfq_create_queue(relay->handle_, number, &NfqueueRelay::OnPacket, side);
    if (side->queue == nullptr) {
      return absl::UnavailableError(
          absl::StrCat("nfq_create_queue ", number, ": ", std::strerror(errno)));
    }
    // Only the IP header comes up: its length field is what the link serializes.
    if (nfq_set_mode(side->queue, NFQNL_COPY_PACKET, kHeaderBytes) < 0 ||
        nfq_set_queue_maxlen(side->queue, kKernelQueuePackets) < 0) {
      return absl::UnavailableError(
          absl::StrCat("configuring NFQUEUE ", number, ": ", std::strerror(errno)));
    }
  }
  nfnl_rcvbufsiz(nfq_nfnlh(relay->handle_), kSocketBufferBytes);
  // Report lost netlink messages instead of stopping the relay.
  const int one = 1;
  setsockopt(nfq_fd(relay->handle_), SOL_NETLINK, NETLINK_NO_ENOBUFS, &one, sizeof(one));
  return relay;
}

NfqueueRelay::~NfqueueRelay() {
  for (Side* side : {&up_, &down_}) {
    if (side->queue != nullptr) nfq_destroy_queue(side->queue);
  }
  if (handle_ != nullptr) nfq_close(handle_);
}

Nanos NfqueueRelay::Now() const { return MonotonicNs() - t0_; }

int NfqueueRelay::OnPacket(nfq_q_handle* queue, ::nfgenmsg*, ::nfq_data* data, void* opaque) {
  auto* side = static_cast<Side*>(opaque);
  const nfqnl_msg_packet_hdr* header = nfq_get_msg_packet_hdr(data);
  if (header == nullptr) return 0;
  const std::uint32_t id = ntohl(header->packet_id);
  unsigned char* payload = nullptr;
  const int copied = nfq_get_payload(data, &payload);
  const int length = copied > 0 ? PacketLength(payload, copied) : 0;
  const Nanos now = side->relay->Now();
  const LinkDirection::Decision decision = side->model->Offer(now, length);
  if (decision.fate == LinkDirection::Fate::kQueueDrop) {
    nfq_set_verdict(queue, id, NF_DROP, 0, nullptr);
    return 0;
  }
  side->held.push_back({id, decision.release_at, decision.fate == LinkDirection::Fate::kDeliver});
  return 0;
}

void NfqueueRelay::ReleaseDue(Side* side, Nanos now) {
  while (!side->held.empty() && side->held.front().release_at <= now) {
    const Held& packet = side->held.front();
    nfq_set_verdict(side->queue, packet.id, packet.accept ? NF_ACCEPT : NF_DROP, 0, nullptr);
    side->held.pop_front();
  }
}

absl::Status NfqueueRelay::Run(const std::atomic<bool>& stop, Nanos until) {
  prctl(PR_SET_TIMERSLACK, 1UL);  // wake at the release time, not up to 50 us after
  t0_ = MonotonicNs();
  const int fd = nfq_fd(handle_);
  std::vector<char> buffer(1 << 17);
  while (!stop.load(std::memory_order_relaxed)) {
    Nanos now = Now();
    if (now >= until) break;
    ReleaseDue(&up_, now);
    ReleaseDue(&down_, now);
    Nanos next = std::min<Nanos>(until, now + 100 * kMillisecond);  // see `stop` at least so often
    for (const Side* side : {&up_, &down_}) {
      if (!side->held.empty()) next = std::min(next, side->held.front().release_at);
    }
    const Nanos wait = std::max<Nanos>(0, next - now);
    timespec timeout{static_cast<time_t>(wait / kSecond), static_cast<long>(wait % kSecond)};
    pollfd pfd{fd, POLLIN, 0};
    const int ready = ppoll(&pfd, 1, &timeout, nullptr);
    if (ready < 0) {
      if (errno == EINTR) continue;
      return absl::InternalError(absl::StrCat("ppoll: ", std::strerror(errno)));
    }
    if (ready == 0) continue;
    // Everything that is waiting, without blocking.
    for (;;) {
      const ssize_t n = recv(fd, buffer.data(), buffer.size(), MSG_DONTWAIT);
      if (n < 0) {
        if (errno == EAGAIN || errno == EWOULDBLOCK) break;
        if (errno == EINTR) continue;
        if (errno == ENOBUFS) {
          ++overruns_;
          continue;
        }
        return absl::InternalError(absl::StrCat("recv from NFQUEUE: ", std::strerror(errno)));
      }
      nfq_handle_packet(handle_, buffer.data(), static_cast<int>(n));
    }
  }
  return absl::OkStatus();
}

}  // namespace cloudcast::linkemu
