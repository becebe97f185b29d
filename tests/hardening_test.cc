// Defects an outside tester found, each pinned by a test that failed before its fix: what a
// hostile or careless client does to the service, and what it must get instead.
#include <arpa/inet.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <fstream>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "cloudcast/client/client.h"
#include "cloudcast/client/opencv.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/server/server.h"
#include "cloudcast/testing/metrics_scrape.h"
#include "cloudcast/v1/cloudcast.grpc.pb.h"
#include "support/proc_status.h"
#include "support/replica_support.h"
#include "support/sanitizers.h"
#include "support/waiting.h"

namespace cloudcast {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;

const SyntheticFrame& Frame() {
  static const SyntheticFrame frame = [] {
    SyntheticOptions o;
    o.width = 160;
    o.height = 120;
    return *SyntheticScene::Default().Render(o);
  }();
  return frame;
}

v1::StreamRequest FrameRequest(std::uint64_t sequence) {
  v1::StreamRequest request;
  v1::Frame* frame = request.mutable_frame();
  frame->set_sequence(sequence);
  EXPECT_TRUE(
      convert::ToProto(Frame().disparity_view(), "d", frame->mutable_disparity()->mutable_raw())
          .ok());
  EXPECT_TRUE(
      convert::ToProto(Frame().colour_view(), "c", frame->mutable_color()->mutable_raw()).ok());
  return request;
}

grpc::ByteBuffer Bytes(const std::string& s) {
  grpc::Slice slice(s);
  return grpc::ByteBuffer(&slice, 1);
}

grpc::ByteBuffer Serialized(const google::protobuf::Message& m) {
  return Bytes(m.SerializeAsString());
}

class HardeningTest : public ::testing::Test {
 protected:
  void SetUp() override { Start(server::ServerOptions{}); }

  void Start(server::ServerOptions options) {
    server_.reset();
    // The paper's camera and range as the server's defaults, stated: these tests send its frames
    // without a camera (the contract has no default one).
    EXPECT_TRUE(ApplyPreset("new_tsukuba", &options.defaults.frame).ok());
    options.listen = "127.0.0.1:0";
    options.metrics_listen = "127.0.0.1:0";
    auto s = server::Server::Start(options);
    ASSERT_TRUE(s.ok()) << s.status();
    server_ = *std::move(s);
    channel_ = grpc::CreateChannel(server_->address(), grpc::InsecureChannelCredentials());
    generic_ = std::make_unique<grpc::GenericStub>(channel_);
  }

  // A Stream call that writes the given messages as raw bytes (valid or not), then half-closes,
  // and reads everything: the replies and the final status.
  struct RawStreamResult {
    std::vector<v1::StreamReply> replies;
    grpc::Status status;
  };
  RawStreamResult RawStream(const std::vector<grpc::ByteBuffer>& messages) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + seconds(30));
    grpc::CompletionQueue cq;
    auto call = generic_->PrepareCall(&ctx, "/cloudcast.v1.CloudCast/Stream", &cq);
    void* tag;
    bool ok;
    call->StartCall(reinterpret_cast<void*>(1));
    EXPECT_TRUE(cq.Next(&tag, &ok) && ok);
    for (const grpc::ByteBuffer& m : messages) {
      call->Write(m, reinterpret_cast<void*>(2));
      if (!cq.Next(&tag, &ok) || !ok) break;
    }
    call->WritesDone(reinterpret_cast<void*>(3));
    cq.Next(&tag, &ok);
    RawStreamResult result;
    for (;;) {
      grpc::ByteBuffer in;
      call->Read(&in, reinterpret_cast<void*>(4));
      if (!cq.Next(&tag, &ok) || !ok) break;
      std::vector<grpc::Slice> slices;
      EXPECT_TRUE(in.Dump(&slices).ok());
      std::string bytes;
      for (const grpc::Slice& s : slices)
        bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
      v1::StreamReply reply;
      EXPECT_TRUE(reply.ParseFromString(bytes));
      result.replies.push_back(reply);
    }
    call->Finish(&result.status, reinterpret_cast<void*>(5));
    cq.Next(&tag, &ok);
    return result;
  }

  std::unique_ptr<server::Server> server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<grpc::GenericStub> generic_;
};

// Defect 1: bytes that are not a StreamRequest ended the stream with OK, and the frames after
// them were silently lost. Now: the frames before are answered, then the stream ends with
// INVALID_ARGUMENT saying the request could not be parsed, and the metrics count it.
TEST_F(HardeningTest, UnparsableStreamRequestEndsTheStreamWithInvalidArgument) {
  // A length-delimited field that claims 1 GB, and plain garbage.
  const std::string claims_a_gigabyte = std::string("\x12\x80\x80\x80\x80\x04", 6) + "abc";
  for (const std::string& bad : {claims_a_gigabyte, std::string("\xff\xff\xff garbage", 12)}) {
    const RawStreamResult r = RawStream({Serialized(FrameRequest(1)), Serialized(FrameRequest(2)),
                                         Bytes(bad), Serialized(FrameRequest(3))});
    EXPECT_EQ(r.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
        << r.status.error_message();
    EXPECT_NE(r.status.error_message().find("could not be parsed"), std::string::npos)
        << r.status.error_message();
    // What came before the bad bytes is answered; nothing after it is taken.
    ASSERT_EQ(r.replies.size(), 2u);
    EXPECT_EQ(r.replies[0].cloud().sequence(), 1u);
    EXPECT_EQ(r.replies[1].cloud().sequence(), 2u);
  }
  const std::string metrics = server::ScrapeMetrics(server_->metrics_port());
  EXPECT_NE(metrics.find("cloudcast_requests_unparsable_total{method=\"Stream\"} 2"),
            std::string::npos)
      << metrics;
  // A client that half-closes normally still gets OK.
  const RawStreamResult good = RawStream({Serialized(FrameRequest(1))});
  EXPECT_TRUE(good.status.ok()) << good.status.error_message();
  EXPECT_EQ(good.replies.size(), 1u);
}

// Defect 1, Process: unparsable bytes got UNIMPLEMENTED with an empty message.
TEST_F(HardeningTest, UnparsableProcessRequestGetsInvalidArgument) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + seconds(30));
  grpc::CompletionQueue cq;
  const grpc::ByteBuffer bad = Bytes(std::string("\x0a\xff\xff\xff\xff\x0f", 6));
  auto call = generic_->PrepareUnaryCall(&ctx, "/cloudcast.v1.CloudCast/Process", bad, &cq);
  call->StartCall();
  grpc::ByteBuffer reply;
  grpc::Status status;
  call->Finish(&reply, &status, reinterpret_cast<void*>(1));
  void* tag;
  bool ok;
  ASSERT_TRUE(cq.Next(&tag, &ok));
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("could not be parsed"), std::string::npos)
      << status.error_message();
  // The whole request is at fault: the empty field path, structured all the same.
  v1::BadRequest violations;
  ASSERT_TRUE(convert::ParseStatusDetails(status.error_details(), &violations));
  ASSERT_EQ(violations.field_violations_size(), 1);
  EXPECT_EQ(violations.field_violations(0).field(), "");
  EXPECT_EQ(violations.field_violations(0).reason(), "INVALID");
  const std::string metrics = server::ScrapeMetrics(server_->metrics_port());
  EXPECT_NE(metrics.find("cloudcast_requests_unparsable_total{method=\"Process\"} 1"),
            std::string::npos)
      << metrics;
}

