// A Stream call's one state (server/src/stream_lifecycle.h), without gRPC: when it reads, when
// and with which status it finishes, and which steps win over which.
#include "stream_lifecycle.h"

#include <gtest/gtest.h>

namespace cloudcast::server {
namespace {

using State = StreamLifecycle::State;

grpc::Status Unavailable() { return grpc::Status(grpc::StatusCode::UNAVAILABLE, "drain"); }
grpc::Status Idle() { return grpc::Status(grpc::StatusCode::DEADLINE_EXCEEDED, "idle"); }

TEST(StreamLifecycleTest, HalfClosedAnswersWhatItHoldsThenEndsOk) {
  StreamLifecycle s;
  EXPECT_TRUE(s.reading());
  bool cancelled = true;
  EXPECT_FALSE(s.Finish(/*nothing_held=*/true, &cancelled));  // reading: not done
  s.HalfClose();
  EXPECT_FALSE(s.reading());
  EXPECT_TRUE(s.sheddable());
  EXPECT_FALSE(s.Finish(/*nothing_held=*/false, &cancelled));  // frames still held
  auto status = s.Finish(/*nothing_held=*/true, &cancelled);
  ASSERT_TRUE(status);
  EXPECT_TRUE(status->ok());
  EXPECT_FALSE(cancelled);
  EXPECT_TRUE(s.finished());
}

TEST(StreamLifecycleTest, ClosingKeepsItsFirstStatusAndWinsOverAHalfClose) {
  StreamLifecycle s;
  s.HalfClose();
  s.Close(Unavailable());  // a drain after the half-close: the drain's status
  s.Close(Idle());         // a second reason to close changes nothing
  s.HalfClose();
  EXPECT_EQ(s.state(), State::kClosing);
  EXPECT_FALSE(s.sheddable());
  EXPECT_TRUE(s.may_end());
  bool cancelled = true;
  EXPECT_FALSE(s.Finish(false, &cancelled));
  auto status = s.Finish(true, &cancelled);
  ASSERT_TRUE(status);
  EXPECT_EQ(status->error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_FALSE(cancelled);
}

TEST(StreamLifecycleTest, EndingFinishesAtOnceWithoutWaitingForTheFramesHeld) {
  StreamLifecycle s;
  s.Close(Unavailable());
  EXPECT_TRUE(s.End(Idle()));
  EXPECT_FALSE(s.End(Unavailable()));  // ending already: the first End stands
  EXPECT_FALSE(s.may_end());
  bool cancelled = true;
  auto status = s.Finish(/*nothing_held=*/false, &cancelled);
  ASSERT_TRUE(status);
  EXPECT_EQ(status->error_code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  EXPECT_FALSE(cancelled);
}

TEST(StreamLifecycleTest, BrokenWinsOverEveryOtherEndAndSaysSo) {
  StreamLifecycle s;
  EXPECT_TRUE(s.End(Idle()));
  EXPECT_TRUE(s.Break());
  EXPECT_FALSE(s.Break());
  EXPECT_FALSE(s.End(Idle()));
  s.Close(Unavailable());
  EXPECT_EQ(s.state(), State::kBroken);
  bool cancelled = false;
  auto status = s.Finish(/*nothing_held=*/false, &cancelled);
  ASSERT_TRUE(status);
  EXPECT_EQ(status->error_code(), grpc::StatusCode::CANCELLED);
  EXPECT_TRUE(cancelled);  // the caller keeps its place until gRPC is done with the call
}

TEST(StreamLifecycleTest, NothingMovesAFinishedCall) {
  StreamLifecycle s;
  s.HalfClose();
  bool cancelled;
  ASSERT_TRUE(s.Finish(true, &cancelled));
  EXPECT_FALSE(s.Break());
  EXPECT_FALSE(s.End(Idle()));
  s.Close(Unavailable());
  EXPECT_TRUE(s.finished());
  EXPECT_FALSE(s.Finish(true, &cancelled));
}

}  // namespace
}  // namespace cloudcast::server
