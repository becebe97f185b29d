#include "read_budget.h"

#include <algorithm>
#include <utility>
#include <vector>

namespace cloudcast::server {

std::uint64_t ReadBudget::Reserve(std::uint64_t client, std::uint64_t bytes, Grant grant) {
  std::lock_guard<std::mutex> lock(mu_);
  Share& share = shares_[client];
  // Behind the client's waiting reservations: the first to come reads first.
  if (share.waiting.empty() && Fits(share, bytes)) {
    share.reserved += bytes;
    return kGranted;
  }
  const std::uint64_t id = next_id_++;
  share.waiting.push_back({id, bytes, std::move(grant)});
  return id;
}

void ReadBudget::Release(std::uint64_t client, std::uint64_t bytes) {
  std::vector<Grant> granted;
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = shares_.find(client);
    if (it == shares_.end()) return;
    Share& share = it->second;
    share.reserved -= std::min(share.reserved, bytes);
    granted = GrantWhatFits(&share);
    if (share.reserved == 0 && share.waiting.empty()) shares_.erase(it);
  }
  // Outside the lock: a grant starts a read, and may reserve or release again.
  for (Grant& g : granted) g();
}

bool ReadBudget::Cancel(std::uint64_t client, std::uint64_t id) {
  std::vector<Grant> granted;
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = shares_.find(client);
    if (it == shares_.end()) return false;
    Share& share = it->second;
    auto w = std::find_if(share.waiting.begin(), share.waiting.end(),
                          [id](const Waiter& x) { return x.id == id; });
    if (w == share.waiting.end()) return false;
    share.waiting.erase(w);
    // The ones behind it may fit now.
    granted = GrantWhatFits(&share);
    if (share.reserved == 0 && share.waiting.empty()) shares_.erase(it);
  }
  for (Grant& g : granted) g();
  return true;
}

std::vector<ReadBudget::Grant> ReadBudget::GrantWhatFits(Share* share) {
  std::vector<Grant> granted;
  while (!share->waiting.empty() && Fits(*share, share->waiting.front().bytes)) {
    share->reserved += share->waiting.front().bytes;
    granted.push_back(std::move(share->waiting.front().grant));
    share->waiting.pop_front();
  }
  return granted;
}

std::uint64_t ReadBudget::reserved(std::uint64_t client) const {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = shares_.find(client);
  return it == shares_.end() ? 0 : it->second.reserved;
}

std::uint64_t ReadBudget::waiting(std::uint64_t client) const {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = shares_.find(client);
  return it == shares_.end() ? 0 : it->second.waiting.size();
}

}  // namespace cloudcast::server