// Defect 6: a DELIVERY_LATEST stream whose client never reads kept being read and its frames
// dropped at full speed, costing every other stream. Now the server stops reading it.
TEST_F(HardeningTest, LatestStreamThatNeverReadsStopsBeingRead) {
  // A small receive window fills after a reply or two, as a real frame's replies fill gRPC's
  // default window within a few seconds (without it, replies pile up in the window first).
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_HTTP2_BDP_PROBE, 0);
  args.SetInt(GRPC_ARG_HTTP2_STREAM_LOOKAHEAD_BYTES, 16 * 1024);
  auto stub = v1::CloudCast::NewStub(
      grpc::CreateCustomChannel(server_->address(), grpc::InsecureChannelCredentials(), args));
  grpc::ClientContext ctx;
  auto call = stub->Stream(&ctx);
  v1::StreamRequest config;
  config.mutable_config()->set_delivery(v1::DELIVERY_LATEST);
  ASSERT_TRUE(call->Write(config));
  // Before the fix about a thousand such frames were read and dropped per second.
  SyntheticOptions o;
  o.width = 320;
  o.height = 240;
  const SyntheticFrame small = *SyntheticScene::Default().Render(o);
  v1::StreamRequest request;
  ASSERT_TRUE(convert::ToProto(small.disparity_view(), "d",
                               request.mutable_frame()->mutable_disparity()->mutable_raw())
                  .ok());
  ASSERT_TRUE(convert::ToProto(small.colour_view(), "c",
                               request.mutable_frame()->mutable_color()->mutable_raw())
                  .ok());
  constexpr int kFrames = 4000;
  std::mutex mu;
  std::condition_variable cv;
  bool writer_done = false;
  int written = 0;
  std::thread writer([&] {
    for (int i = 0; i < kFrames; ++i) {
      request.mutable_frame()->set_sequence(static_cast<std::uint64_t>(i));
      if (!call->Write(request)) break;
      std::lock_guard<std::mutex> lock(mu);
      ++written;
    }
    std::lock_guard<std::mutex> lock(mu);
    writer_done = true;
    cv.notify_all();
  });
  // Observed for a few seconds: the writer must be held back by flow control, the server having
  // stopped reading, rather than have every frame read and dropped.
  {
    std::unique_lock<std::mutex> lock(mu);
    cv.wait_for(lock, seconds(3), [&] { return writer_done; });
    EXPECT_FALSE(writer_done) << "the server read all " << kFrames << " frames";
  }
  const double dropped = server::MetricValue(server::ScrapeMetrics(server_->metrics_port()),
                                             "cloudcast_frames_dropped_total");
  std::printf("frames written %d, dropped by the server %.0f\n", written, dropped);
  EXPECT_LT(dropped, 100) << "written " << written;
  ctx.TryCancel();
  writer.join();
}

// What an HTTP/2 client sends first: the connection preface and an empty SETTINGS frame.
std::string Http2PrefaceAndSettings() {
  return std::string("PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n\0\0\0\4\0\0\0\0\0", 33);
}

