#include "admission.h"

#include <utility>

#include "absl/strings/str_cat.h"

namespace cloudcast::server {

Admission::Ticket& Admission::Ticket::operator=(Ticket&& other) noexcept {
  if (this != &other) {
    Release();
    admission_ = std::exchange(other.admission_, nullptr);
    kind_ = other.kind_;
    client_ = std::move(other.client_);
  }
  return *this;
}

void Admission::Ticket::Release() {
  if (admission_ != nullptr) std::exchange(admission_, nullptr)->Give(kind_, client_);
}

absl::StatusOr<Admission::Ticket> Admission::Admit(Kind kind, const Client& client,
                                                   Refusal* refusal) {
  Refusal ignored;
  if (refusal == nullptr) refusal = &ignored;
  *refusal = Refusal::kNone;
  const bool stream = kind == Kind::kStream;
  const std::uint32_t limit = stream ? limits_.max_streams : limits_.max_process;
  const std::uint32_t own_limit = stream ? client.max_streams : client.max_process;
  const std::uint32_t share =
      own_limit > 0 ? own_limit
                    : (stream ? limits_.max_streams_per_client : limits_.max_process_per_client);
  const char* what = stream ? "concurrent streams" : "Process calls in flight";
  {
    std::lock_guard<std::mutex> lock(mu_);
    std::uint32_t& total = stream ? total_.streams : total_.process;
    if (total >= limit) {
      *refusal = Refusal::kServerFull;
      return absl::ResourceExhaustedError(
          absl::StrCat("too many ", what, ": the server's limit is ", limit,
                       stream ? " (max_streams, --max-streams)" : " (max_streams, --max-streams)"));
    }
    Counts& mine = clients_[client.key];
    std::uint32_t& own = stream ? mine.streams : mine.process;
    if (own >= share) {
      *refusal = Refusal::kClientShare;
      if (!client.tenant.empty() && own_limit > 0) {
        return absl::ResourceExhaustedError(absl::StrCat(
            "too many ", what, " for tenant '", client.tenant, "': its limit is ", share,
            stream ? " (max_streams" : " (max_process_in_flight", " in --tokens-file)"));
      }
      const std::string who =
          client.tenant.empty() ? client.key : absl::StrCat("tenant '", client.tenant, "'");
      return absl::ResourceExhaustedError(
          absl::StrCat("too many ", what, " from ", who, ": the limit per client is ", share,
                       stream ? " (--max-streams-per-client)" : " (--max-process-per-client)"));
    }
    ++own;
    ++total;
  }
  Ticket t;
  t.admission_ = this;
  t.kind_ = kind;
  t.client_ = client.key;
  return t;
}

void Admission::Give(Kind kind, const std::string& client) {
  std::lock_guard<std::mutex> lock(mu_);
  const bool stream = kind == Kind::kStream;
  --(stream ? total_.streams : total_.process);
  auto it = clients_.find(client);
  if (it == clients_.end()) return;
  --(stream ? it->second.streams : it->second.process);
  if (it->second.streams == 0 && it->second.process == 0) clients_.erase(it);
}

std::uint32_t Admission::open(Kind kind) const {
  std::lock_guard<std::mutex> lock(mu_);
  return kind == Kind::kStream ? total_.streams : total_.process;
}

std::string PeerHost(std::string_view peer) {
  const std::size_t colon = peer.rfind(':');
  // "unix:/path" and other forms without a port stay whole.
  if (colon == std::string_view::npos || peer.find(':') == colon) return std::string(peer);
  const std::string_view port = peer.substr(colon + 1);
  for (char c : port) {
    if (c < '0' || c > '9') return std::string(peer);
  }
  return std::string(peer.substr(0, colon));
}

}  // namespace cloudcast::server
