// A test robot: one DELIVERY_ALL stream of the client library and what came back, sequence by
// sequence (how often each frame was answered, by which replica, when), its reconnects and its
// end. The scale-out and fault tests drive it and check "every frame answered exactly once".
#pragma once

#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "cloudcast/client/client.h"

namespace cloudcast::testing {

struct Robot {
  std::unique_ptr<client::Stream> stream;
  std::mutex mu;
  std::condition_variable cv;
  std::map<std::uint64_t, int> answers;     // sequence -> times answered
  std::map<std::uint64_t, std::string> by;  // sequence -> the replica that answered
  std::map<std::uint64_t, std::chrono::steady_clock::time_point> sent_at, answered_at;
  std::vector<std::string> errors;
  std::vector<client::Reconnect> reconnects;
  std::string first_instance;
  std::uint64_t sent = 0;
  absl::Status final_status;

  std::size_t answered() {
    std::lock_guard<std::mutex> lock(mu);
    return answers.size();
  }
  // Waits (bounded) until `n` frames have been answered.
  bool WaitForAnswers(std::size_t n, std::chrono::seconds timeout = std::chrono::seconds(60)) {
    std::unique_lock<std::mutex> lock(mu);
    return cv.wait_for(lock, timeout, [&] { return answers.size() >= n; });
  }
  // The longest time from a send to its answer, ms.
  double MaxLatencyMs() {
    std::lock_guard<std::mutex> lock(mu);
    double worst = 0;
    for (const auto& [seq, t] : answered_at) {
      worst = std::max(worst, std::chrono::duration<double, std::milli>(t - sent_at[seq]).count());
    }
    return worst;
  }
  // Every one of `frames` frames answered exactly once, no frame error, the stream ended OK.
  void ExpectEveryFrameOnce(int frames) {
    std::lock_guard<std::mutex> lock(mu);
    EXPECT_TRUE(final_status.ok()) << final_status;
    EXPECT_TRUE(errors.empty()) << errors.front();
    ASSERT_EQ(answers.size(), static_cast<std::size_t>(frames));
    for (const auto& [sequence, times] : answers) EXPECT_EQ(times, 1) << "frame " << sequence;
  }
};

// Opens a DELIVERY_ALL stream on `client` whose replies and reconnects land in the Robot.
inline std::unique_ptr<Robot> OpenRobot(client::Client& client, bool resilient,
                                        std::chrono::milliseconds reconnect_timeout) {
  auto robot = std::make_unique<Robot>();
  Robot* r = robot.get();
  client::StreamConfig config;
  config.set_delivery(v1::DELIVERY_ALL);
  client::StreamOptions options;
  options.resilient = resilient;
  options.reconnect_timeout = reconnect_timeout;
  options.on_result = [r](client::Result&& result) {
    std::lock_guard<std::mutex> lock(r->mu);
    if (!result.ok()) {
      r->errors.push_back(std::string(result.status.message()));
    } else {
      ++r->answers[result.sequence];
      r->by[result.sequence] = result.server_instance;
      r->answered_at.emplace(result.sequence, std::chrono::steady_clock::now());
      if (r->first_instance.empty()) r->first_instance = result.server_instance;
    }
    r->cv.notify_all();
  };
  options.on_reconnect = [r](const client::Reconnect& event) {
    std::lock_guard<std::mutex> lock(r->mu);
    r->reconnects.push_back(event);
  };
  auto stream = client.OpenStream(config, options);
  EXPECT_TRUE(stream.ok()) << stream.status();
  if (stream.ok()) robot->stream = *std::move(stream);
  return robot;
}

}  // namespace cloudcast::testing