// A TCP connection to the metrics port that sends nothing (or half a request) and stays open.
int IdleConnection(int port, const std::string& partial = "") {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  EXPECT_EQ(connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
  if (!partial.empty()) {
    EXPECT_GT(write(fd, partial.data(), partial.size()), 0);
  }
  return fd;
}

// Defect 2: two idle TCP connections to the metrics port blocked /metrics for 30 s each. Now a
// scrape is answered at once, however many slow or idle connections are open.
TEST_F(HardeningTest, MetricsAreServedWhileIdleConnectionsAreOpen) {
  std::vector<int> idle;
  for (int i = 0; i < 64; ++i) {
    idle.push_back(IdleConnection(server_->metrics_port(), i % 2 ? "GET /metr" : ""));
  }
  for (int scrape = 0; scrape < 3; ++scrape) {
    const std::string text =
        server::ScrapeMetrics(server_->metrics_port(), "/metrics", /*timeout_ms=*/5000);
    EXPECT_NE(text.find("HTTP/1.1 200 OK"), std::string::npos) << "scrape " << scrape;
    EXPECT_NE(text.find("cloudcast_frames_processed_total"), std::string::npos);
  }
  for (int fd : idle) close(fd);
  // Anything else is refused politely.
  EXPECT_NE(server::ScrapeMetrics(server_->metrics_port(), "/other", 5000).find("404"),
            std::string::npos);
}

// The exporter listens where the service does unless told otherwise: with --listen on loopback,
// /metrics is on loopback too, not on every interface.
TEST_F(HardeningTest, MetricsListenWhereTheServiceListensByDefault) {
  server::ServerOptions options;
  options.listen = "127.0.0.1:0";
  options.metrics_listen = ":0";
  auto s = server::Server::Start(options);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ((*s)->metrics_address().rfind("127.0.0.1:", 0), 0u) << (*s)->metrics_address();
  EXPECT_EQ(server::ServerOptions{}.metrics_listen, ":9464");
}

// Defect 7: one idle client (a connection with no calls, or a stream that sends nothing) made
// a graceful shutdown wait its whole grace period. Now the server ends at once when nothing is
// in flight: the idle stream gets UNAVAILABLE and the idle connection is closed.
TEST_F(HardeningTest, ShutdownDoesNotWaitForIdleClients) {
  // Idle connections: a gRPC channel, a TCP connection that sent nothing, and one that sent
  // the HTTP/2 preface and its SETTINGS and then nothing.
  auto idle = grpc::CreateChannel(server_->address(), grpc::InsecureChannelCredentials());
  ASSERT_TRUE(idle->WaitForConnected(std::chrono::system_clock::now() + seconds(10)));
  const int silent = IdleConnection(server_->port());
  const int preface = IdleConnection(server_->port(), Http2PrefaceAndSettings());
  // ...and a stream that sits idle (its one frame answered, so the server surely holds it).
  auto stub = v1::CloudCast::NewStub(channel_);
  grpc::ClientContext ctx;
  auto call = stub->Stream(&ctx);
  ASSERT_TRUE(call->Write(FrameRequest(1)));
  v1::StreamReply first;
  ASSERT_TRUE(call->Read(&first));
  std::mutex mu;
  std::condition_variable cv;
  bool done = false;
  // A grace far longer than the wait below: a server that waits for its idle clients fails.
  std::thread shutdown([&] {
    server_->Shutdown(seconds(60));
    std::lock_guard<std::mutex> lock(mu);
    done = true;
    cv.notify_all();
  });
  v1::StreamReply reply;
  EXPECT_FALSE(call->Read(&reply));
  const grpc::Status status = call->Finish();
  EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE) << status.error_message();
  {
    std::unique_lock<std::mutex> lock(mu);
    EXPECT_TRUE(cv.wait_for(lock, seconds(20), [&] { return done; }))
        << "Shutdown is waiting for idle clients";
  }
  shutdown.join();
  close(silent);
  close(preface);
}

// The server lets clients send HTTP/2 DATA frames of up to 256 KB, not the protocol's default
// 16 KB (server.cc: a raw frame then reaches it in a quarter of the slices). Read from the
// SETTINGS frame it sends a raw HTTP/2 connection.
TEST_F(HardeningTest, ClientsMaySendHttp2FramesOf256KB) {
  const int fd = IdleConnection(server_->port(), Http2PrefaceAndSettings());
  timeval timeout{10, 0};  // a server that sends no SETTINGS fails the reads below
  ASSERT_EQ(setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout), 0);
  std::string in;
  auto read_at_least = [&](std::size_t n) {
    char buf[4096];
    while (in.size() < n) {
      const ssize_t got = read(fd, buf, sizeof buf);
      if (got <= 0) return false;
      in.append(buf, static_cast<std::size_t>(got));
    }
    return true;
  };
  // Frames: 24-bit length, type, flags, 32-bit stream id. The server's SETTINGS (type 4, no
  // ACK flag) come first; each setting is a 16-bit id and a 32-bit value.
  std::optional<std::uint32_t> max_frame_size;
  std::size_t at = 0;
  bool settings_seen = false;
  while (!settings_seen) {
    ASSERT_TRUE(read_at_least(at + 9)) << "no SETTINGS frame from the server";
    const auto byte = [&](std::size_t i) { return static_cast<std::uint8_t>(in[i]); };
    const std::size_t length = (std::size_t{byte(at)} << 16) | (byte(at + 1) << 8) | byte(at + 2);
    const std::uint8_t type = byte(at + 3), flags = byte(at + 4);
    ASSERT_TRUE(read_at_least(at + 9 + length));
    if (type == 4 && (flags & 1) == 0) {
      settings_seen = true;
      for (std::size_t k = at + 9; k + 6 <= at + 9 + length; k += 6) {
        const std::uint16_t id = static_cast<std::uint16_t>((byte(k) << 8) | byte(k + 1));
        const std::uint32_t value = (std::uint32_t{byte(k + 2)} << 24) | (byte(k + 3) << 16) |
                                    (byte(k + 4) << 8) | byte(k + 5);
        if (id == 5) max_frame_size = value;  // SETTINGS_MAX_FRAME_SIZE
      }
    }
    at += 9 + length;
  }
  close(fd);
  EXPECT_EQ(max_frame_size, std::optional<std::uint32_t>(256 * 1024));
}

