// Fair order for keyed work, on two levels:
//   - between clients (a peer address, or a tenant): deficit round robin (Shreedhar and Varghese)
//     weighted by cost. Each client takes turns; in its turn it runs work up to `quantum` more
//     cost units than it has used. The server's costs are frame pixels, so a client sending
//     4096x4096 frames gets a frame per 16.7 M pixels of turns, and one sending 640x480 frames
//     about two frames per turn: neither starves the other, however many connections either
//     spreads its calls over.
//   - between the calls (streams, Process calls) of one client: plain round robin, one item each
//     in turn, so a greedy stream cannot starve a paced one of the same client.
// Within a call, items keep their arrival order. PopIf skips clients whose next item may not
// start now (the worker pool's memory and large-frame limits), keeping their place and credit.
// No locks: the caller holds its own.
#pragma once

#include <cstdint>
#include <deque>
#include <optional>
#include <unordered_map>
#include <utility>

namespace cloudcast::server {

template <typename Item>
class FairQueue {
 public:
  explicit FairQueue(std::uint64_t quantum) : quantum_(quantum > 0 ? quantum : 1) {}

  void Push(std::uint64_t client, std::uint64_t call, std::uint64_t cost, Item item) {
    auto [c, new_client] = clients_.try_emplace(client);
    if (new_client) ring_.push_back(client);
    auto [k, new_call] = c->second.calls.try_emplace(call);
    if (new_call) c->second.ring.push_back(call);
    k->second.push_back({cost, std::move(item)});
    ++size_;
  }

  // The next item; the queue must not be empty.
  Item Pop() {
    return *PopIf([](const Item&) { return true; });
  }

  // The next item in fair order among those `may_start(item)` accepts, looking only at each
  // client's next item (its next call's oldest); nullopt when no client's next item may start.
  template <typename MayStart>
  std::optional<Item> PopIf(const MayStart& may_start) {
    bool any = false;
    for (const std::uint64_t id : ring_) {
      if (may_start(Head(clients_.at(id)).item)) {
        any = true;
        break;
      }
    }
    if (!any) return std::nullopt;
    // Deficit round robin over the clients that may start; every visit of one in a new turn
    // adds to its credit, so the loop ends.
    std::size_t i = 0;
    for (;;) {
      if (i >= ring_.size()) i = 0;
      const std::uint64_t id = ring_[i];
      Client& c = clients_.at(id);
      Work& head = Head(c);
      if (!may_start(head.item)) {
        ++i;
        continue;
      }
      if (!c.in_turn) {
        c.deficit += quantum_;
        c.in_turn = true;
      }
      if (head.cost <= c.deficit) {
        c.deficit -= head.cost;
        const std::uint64_t call = c.ring.front();
        std::deque<Work>& work = c.calls.at(call);
        Item item = std::move(work.front().item);
        work.pop_front();
        --size_;
        c.ring.pop_front();
        if (work.empty()) {
          c.calls.erase(call);
        } else {
          c.ring.push_back(call);  // the client's next item comes from its next call
        }
        if (c.ring.empty()) {
          // An idle client keeps no credit (DRR): it cannot save turns up for a burst.
          clients_.erase(id);
          ring_.erase(ring_.begin() + static_cast<std::ptrdiff_t>(i));
        }
        return item;
      }
      // Its turn is over; the rest of its credit carries to its next turn.
      c.in_turn = false;
      ring_.erase(ring_.begin() + static_cast<std::ptrdiff_t>(i));
      ring_.push_back(id);
    }
  }

  bool empty() const { return size_ == 0; }
  std::size_t size() const { return size_; }

 private:
  struct Work {
    std::uint64_t cost;
    Item item;
  };
  struct Client {
    std::unordered_map<std::uint64_t, std::deque<Work>> calls;
    std::deque<std::uint64_t> ring;  // calls with work, in turn order
    std::uint64_t deficit = 0;
    bool in_turn = false;
  };

  static Work& Head(Client& c) { return c.calls.at(c.ring.front()).front(); }

  const std::uint64_t quantum_;
  std::unordered_map<std::uint64_t, Client> clients_;
  std::deque<std::uint64_t> ring_;  // clients with work, in turn order
  std::size_t size_ = 0;
};

}  // namespace cloudcast::server
