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

// Issue 30, defect 6: a drain answers the message of a read already started (its client sent it
// before it could know of the drain) and waits for that read, until told to stop waiting.
TEST(StreamLifecycleTest, ADrainAnswersTheReadStartedAndWaitsForItUntilToldNotTo) {
  StreamLifecycle s;
  s.Drain(Unavailable());
  EXPECT_EQ(s.state(), State::kClosing);
  EXPECT_FALSE(s.reading());      // no new read
  EXPECT_TRUE(s.answers_read());  // the one started is answered
  bool cancelled = true;
  EXPECT_FALSE(s.Finish(/*nothing_held=*/true, &cancelled, /*read_started=*/true));
  EXPECT_FALSE(s.Finish(/*nothing_held=*/false, &cancelled, /*read_started=*/true));
  s.StopAwaitingRead();
  EXPECT_TRUE(s.answers_read());  // still answered if it comes before the end
  auto status = s.Finish(/*nothing_held=*/true, &cancelled, /*read_started=*/true);
  ASSERT_TRUE(status);
  EXPECT_EQ(status->error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_FALSE(cancelled);
  EXPECT_FALSE(s.answers_read());  // finished
}

TEST(StreamLifecycleTest, ADrainWithNoReadStartedEndsOnceNothingIsHeld) {
  StreamLifecycle s;
  s.Drain(Unavailable());
  bool cancelled = true;
  EXPECT_FALSE(s.Finish(/*nothing_held=*/false, &cancelled));
  EXPECT_TRUE(s.Finish(/*nothing_held=*/true, &cancelled, /*read_started=*/false));
}

// Only a drain of a stream that was reading answers a late read: not past bytes that did not
// parse (closing already), not a half-closed stream (no read can deliver), not once ending or
// broken.
TEST(StreamLifecycleTest, OnlyADrainOfAReadingStreamAnswersALateRead) {
  {
    StreamLifecycle s;
    s.Close(Unavailable());  // unparsable bytes
    s.Drain(Unavailable());
    EXPECT_FALSE(s.answers_read());
    bool cancelled;
    EXPECT_TRUE(s.Finish(true, &cancelled, /*read_started=*/true));  // nothing awaited
  }
  {
    StreamLifecycle s;
    s.HalfClose();
    s.Drain(Unavailable());
    EXPECT_EQ(s.state(), State::kClosing);
    EXPECT_FALSE(s.answers_read());
  }
  {
    StreamLifecycle s;
    s.Drain(Unavailable());
    EXPECT_TRUE(s.End(Idle()));
    EXPECT_FALSE(s.answers_read());
    bool cancelled;
    EXPECT_TRUE(s.Finish(false, &cancelled, /*read_started=*/true));  // ending: at once
  }
  {
    StreamLifecycle s;
    s.Drain(Unavailable());
    EXPECT_TRUE(s.Break());
    EXPECT_FALSE(s.answers_read());
  }
}

}  // namespace
}  // namespace cloudcast::server