// Defect 4: 4 greedy DELIVERY_ALL streams raised a paced stream's latency tenfold: the worker
// pool ran frames first come, first served, so each paced frame waited behind every greedy
// stream's queue. An ordering property, not a time: while a paced frame waits, the greedy
// streams get few frames answered (about one turn), not all they have queued.
TEST_F(HardeningTest, APacedStreamIsNotStarvedByGreedyOnes) {
  server::ServerOptions options;
  options.threads = 2;
  options.max_queued_frames = 8;  // deep greedy queues make a FIFO's unfairness plain
  Start(options);
  SyntheticOptions o;
  o.width = 640;
  o.height = 480;
  const SyntheticFrame big = *SyntheticScene::Default().Render(o);
  auto connect = [&] {
    auto c = client::Client::Connect(server_->address());
    EXPECT_TRUE(c.ok());
    return *std::move(c);
  };
  auto greedy_client = connect();  // one connection for the four greedy streams
  auto paced_client = connect();
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> greedy_answers{0};
  std::vector<std::unique_ptr<client::Stream>> greedy;
  std::vector<std::thread> greedy_senders;
  client::StreamConfig all;
  all.set_delivery(v1::DELIVERY_ALL);
  for (int i = 0; i < 4; ++i) {
    client::StreamOptions so;
    so.on_result = [&](client::Result&&) { greedy_answers.fetch_add(1); };
    auto stream = greedy_client->OpenStream(all, so);
    ASSERT_TRUE(stream.ok());
    greedy.push_back(*std::move(stream));
  }
  for (auto& g : greedy) {
    greedy_senders.emplace_back([&, s = g.get()] {
      while (!stop.load() && s->Send(big.disparity_view(), big.colour_view()).ok()) {
      }
    });
  }
  // The paced stream: one frame at a time, each answered before the next is sent; how many
  // greedy frames were answered while it waited?
  auto paced = paced_client->OpenStream(all);
  ASSERT_TRUE(paced.ok());
  std::vector<std::uint64_t> overtaken;
  for (int i = 0; i < 30; ++i) {
    const std::uint64_t before = greedy_answers.load();
    ASSERT_TRUE((*paced)->Send(big.disparity_view(), big.colour_view()).ok());
    client::Result r;
    ASSERT_TRUE((*paced)->Read(&r));
    ASSERT_TRUE(r.ok()) << r.status;
    if (i >= 5) overtaken.push_back(greedy_answers.load() - before);  // once the queues are full
  }
  stop.store(true);
  for (auto& g : greedy) g->Cancel();
  for (auto& t : greedy_senders) t.join();
  std::sort(overtaken.begin(), overtaken.end());
  const std::uint64_t median = overtaken[overtaken.size() / 2];
  std::printf("greedy frames answered while a paced frame waited: median %lu, max %lu\n",
              static_cast<unsigned long>(median), static_cast<unsigned long>(overtaken.back()));
  // Fair: the frames in work when it arrived plus about a turn of the greedy client (6 to 7
  // measured here). First come, first served: every greedy stream's queue (33 measured).
  EXPECT_LE(median, 16u);
}

// Defect 5: one client could lock everyone out: 64 streams that never send took every slot
// until the idle timeout (60 s). Now one client gets at most half of --max-streams, and a stream
// that sends nothing is ended after --first-message-timeout.
TEST_F(HardeningTest, OneClientCannotLockEveryoneOut) {
  server::ServerOptions options;
  options.max_streams = 8;  // a client's share: 4
  options.first_message_timeout = milliseconds(300);
  Start(options);
  auto stub = v1::CloudCast::NewStub(channel_);
  std::vector<std::unique_ptr<grpc::ClientContext>> contexts;
  std::vector<std::unique_ptr<grpc::ClientReaderWriter<v1::StreamRequest, v1::StreamReply>>> calls;
  for (int i = 0; i < 5; ++i) {
    contexts.push_back(std::make_unique<grpc::ClientContext>());
    calls.push_back(stub->Stream(contexts.back().get()));
  }
  // One of the five, whichever reached the server last (not always the fifth sent: the ASan run
  // showed another order), is refused naming the limit; the four silent ones are ended soon.
  v1::StreamReply reply;
  int refused = 0, ended = 0;
  for (int i = 0; i < 5; ++i) {
    EXPECT_FALSE(calls[i]->Read(&reply));
    const grpc::Status s = calls[i]->Finish();
    if (s.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED) {
      ++refused;
      EXPECT_NE(s.error_message().find("--max-streams-per-client"), std::string::npos)
          << s.error_message();
    } else {
      ++ended;
      EXPECT_EQ(s.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED)
          << i << ": " << s.error_message();
      EXPECT_NE(s.error_message().find("--first-message-timeout"), std::string::npos)
          << s.error_message();
    }
  }
  EXPECT_EQ(refused, 1);
  EXPECT_EQ(ended, 4);
  // A stream that talks is not cut short by the first-message timeout. The silent streams keep
  // their places until gRPC is done with them (OnDone), which may come just after this client
  // holds their status (a stream that read nothing keeps its place so: the rapid-reset bound,
  // stream_reactor.cc), so the next stream may be refused for that moment: it tries again.
  bool answered = false;
  for (int attempt = 0; attempt < 200 && !answered; ++attempt) {
    grpc::ClientContext ctx;
    auto call = stub->Stream(&ctx);
    if (call->Write(FrameRequest(7)) && call->Read(&reply)) {
      EXPECT_EQ(reply.cloud().sequence(), 7u);
      ASSERT_TRUE(call->WritesDone());
      EXPECT_TRUE(call->Finish().ok());
      answered = true;
    } else {
      const grpc::Status s = call->Finish();
      ASSERT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
      testing::PauseFor(milliseconds(10));
    }
  }
  EXPECT_TRUE(answered) << "the client's share was still taken by its ended streams";
}

// Waits `d` (the memory test polls /proc, which has no event to wait on).
void Pause(milliseconds d) {
  std::mutex mu;
  std::condition_variable cv;
  std::unique_lock<std::mutex> lock(mu);
  cv.wait_for(lock, d, [] { return false; });
}

using testing::ResidentBytes;

// Defect 3: a DELIVERY_ALL stream whose client stops reading held 37-57 MB in the server (gRPC's
// transport buffers, far more than max_queued_frames frames), 60 of them 2.6-3.5 GB, and most of
// it stayed after they left. Now each is bounded near its stated limit, and memory goes back to
// the OS once they are gone.
TEST(HardeningMemoryTest, StreamsThatStopReadingHoldBoundedMemoryAndGiveItBack) {
  if (testing::kUnderAddressSanitizer) {
    // The server under test is built the same way. ASan's redzones enlarge every block and its
    // quarantine holds freed memory back on purpose (256 MB by default), so RSS then measures
    // ASan, not the server: the bounds hold in the normal build, where this test runs in CI.
    GTEST_SKIP() << "RSS bounds are not meaningful under ASan (redzones and quarantine)";
  }
  const std::string log = ::testing::TempDir() + "/memory_server.log";
  testing::ServerProcess server("127.0.0.1:0", "memory", {}, log);
  ASSERT_TRUE(server.WaitUntilServing());
  SyntheticOptions o;
  o.width = 640;
  o.height = 480;
  const SyntheticFrame big = *SyntheticScene::Default().Render(o);
  v1::StreamRequest request;
  ASSERT_TRUE(convert::ToProto(big.disparity_view(), "d",
                               request.mutable_frame()->mutable_disparity()->mutable_raw())
                  .ok());
  ASSERT_TRUE(convert::ToProto(big.colour_view(), "c",
                               request.mutable_frame()->mutable_color()->mutable_raw())
                  .ok());
  const std::size_t frame_bytes = request.ByteSizeLong();
  // A client that never reads: a small receive window, so that the server's writes stall soon.
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_HTTP2_BDP_PROBE, 0);
  args.SetMaxSendMessageSize(64 << 20);
  auto channel =
      grpc::CreateCustomChannel(server.address(), grpc::InsecureChannelCredentials(), args);
  auto stub = v1::CloudCast::NewStub(channel);
  v1::StreamRequest config;
  config.mutable_config()->set_delivery(v1::DELIVERY_ALL);
  {
    // Warm: the workers' scratch (pipeline tables, clouds) is sized to this frame and kept by
    // design, so the baseline is a server that has served it, not an untouched one.
    grpc::ClientContext context;
    auto warm = stub->Stream(&context);
    std::thread writer([&] {
      bool ok = warm->Write(config);
      for (int f = 0; f < 8 && ok; ++f) ok = warm->Write(request);
      warm->WritesDone();
    });
    v1::StreamReply reply;
    int replies = 0;
    while (warm->Read(&reply)) replies += reply.has_cloud() ? 1 : 0;
    writer.join();
    ASSERT_TRUE(warm->Finish().ok());
    ASSERT_EQ(replies, 8);
  }
  Pause(milliseconds(1500));  // the idle housekeeping trims what the warm stream freed
  const std::uint64_t before = ResidentBytes(server.pid());
  constexpr int kStreams = 16;
  std::vector<std::unique_ptr<grpc::ClientContext>> contexts;
  std::vector<std::unique_ptr<grpc::ClientReaderWriter<v1::StreamRequest, v1::StreamReply>>> calls;
  std::vector<std::thread> writers;
  std::atomic<int> written{0};
  for (int i = 0; i < kStreams; ++i) {
    contexts.push_back(std::make_unique<grpc::ClientContext>());
    calls.push_back(stub->Stream(contexts.back().get()));
  }
  for (int i = 0; i < kStreams; ++i) {
    writers.emplace_back([&, call = calls[i].get()] {
      v1::StreamRequest r = request;
      if (!call->Write(config)) return;
      for (int f = 0; f < 400 && call->Write(r); ++f) written.fetch_add(1);
    });
  }
  // Until the writers are held back and the server's memory has stopped growing (polled, as no
  // event says so; bounded).
  std::uint64_t peak = 0, last = 0;
  for (int i = 0; i < 100; ++i) {
    Pause(milliseconds(100));
    const std::uint64_t now = ResidentBytes(server.pid());
    peak = std::max(peak, now);
    if (i > 20 && now <= last + (1 << 20)) break;
    last = now;
  }
  const double per_stream_mb = static_cast<double>(peak - before) / kStreams / (1 << 20);
  std::printf(
      "%d streams that stopped reading: server RSS %.0f -> %.0f MB (%.1f MB per stream, "
      "frame %.2f MB, %d frames written)\n",
      kStreams, before / 1048576.0, peak / 1048576.0, per_stream_mb, frame_bytes / 1048576.0,
      written.load());
  for (auto& c : contexts) c->TryCancel();
  for (auto& w : writers) w.join();
  for (auto& c : calls) c->Finish();
  // They leave: their connection closes too (its transport buffers go with it).
  calls.clear();
  stub.reset();
  channel.reset();
  std::uint64_t after = 0;
  for (int i = 0; i < 50; ++i) {
    Pause(milliseconds(100));
    after = ResidentBytes(server.pid());
    if (after < before + (32 << 20)) break;
  }
  std::printf("after they left: %.0f MB\n", after / 1048576.0);
  EXPECT_LT(per_stream_mb, 12.0);
  EXPECT_LT(after, before + (64 << 20));
}

// Defect 3, the server-wide budget: frames beyond it are refused with RESOURCE_EXHAUSTED naming
// the flag, instead of memory growing; the stream goes on, and a frame that fits still works.
TEST_F(HardeningTest, FramesOverTheMemoryBudgetAreRefusedNotHeld) {
  server::ServerOptions options;
  options.memory_budget_bytes = std::uint64_t{1} << 20;  // 1 MB: a 640x480 frame does not fit
  Start(options);
  SyntheticOptions o;
  o.width = 640;
  o.height = 480;
  const SyntheticFrame big = *SyntheticScene::Default().Render(o);
  auto client = client::Client::Connect(server_->address());
  ASSERT_TRUE(client.ok());
  auto stream = (*client)->OpenStream();
  ASSERT_TRUE(stream.ok());
  ASSERT_TRUE((*stream)->Send(big.disparity_view(), big.colour_view()).ok());
  ASSERT_TRUE((*stream)->Send(Frame().disparity_view(), Frame().colour_view()).ok());  // 160x120
  ASSERT_TRUE((*stream)->CloseSend().ok());
  client::Result r;
  ASSERT_TRUE((*stream)->Read(&r));
  EXPECT_EQ(r.status.code(), absl::StatusCode::kResourceExhausted) << r.status;
  EXPECT_NE(std::string(r.status.message()).find("--memory-budget-mb"), std::string::npos)
      << r.status;
  EXPECT_EQ(r.sequence, 0u);
  ASSERT_TRUE((*stream)->Read(&r));
  EXPECT_TRUE(r.ok()) << r.status;
  EXPECT_EQ(r.sequence, 1u);
  EXPECT_TRUE((*stream)->Finish().ok());
  // Process, likewise.
  auto process = (*client)->Process(big.disparity_view(), big.colour_view());
  EXPECT_EQ(process.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_TRUE((*client)->Process(Frame().disparity_view(), Frame().colour_view()).ok());
}

// Defect 8: a JPEG sent as disparity was accepted without a word, although lossy compression
// corrupts disparities (the proto says so). Now it is refused, naming the field.
TEST_F(HardeningTest, JpegDisparityIsRefused) {
  auto client = client::Client::Connect(server_->address());
  ASSERT_TRUE(client.ok());
  const SyntheticFrame& f = Frame();
  cv::Mat disparity(static_cast<int>(f.height), static_cast<int>(f.width), CV_8U);
  for (int v = 0; v < disparity.rows; ++v) {
    for (int u = 0; u < disparity.cols; ++u) disparity.at<std::uint8_t>(v, u) = 100 + u % 50;
  }
  auto jpeg = client::EncodeJpeg(disparity, 95);
  ASSERT_TRUE(jpeg.ok());
  auto png = client::EncodePng(disparity);
  ASSERT_TRUE(png.ok());
  const client::EncodedImage as_jpeg{*jpeg}, as_png{*png};
  auto refused = (*client)->Process(as_jpeg, f.colour_view());
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
  const std::string m(refused.status().message());
  EXPECT_NE(m.find("frame.disparity.encoded is a JPEG"), std::string::npos) << m;
  EXPECT_NE(m.find("lossy"), std::string::npos) << m;
  // The same map as PNG (lossless) is fine, and so is JPEG colour.
  EXPECT_TRUE((*client)->Process(as_png, f.colour_view()).ok());
  cv::Mat colour(static_cast<int>(f.height), static_cast<int>(f.width), CV_8UC3,
                 const_cast<std::uint8_t*>(f.colour.data()));
  auto colour_jpeg = client::EncodeJpeg(colour, 90);
  ASSERT_TRUE(colour_jpeg.ok());
  EXPECT_TRUE((*client)->Process(as_png, client::EncodedImage{*colour_jpeg}).ok());
}

// Issue 18, defect 5: camera values that are finite in double but 0 or denormal in float (the
// pipeline's precision) were accepted, and every cloud came out empty. Now they are refused,
// naming the field, on Process and on Stream alike.
TEST_F(HardeningTest, CameraValuesThatVanishInFloatAreRefusedNamingTheField) {
  auto client = client::Client::Connect(server_->address());
  ASSERT_TRUE(client.ok());
  struct Case {
    const char* field;
    void (*set)(v1::CameraModel*);
  };
  const Case cases[] = {
      {"config.camera.fx", [](v1::CameraModel* c) { c->set_fx(1e-300); }},
      {"config.camera.fx", [](v1::CameraModel* c) { c->set_fx(5e-324); }},
      {"config.camera.fy", [](v1::CameraModel* c) { c->set_fy(1e-300); }},
      {"config.camera.baseline", [](v1::CameraModel* c) { c->set_baseline(1e-300); }},
      {"config.camera.disparity_scale", [](v1::CameraModel* c) { c->set_disparity_scale(1e-300); }},
      {"config.camera.disparity_scale",
       [](v1::CameraModel* c) { c->set_disparity_scale(-1e-300); }},
  };
  for (const Case& k : cases) {
    client::StreamConfig config;
    k.set(config.mutable_camera());
    auto r = (*client)->Process(Frame().disparity_view(), Frame().colour_view(), config);
    ASSERT_FALSE(r.ok()) << k.field << ": accepted, " << r->reply.point_count() << " points";
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument) << r.status();
    EXPECT_NE(std::string(r.status().message()).find(k.field), std::string::npos) << r.status();
    // The same config on a stream is a config error naming the field; the stream goes on.
    auto stream = (*client)->OpenStream(config);
    ASSERT_TRUE(stream.ok());
    ASSERT_TRUE((*stream)->Send(Frame().disparity_view(), Frame().colour_view()).ok());
    ASSERT_TRUE((*stream)->CloseSend().ok());
    client::Result first;
    ASSERT_TRUE((*stream)->Read(&first));
    EXPECT_EQ(first.status.code(), absl::StatusCode::kInvalidArgument) << first.status;
    EXPECT_NE(std::string(first.status.message()).find(k.field), std::string::npos) << first.status;
    client::Result frame;
    ASSERT_TRUE((*stream)->Read(&frame));
    EXPECT_TRUE(frame.ok()) << frame.status;  // with the server's default camera
    EXPECT_TRUE((*stream)->Finish().ok());
  }
  // Small but sound values still work: a 1e-3 baseline (millimetres) gives points.
  client::StreamConfig small;
  small.mutable_camera()->set_baseline(1e-3);
  small.mutable_passthrough()->set_enabled(false);
  auto r = (*client)->Process(Frame().disparity_view(), Frame().colour_view(), small);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_GT(r->reply.point_count(), 0u);
}

// Behind the shipped proxy every call comes from the proxy's address: the per-client shares and
// fairness then count the address the proxy names in x-forwarded-for, when (and only when) the
// proxy is trusted (--trusted-proxy). A client's own header before the proxy's counts for nothing.
TEST_F(HardeningTest, ATrustedProxyNamesTheClientInXForwardedFor) {
  auto stream_from = [&](const std::vector<std::string>& forwarded_for, grpc::ClientContext* ctx) {
    for (const std::string& f : forwarded_for) ctx->AddMetadata("x-forwarded-for", f);
    auto stub = v1::CloudCast::NewStub(channel_);
    auto call = stub->Stream(ctx);
    call->Write(FrameRequest(1));  // fails when the server refused the stream at once
    return call;
  };
  auto answered = [](grpc::ClientReaderWriter<v1::StreamRequest, v1::StreamReply>* call) {
    v1::StreamReply reply;
    return call->Read(&reply) && reply.has_cloud();
  };
  for (const bool trusted : {true, false}) {
    SCOPED_TRACE(trusted ? "trusted" : "not trusted");
    server::ServerOptions options;
    options.max_streams = 8;
    options.max_streams_per_client = 1;
    if (trusted) options.trusted_proxies = {"127.0.0.1"};
    Start(options);
    grpc::ClientContext a, b, c;
    auto first = stream_from({"10.0.0.1"}, &a);
    ASSERT_TRUE(answered(first.get()));
    // Another client behind the proxy (the proxy's entry last, after one the client forged).
    auto second = stream_from({"10.0.0.1", "10.0.0.2"}, &b);
    EXPECT_EQ(answered(second.get()), trusted);
    // The first client again: over its share either way.
    auto third = stream_from({"10.0.0.2", "10.0.0.1"}, &c);
    EXPECT_FALSE(answered(third.get()));
    const grpc::Status refused = third->Finish();
    EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
    EXPECT_NE(refused.error_message().find(trusted ? "ipv4:10.0.0.1" : "ipv4:127.0.0.1"),
              std::string::npos)
        << refused.error_message();
    a.TryCancel();
    b.TryCancel();
    first->Finish();
    second->Finish();
  }
  // A trusted proxy must be an address.
  server::ServerOptions bad;
  bad.trusted_proxies = {"proxy.local"};
  const absl::Status s = bad.Validate();
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(std::string(s.message()).find("--trusted-proxy 'proxy.local'"), std::string::npos) << s;
}

// Issue 30, defect 1: one 2 KB Process call aborted the server. A 64x16 mono8 pair with OpenCV's
// SGBM_3WAY and 128 disparities made OpenCV throw from a destructor (buffer_area.cpp:32), which no
// catch can hold: terminate, SIGABRT. Pairs narrower than their disparity range, for every
// matcher, must each get an error naming the field, and the server must go on.
TEST_F(HardeningTest, StereoPairsNarrowerThanTheirDisparitiesAreRefusedNotFatal) {
  auto stub = v1::CloudCast::NewStub(channel_);
  auto image = [](std::uint32_t w, std::uint32_t h, int shift, v1::ColorImage* out) {
    v1::RawColor* raw = out->mutable_raw();
    raw->set_encoding(v1::COLOR_MONO8);
    raw->set_width(w);
    raw->set_height(h);
    std::string pixels(std::size_t{w} * h, '\0');
    for (std::uint32_t y = 0; y < h; ++y) {
      for (std::uint32_t x = 0; x < w; ++x) {
        pixels[std::size_t{y} * w + x] = static_cast<char>(((x + shift) * 37 + y * 11) * 13 & 0xFF);
      }
    }
    raw->set_pixels(std::move(pixels));
  };
  struct Case {
    std::uint32_t width, height;
    int disparities;
  };
  // The tester's three fatal sizes, and the edges of "wider than num_disparities + block_size"
  // (block 5 here) and of StereoBM's "block below the height".
  const Case cases[] = {{64, 16, 128}, {100, 8, 112}, {1024, 64, 2048}, {133, 8, 128},
                        {134, 8, 128}, {16, 16, 16},  {48, 4, 32},      {48, 5, 32}, {48, 6, 32}};
  const v1::StereoMatcher matchers[] = {
      v1::STEREO_MATCHER_OPENCV_SGBM_3WAY, v1::STEREO_MATCHER_OPENCV_SGBM,
      v1::STEREO_MATCHER_OPENCV_HH, v1::STEREO_MATCHER_OPENCV_BM, v1::STEREO_MATCHER_SGM};
  for (const v1::StereoMatcher matcher : matchers) {
    for (const Case& k : cases) {
      v1::ProcessRequest request;
      v1::StereoConfig* stereo = request.mutable_config()->mutable_stereo();
      stereo->set_matcher(matcher);
      stereo->set_num_disparities(k.disparities);
      stereo->set_block_size(5);
      image(k.width, k.height, 0, request.mutable_frame()->mutable_color());
      image(k.width, k.height, 3, request.mutable_frame()->mutable_right());
      grpc::ClientContext ctx;
      ctx.set_deadline(std::chrono::system_clock::now() + seconds(30));
      v1::CloudReply reply;
      const grpc::Status status = stub->Process(&ctx, request, &reply);
      const std::string what = v1::StereoMatcher_Name(matcher) + " " + std::to_string(k.width) +
                               "x" + std::to_string(k.height) + " with " +
                               std::to_string(k.disparities) + " disparities";
      ASSERT_NE(status.error_code(), grpc::StatusCode::UNAVAILABLE)
          << what << ": the server is gone: " << status.error_message();
      // Ours takes any size; OpenCV's need width > num_disparities + block_size.
      const bool too_narrow = matcher != v1::STEREO_MATCHER_SGM &&
                              k.width <= static_cast<std::uint32_t>(k.disparities) + 5;
      const bool too_short = matcher == v1::STEREO_MATCHER_OPENCV_BM && k.height <= 5;
      if (too_narrow || too_short) {
        // No pixel of the left image has its whole disparity range and block in the right one
        // (or StereoBM's block is taller than the pair).
        EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
            << what << ": " << status.error_message();
        const char* field =
            too_narrow ? "config.stereo.num_disparities" : "config.stereo.block_size";
        EXPECT_NE(status.error_message().find(field), std::string::npos)
            << what << ": " << status.error_message();
        v1::BadRequest bad;
        ASSERT_TRUE(convert::ParseStatusDetails(status.error_details(), &bad)) << what;
        ASSERT_EQ(bad.field_violations_size(), 1) << what;
        EXPECT_EQ(bad.field_violations(0).field(), field) << what;
      } else {
        // Matched, or refused for its work (the volume limit), never a crash.
        EXPECT_TRUE(status.ok() || status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED)
            << what << ": " << status.error_message();
      }
    }
  }
  // The server is still there for everyone.
  auto client = client::Client::Connect(server_->address());
  ASSERT_TRUE(client.ok());
  EXPECT_TRUE((*client)->Process(Frame().disparity_view(), Frame().colour_view()).ok());
}

// Issue 30, defect 8: DEPTH_F32 values of -5 and 1e-45 counted as valid and made points (22,794
// behind the camera with the passthrough off). Depths behind the camera or subnormal are no
// measurement, as negative disparities are none.
TEST_F(HardeningTest, DepthsBehindTheCameraMakeNoPoints) {
  auto stub = v1::CloudCast::NewStub(channel_);
  const std::uint32_t w = 64, h = 48;
  std::vector<float> depth(std::size_t{w} * h);
  std::size_t positive = 0;
  for (std::size_t i = 0; i < depth.size(); ++i) {
    switch (i % 4) {
      case 0: depth[i] = -5.0f; break;
      case 1: depth[i] = 1e-45f; break;
      case 2: depth[i] = -0.5f; break;
      default: depth[i] = 1.5f; ++positive;
    }
  }
  v1::ProcessRequest request;
  request.mutable_config()->mutable_passthrough()->set_enabled(false);
  request.mutable_config()->mutable_voxel_grid()->set_enabled(false);
  v1::RawDepth* raw = request.mutable_frame()->mutable_depth()->mutable_raw();
  raw->set_encoding(v1::DEPTH_F32);
  raw->set_width(w);
  raw->set_height(h);
  raw->set_pixels(std::string(reinterpret_cast<const char*>(depth.data()), depth.size() * 4));
  v1::RawColor* colour = request.mutable_frame()->mutable_color()->mutable_raw();
  colour->set_encoding(v1::COLOR_MONO8);
  colour->set_width(w);
  colour->set_height(h);
  colour->set_pixels(std::string(std::size_t{w} * h, '\x80'));
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + seconds(30));
  v1::CloudReply reply;
  const grpc::Status status = stub->Process(&ctx, request, &reply);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(reply.counts().valid_points(), positive);
  EXPECT_EQ(reply.point_count(), positive);
}

// Issue 30, defect 3: stereo work was undercharged. A 4096x16 pair with 2048 disparities, SGBM_3WAY
// and block 255 (a 128 KB request) took 2,147 MB and 7.6 s of one worker; the estimate charged
// OpenCV's SGBM modes nothing for their costs (about 9 MB a frame). Now each matcher's allocation
// is charged against --work-memory-mb before matching, and the block counts in the matching
// volume (ServerLimits.max_stereo_volume, which bounds a frame's matching time).
TEST_F(HardeningTest, StereoPairsAreChargedWhatTheirMatcherTakes) {
  auto stub = v1::CloudCast::NewStub(channel_);
  auto request_for = [](v1::StereoMatcher matcher, std::uint32_t w, std::uint32_t h,
                        int disparities, int block) {
    v1::ProcessRequest request;
    v1::StereoConfig* stereo = request.mutable_config()->mutable_stereo();
    stereo->set_matcher(matcher);
    stereo->set_num_disparities(disparities);
    stereo->set_block_size(block);
    for (v1::ColorImage* image : {request.mutable_frame()->mutable_color(),
                                  request.mutable_frame()->mutable_right()}) {
      v1::RawColor* raw = image->mutable_raw();
      raw->set_encoding(v1::COLOR_MONO8);
      raw->set_width(w);
      raw->set_height(h);
      std::string pixels(std::size_t{w} * h, '\0');
      for (std::size_t i = 0; i < pixels.size(); ++i) pixels[i] = static_cast<char>(i * 131 % 251);
      raw->set_pixels(std::move(pixels));
    }
    return request;
  };
  for (const v1::StereoMatcher matcher :
       {v1::STEREO_MATCHER_OPENCV_SGBM_3WAY, v1::STEREO_MATCHER_OPENCV_SGBM,
        v1::STEREO_MATCHER_OPENCV_HH}) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + seconds(30));
    v1::CloudReply reply;
    const grpc::Status status =
        stub->Process(&ctx, request_for(matcher, 4096, 16, 2048, 255), &reply);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED)
        << v1::StereoMatcher_Name(matcher) << ": " << status.error_message();
    EXPECT_NE(status.error_message().find("--work-memory-mb"), std::string::npos)
        << status.error_message();
  }
  // Within memory, the block still counts in the matching work: 2048x64 with 256 disparities and
  // block 255 is 2048 x (64 + 2040) x 256 = 1.1 billion cells, over the default 2^27.
  {
    server::ServerOptions options;
    options.work_memory_bytes = std::uint64_t{4} << 30;
    Start(options);
    stub = v1::CloudCast::NewStub(channel_);
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + seconds(30));
    v1::CloudReply reply;
    const grpc::Status status =
        stub->Process(&ctx, request_for(v1::STEREO_MATCHER_OPENCV_SGBM, 2048, 64, 256, 255), &reply);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << status.error_message();
    EXPECT_NE(status.error_message().find("ServerLimits.max_stereo_volume"), std::string::npos)
        << status.error_message();
    v1::BadRequest bad;
    ASSERT_TRUE(convert::ParseStatusDetails(status.error_details(), &bad));
    ASSERT_EQ(bad.field_violations_size(), 1);
    EXPECT_EQ(bad.field_violations(0).reason(), "OVER_LIMIT");
    EXPECT_FALSE(bad.field_violations(0).field().empty()) << status.error_message();
  }
  // A camera's pair at the defaults is taken as before.
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + seconds(30));
  v1::CloudReply reply;
  const grpc::Status ok =
      stub->Process(&ctx, request_for(v1::STEREO_MATCHER_OPENCV_SGBM, 640, 480, 128, 5), &reply);
  EXPECT_TRUE(ok.ok()) << ok.error_message();
}

}  // namespace
}  // namespace cloudcast
