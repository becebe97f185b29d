// Tests of the client library against a real server, started in-process on an ephemeral
// loopback port: Process and Stream round trips (synthetic frames and, when present, New
// Tsukuba), every cv::Mat input type including a non-continuous ROI, PNG / JPEG sends,
// Reconfigure, FrameErrors that leave the stream going, Finish, the callback receiver, and
// connection failures.
//
// Clouds are checked against core::Pipeline::Run on the same pixels and parameters: the same
// point count, and a one-to-one matching in which every point lies within the reply's
// position_error_bound per coordinate (Draco's quantization) with the exact colour (8-bit
// colour is lossless).
#include "cloudcast/client/client.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <string>
#include <thread>
#include <tuple>
#include <utility>
#include <vector>

#include "cloudcast/client/config.h"
#include "cloudcast/client/opencv.h"
#include "cloudcast/core/image.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/core/point.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/io/image_io.h"
#include "gtest/gtest.h"
#include "support/client_fixture.h"
#include "support/server_fixture.h"
#include "support/test_support.h"
#include "support/waiting.h"

namespace cloudcast::client {
namespace {

using std::chrono::milliseconds;

// ---------------------------------------------------------------------------------------------
// Helpers

SyntheticFrame Render(std::uint32_t w, std::uint32_t h, std::uint64_t frame,
                      DisparityEncoding e = DisparityEncoding::kF32) {
  SyntheticOptions options;
  options.width = w;
  options.height = h;
  options.frame = frame;
  options.disparity_encoding = e;
  absl::StatusOr<SyntheticFrame> f = SyntheticScene::Default().Render(options);
  EXPECT_TRUE(f.ok()) << f.status();
  return f.ok() ? *std::move(f) : SyntheticFrame{};
}

// Mats over a synthetic frame's pixels (no copy).
cv::Mat DisparityMat(const SyntheticFrame& f) {
  const int type = f.disparity_encoding == DisparityEncoding::kU8    ? CV_8UC1
                   : f.disparity_encoding == DisparityEncoding::kU16 ? CV_16UC1
                                                                     : CV_32FC1;
  return cv::Mat(f.height, f.width, type, const_cast<std::uint8_t*>(f.disparity.data()));
}
cv::Mat ColourMat(const SyntheticFrame& f) {
  return cv::Mat(f.height, f.width, CV_8UC3, const_cast<std::uint8_t*>(f.colour.data()));
}

PipelineOptions OptionsFor(const CameraModel& camera, float leaf = 0.03f) {
  PipelineOptions options;
  options.camera = camera;
  options.voxel.SetLeaf(leaf);
  return options;
}

// The config that makes the server run exactly `options`, every delivered.
StreamConfig ConfigFor(const PipelineOptions& options) {
  StreamConfig config = MakeStreamConfig(options);
  config.set_delivery(v1::DELIVERY_ALL);
  return config;
}

PointCloud Reference(const PipelineOptions& options, const DisparityView& d, const ColorView& c) {
  Pipeline pipeline;
  PointCloud out;
  const absl::Status s = pipeline.Run(options, d, c, &out);
  EXPECT_TRUE(s.ok()) << s;
  return out;
}

DisparityView ViewOf(const cv::Mat& m, DisparityEncoding e) {
  DisparityView v;
  v.data = m.data;
  v.size_bytes = m.step[0] * (m.rows - 1) + m.cols * m.elemSize();
  v.width = m.cols;
  v.height = m.rows;
  v.stride_bytes = m.step[0];
  v.encoding = e;
  return v;
}
ColorView ViewOf(const cv::Mat& m, ColorEncoding e) {
  ColorView v;
  v.data = m.data;
  v.size_bytes = m.step[0] * (m.rows - 1) + m.cols * m.elemSize();
  v.width = m.cols;
  v.height = m.rows;
  v.stride_bytes = m.step[0];
  v.encoding = e;
  return v;
}

// The decoded cloud is `reference` within the position error bound the reply reports, per
// coordinate, with the same RGB (8-bit colour is lossless).
::testing::AssertionResult MatchesWithinBound(const PointCloud& reference,
                                              const PointCloud& decoded, float bound) {
  return testing::CloudsMatch(reference, decoded, testing::CloudTolerance::DracoBound(bound));
}

// A loopback port with nothing listening: bound, read and released.
int DeadPort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = 0;
  socklen_t len = sizeof(addr);
  if (fd < 0 || ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) != 0) {
    if (fd >= 0) ::close(fd);
    return 1;  // port 1 needs root to listen on: dead as well
  }
  const int port = ntohs(addr.sin_port);
  ::close(fd);
  return port;
}

// ---------------------------------------------------------------------------------------------
// The fixture: one server for the whole suite, a client of its own per test.

class ClientTest : public testing::SharedServerClientTest {
 protected:
  std::unique_ptr<Stream> Open(const StreamConfig& config, StreamOptions options = {}) {
    absl::StatusOr<std::unique_ptr<Stream>> s = client_->OpenStream(config, std::move(options));
    EXPECT_TRUE(s.ok()) << s.status();
    return s.ok() ? std::move(s).value() : nullptr;
  }
  // Sends `frames` copies of `f` as fast as Send returns, reading on another thread, and returns
  // every result once the stream has finished.
  static std::vector<Result> SendAll(Stream& stream, const SyntheticFrame& f, int frames) {
    std::vector<Result> results;
    std::thread reader([&] {
      Result r;
      while (stream.Read(&r)) results.push_back(std::move(r));
    });
    for (int i = 0; i < frames; ++i) {
      EXPECT_TRUE(stream.Send(f.disparity_view(), f.colour_view()).ok());
    }
    EXPECT_TRUE(stream.CloseSend().ok());
    reader.join();
    EXPECT_TRUE(stream.Finish().ok());
    return results;
  }
};

// ---------------------------------------------------------------------------------------------
// Connecting

TEST(ClientConnectTest, DeadPortFailsWithinTheDeadline) {
  const std::string target = "127.0.0.1:" + std::to_string(DeadPort());
  ClientOptions options;
  options.connect_timeout = milliseconds(500);
  // It returns (a hang would be the test's timeout), with the deadline it gave up at.
  absl::StatusOr<std::unique_ptr<Client>> c = Client::Connect(target, options);
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.status().code(), absl::StatusCode::kUnavailable) << c.status();
  EXPECT_NE(c.status().message().find(target), std::string::npos) << c.status();
  EXPECT_NE(c.status().message().find("500 ms"), std::string::npos) << c.status();
}

TEST(ClientConnectTest, WithoutWaitingTheFirstCallReportsTheDeadServer) {
  const std::string target = "127.0.0.1:" + std::to_string(DeadPort());
  ClientOptions options;
  options.connect_timeout = milliseconds(0);
  options.call_timeout = milliseconds(2000);
  absl::StatusOr<std::unique_ptr<Client>> c = Client::Connect(target, options);
  ASSERT_TRUE(c.ok()) << c.status();
  absl::StatusOr<v1::ServerInfo> info = (*c)->GetInfo();
  ASSERT_FALSE(info.ok());
  EXPECT_EQ(info.status().code(), absl::StatusCode::kUnavailable) << info.status();
  EXPECT_NE(info.status().message().find(target), std::string::npos) << info.status();

  // A stream to it fails at open (its first message cannot be written), or at the latest ends
  // at once with UNAVAILABLE.
  absl::StatusOr<std::unique_ptr<Stream>> stream = (*c)->OpenStream();
  if (stream.ok()) {
    Result r;
    EXPECT_FALSE((*stream)->Read(&r));
    EXPECT_EQ((*stream)->Finish().code(), absl::StatusCode::kUnavailable);
  } else {
    EXPECT_EQ(stream.status().code(), absl::StatusCode::kUnavailable) << stream.status();
  }
}

TEST(ClientConnectTest, EmptyTargetIsRejected) {
  EXPECT_EQ(Client::Connect("").status().code(), absl::StatusCode::kInvalidArgument);
}

// The TCP connections of this network namespace to `port` that are open, seen from the
// connecting side (remote port `port`): a client's socket is a line of its own in /proc/net/tcp,
// or tcp6 for gRPC's dual-stack sockets (127.0.0.1 as ::ffff:127.0.0.1).
int ConnectionsTo(int port) {
  int n = 0;
  for (const char* table : {"/proc/net/tcp", "/proc/net/tcp6"}) {
    std::FILE* f = std::fopen(table, "r");
    if (f == nullptr) continue;
    char line[512];
    while (std::fgets(line, sizeof line, f) != nullptr) {
      unsigned remote_port, state;
      if (std::sscanf(line, " %*d: %*[0-9A-F]:%*X %*[0-9A-F]:%X %X", &remote_port, &state) == 2 &&
          remote_port == static_cast<unsigned>(port) && state == 0x01 /* ESTABLISHED */) {
        ++n;
      }
    }
    std::fclose(f);
  }
  return n;
}

// A Client is a connection, as its header says: two robots in one process (or the load
// generator's streams) are two clients to the server, fairly queued apart, not two streams on
// one connection that gRPC's process-wide subchannel pool would otherwise share.
TEST(ClientConnectTest, EveryClientHasAConnectionOfItsOwn) {
  // A server of its own: no other test's client (whose connection may still be closing) counts.
  std::unique_ptr<server::Server> server = testing::StartTestServer();
  ASSERT_NE(server, nullptr);
  std::vector<std::unique_ptr<Client>> clients;
  for (int i = 1; i <= 3; ++i) {
    absl::StatusOr<std::unique_ptr<Client>> c = Client::Connect(server->address());
    ASSERT_TRUE(c.ok()) << c.status();
    ASSERT_TRUE((*c)->GetInfo().ok());
    clients.push_back(*std::move(c));
    EXPECT_EQ(ConnectionsTo(server->port()), i) << "after " << i << " clients";
  }
}

// ---------------------------------------------------------------------------------------------
// Unary calls

TEST_F(ClientTest, GetInfoDescribesTheServer) {
  absl::StatusOr<v1::ServerInfo> info = client_->GetInfo();
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_FALSE(info->version().empty());
  EXPECT_GT(info->limits().max_message_bytes(), 0u);
  EXPECT_GT(info->limits().max_side(), 0u);
  EXPECT_TRUE(info->defaults().voxel_grid().has_leaf());
  EXPECT_FLOAT_EQ(info->defaults().voxel_grid().leaf(), 0.03f);
}

TEST_F(ClientTest, ProcessSyntheticEqualsThePipeline) {
  const SyntheticFrame f = Render(640, 480, 3);
  const PipelineOptions options = OptionsFor(f.camera);
  FrameMeta meta;
  meta.sequence = 42;
  meta.frame_id = "left";
  meta.capture_time_unix_ns = 1234567890123;
  absl::StatusOr<Result> r =
      client_->Process(f.disparity_view(), f.colour_view(), ConfigFor(options), meta);
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_TRUE(r->ok()) << r->status;
  EXPECT_EQ(r->sequence, 42u);
  EXPECT_EQ(r->frame_id, "left");
  EXPECT_EQ(r->capture_time_unix_ns, 1234567890123);
  EXPECT_GT(r->draco_bytes(), 0u);
  EXPECT_EQ(r->reply.point_count(), r->cloud.size());
  EXPECT_GT(r->times.receive_unix_ns, r->times.send_unix_ns);
  EXPECT_GE(r->round_trip().count(), 0);

  const PointCloud reference = Reference(options, f.disparity_view(), f.colour_view());
  ASSERT_GT(reference.size(), 1000u);  // the scene must exercise the filters
  EXPECT_EQ(r->reply.counts().after_voxel_grid(), reference.size());
  EXPECT_LE(r->reply.position_error_bound(), 0.03f / 4);  // the default: a quarter of the leaf
  EXPECT_TRUE(MatchesWithinBound(reference, r->cloud, r->reply.position_error_bound()));
}

TEST_F(ClientTest, ProcessRejectsAMalformedFrameWithTheServersError) {
  const SyntheticFrame a = Render(64, 48, 0);
  const SyntheticFrame b = Render(32, 24, 0);
  absl::StatusOr<Result> r = client_->Process(a.disparity_view(), b.colour_view());
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument) << r.status();
  EXPECT_NE(r.status().message().find(shared_target()), std::string::npos) << r.status();
}

TEST_F(ClientTest, InputsThatCannotBeReadSafelyNeverLeaveTheClient) {
  const SyntheticFrame f = Render(64, 48, 0);
  DisparityView null_data = f.disparity_view();
  null_data.data = nullptr;
  EXPECT_EQ(client_->Process(null_data, f.colour_view()).status().code(),
            absl::StatusCode::kInvalidArgument);
  ColorView short_buffer = f.colour_view();
  short_buffer.size_bytes -= 1;
  absl::Status s = client_->Process(f.disparity_view(), short_buffer).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("colour"), std::string::npos) << s;
  BgraView narrow_stride;
  narrow_stride.data = f.colour.data();
  narrow_stride.size_bytes = f.colour.size();
  narrow_stride.width = 64;
  narrow_stride.height = 36;
  narrow_stride.stride_bytes = 64 * 3;
  EXPECT_EQ(client_->Process(f.disparity_view(), narrow_stride).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(client_->Process(f.disparity_view(), EncodedImage{}).status().code(),
            absl::StatusCode::kInvalidArgument);
}

// ---------------------------------------------------------------------------------------------
// cv::Mat inputs

TEST(ClientMatTest, UnsupportedMatTypesAreRefusedWithTheirName) {
  absl::StatusOr<DisparityInput> sgbm = DisparityFromMat(cv::Mat(4, 4, CV_16SC1));
  EXPECT_EQ(sgbm.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(sgbm.status().message().find("CV_16S"), std::string::npos) << sgbm.status();
  EXPECT_FALSE(DisparityFromMat(cv::Mat(4, 4, CV_8UC3)).ok());
  EXPECT_FALSE(DisparityFromMat(cv::Mat()).ok());
  absl::StatusOr<ColorInput> two = ColorFromMat(cv::Mat(4, 4, CV_8UC2));
  EXPECT_EQ(two.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(two.status().message().find("8UC2"), std::string::npos) << two.status();
  EXPECT_FALSE(ColorFromMat(cv::Mat(4, 4, CV_16UC3)).ok());
  EXPECT_FALSE(ColorFromMat(cv::Mat(4, 4, CV_32FC3)).ok());
}

TEST(ClientMatTest, ViewsPointIntoTheMatWithItsStride) {
  cv::Mat big(100, 200, CV_16UC1, cv::Scalar(7));
  cv::Mat roi = big(cv::Rect(10, 20, 50, 30));
  ASSERT_FALSE(roi.isContinuous());
  absl::StatusOr<DisparityInput> d = DisparityFromMat(roi);
  ASSERT_TRUE(d.ok()) << d.status();
  const auto& view = std::get<DisparityView>(*d);
  EXPECT_EQ(view.data, roi.data);
  EXPECT_EQ(view.width, 50u);
  EXPECT_EQ(view.height, 30u);
  EXPECT_EQ(view.stride_bytes, 400u);
  EXPECT_EQ(view.encoding, DisparityEncoding::kU16);
  EXPECT_EQ(view.size_bytes, 400u * 29 + 100);  // never past the ROI's last pixel
  absl::StatusOr<ColorInput> bgra = ColorFromMat(cv::Mat(3, 5, CV_8UC4));
  ASSERT_TRUE(bgra.ok());
  EXPECT_TRUE(std::holds_alternative<BgraView>(*bgra));
}

// Every supported disparity type with every supported colour type, and both as ROIs of larger
// images, against the pipeline on the equivalent views.
TEST_F(ClientTest, MatInputsOfEverySupportedType) {
  struct DisparityCase {
    DisparityEncoding encoding;
    const char* name;
  };
  const DisparityCase disparities[] = {{DisparityEncoding::kU8, "CV_8U"},
                                       {DisparityEncoding::kU16, "CV_16U"},
                                       {DisparityEncoding::kF32, "CV_32F"}};
  for (const DisparityCase& dc : disparities) {
    const SyntheticFrame f = Render(320, 240, 5, dc.encoding);
    const PipelineOptions options = OptionsFor(f.camera, 0.05f);
    const cv::Mat disparity = DisparityMat(f);
    const cv::Mat bgr = ColourMat(f);
    cv::Mat bgra, grey;
    cv::cvtColor(bgr, bgra, cv::COLOR_BGR2BGRA);
    // Alpha varies so that a client forwarding it (or mixing it into colour) would show.
    for (int v = 0; v < bgra.rows; ++v) {
      for (int u = 0; u < bgra.cols; ++u) bgra.at<cv::Vec4b>(v, u)[3] = (u * 7 + v) & 0xFF;
    }
    cv::cvtColor(bgr, grey, cv::COLOR_BGR2GRAY);
    struct ColourCase {
      const cv::Mat* mat;
      const cv::Mat* reference_pixels;
      ColorEncoding reference_encoding;
      const char* name;
    };
    const ColourCase colours[] = {{&bgr, &bgr, ColorEncoding::kBGR8, "CV_8UC3"},
                                  {&bgra, &bgr, ColorEncoding::kBGR8, "CV_8UC4"},
                                  {&grey, &grey, ColorEncoding::kMono8, "CV_8UC1"}};
    for (const ColourCase& cc : colours) {
      SCOPED_TRACE(std::string(dc.name) + " + " + cc.name);
      const PointCloud reference = Reference(options, ViewOf(disparity, dc.encoding),
                                             ViewOf(*cc.reference_pixels, cc.reference_encoding));
      ASSERT_GT(reference.size(), 100u);
      absl::StatusOr<Result> r = ProcessMats(*client_, disparity, *cc.mat, ConfigFor(options));
      ASSERT_TRUE(r.ok()) << r.status();
      EXPECT_TRUE(MatchesWithinBound(reference, r->cloud, r->reply.position_error_bound()));
    }
  }
}

TEST_F(ClientTest, NonContinuousRoiMatsAreSentAsTheirPixelsOnly) {
  const SyntheticFrame f = Render(320, 240, 8, DisparityEncoding::kU16);
  // Embed the frame in larger images whose surroundings would ruin the cloud if sent.
  cv::Mat big_disparity(300, 400, CV_16UC1, cv::Scalar(16 * 200));
  cv::Mat big_colour(300, 400, CV_8UC3, cv::Scalar(255, 0, 255));
  const cv::Rect where(30, 40, 320, 240);
  DisparityMat(f).copyTo(big_disparity(where));
  ColourMat(f).copyTo(big_colour(where));
  const cv::Mat d = big_disparity(where), c = big_colour(where);
  ASSERT_FALSE(d.isContinuous());
  ASSERT_FALSE(c.isContinuous());

  const PipelineOptions options = OptionsFor(f.camera, 0.05f);
  const PointCloud reference = Reference(options, f.disparity_view(), f.colour_view());
  absl::StatusOr<Result> r = ProcessMats(*client_, d, c, ConfigFor(options));
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->reply.counts().pixels(), 320u * 240u);
  EXPECT_TRUE(MatchesWithinBound(reference, r->cloud, r->reply.position_error_bound()));

  // The same through a stream, twice, so the reused request is refilled correctly.
  std::unique_ptr<Stream> stream = Open(ConfigFor(options));
  ASSERT_NE(stream, nullptr);
  for (int i = 0; i < 2; ++i) ASSERT_TRUE(SendMats(*stream, d, c).ok());
  for (int i = 0; i < 2; ++i) {
    Result result;
    ASSERT_TRUE(stream->Read(&result));
    ASSERT_TRUE(result.ok()) << result.status;
    EXPECT_EQ(result.sequence, static_cast<std::uint64_t>(i));
    EXPECT_TRUE(MatchesWithinBound(reference, result.cloud, result.reply.position_error_bound()));
  }
  EXPECT_TRUE(stream->Finish().ok());
}

// ---------------------------------------------------------------------------------------------
// Encoded images

TEST_F(ClientTest, PngFramesEqualTheRawOnes) {
  const SyntheticFrame f = Render(320, 240, 11, DisparityEncoding::kU16);
  const PipelineOptions options = OptionsFor(f.camera, 0.05f);
  absl::StatusOr<std::string> d = EncodePng(DisparityMat(f));
  absl::StatusOr<std::string> c = EncodePng(ColourMat(f), 3);
  ASSERT_TRUE(d.ok()) << d.status();
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_LT(d->size(), f.disparity.size());  // worth it on a thin uplink

  const PointCloud reference = Reference(options, f.disparity_view(), f.colour_view());
  absl::StatusOr<Result> r =
      client_->Process(EncodedImage{*d}, EncodedImage{*c}, ConfigFor(options));
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_TRUE(MatchesWithinBound(reference, r->cloud, r->reply.position_error_bound()));
}

TEST_F(ClientTest, JpegColourWithRawDisparity) {
  const SyntheticFrame f = Render(320, 240, 12, DisparityEncoding::kF32);
  const PipelineOptions options = OptionsFor(f.camera, 0.05f);
  absl::StatusOr<std::string> jpeg = EncodeJpeg(ColourMat(f), 80);
  ASSERT_TRUE(jpeg.ok()) << jpeg.status();
  EXPECT_LT(jpeg->size(), f.colour.size() / 2);
  // The server decodes with the same OpenCV, so the reference uses the same decoded pixels.
  const cv::Mat decoded = cv::imdecode(
      cv::Mat(1, static_cast<int>(jpeg->size()), CV_8UC1, jpeg->data()), cv::IMREAD_COLOR);
  ASSERT_FALSE(decoded.empty());
  const PointCloud reference =
      Reference(options, f.disparity_view(), ViewOf(decoded, ColorEncoding::kBGR8));

  std::unique_ptr<Stream> stream = Open(ConfigFor(options));
  ASSERT_NE(stream, nullptr);
  ASSERT_TRUE(stream->Send(f.disparity_view(), EncodedImage{*jpeg}).ok());
  Result r;
  ASSERT_TRUE(stream->Read(&r));
  ASSERT_TRUE(r.ok()) << r.status;
  EXPECT_TRUE(MatchesWithinBound(reference, r.cloud, r.reply.position_error_bound()));
  EXPECT_TRUE(stream->Finish().ok());
}

TEST(ClientEncodeTest, EncodersReportWhatTheyCannotDo) {
  EXPECT_FALSE(EncodePng(cv::Mat()).ok());
  EXPECT_FALSE(EncodeImage(cv::Mat(4, 4, CV_8UC3), ".nosuchformat").ok());
  absl::StatusOr<std::string> tiff = EncodeImage(cv::Mat(4, 4, CV_32FC1, cv::Scalar(1.5)), ".tiff");
  ASSERT_TRUE(tiff.ok()) << tiff.status();
  EXPECT_GT(tiff->size(), 0u);
}

// ---------------------------------------------------------------------------------------------
// Streams

TEST_F(ClientTest, StreamRoundTripsEveryFrameInOrder) {
  const DisparityEncoding encodings[] = {DisparityEncoding::kU8, DisparityEncoding::kU16,
                                         DisparityEncoding::kF32};
  std::vector<SyntheticFrame> frames;
  // Small frames, all sent before the first Read: they must fit the server's per-stream queue
  // and the transport's windows, or Send would wait for a Read that never comes.
  for (int i = 0; i < 4; ++i) frames.push_back(Render(160, 120, i, encodings[i % 3]));
  const PipelineOptions options = OptionsFor(frames[0].camera, 0.05f);
  std::unique_ptr<Stream> stream = Open(ConfigFor(options));
  ASSERT_NE(stream, nullptr);

  const std::int64_t t0 = UnixNanosNow();
  for (std::size_t i = 0; i < frames.size(); ++i) {
    FrameMeta meta;
    meta.frame_id = "cam" + std::to_string(i);
    if (i % 2 == 0) meta.capture_time_unix_ns = t0 - 1000000 * static_cast<std::int64_t>(i);
    ASSERT_TRUE(stream->Send(frames[i].disparity_view(), frames[i].colour_view(), meta).ok());
  }
  EXPECT_EQ(stream->frames_sent(), frames.size());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    SCOPED_TRACE("frame " + std::to_string(i));
    Result r;
    ASSERT_TRUE(stream->Read(&r));
    ASSERT_TRUE(r.ok()) << r.status;
    EXPECT_EQ(r.sequence, i);  // automatic numbering from 0
    EXPECT_EQ(r.frame_id, "cam" + std::to_string(i));
    if (i % 2 == 0) {
      EXPECT_EQ(r.capture_time_unix_ns, t0 - 1000000 * static_cast<std::int64_t>(i));
    } else {
      EXPECT_GE(r.capture_time_unix_ns, t0);  // stamped at Send
    }
    EXPECT_GT(r.times.send_unix_ns, 0);
    EXPECT_GE(r.times.receive_unix_ns, r.times.send_unix_ns);
    EXPECT_GE(r.round_trip().count(), 0);
    // The latency runs from the capture, which precedes the send: it holds the round trip.
    EXPECT_LE(r.capture_time_unix_ns, r.times.send_unix_ns);
    EXPECT_EQ(r.frames_dropped, 0u);
    EXPECT_EQ(r.cloud.size(), r.reply.point_count());
    const PointCloud reference =
        Reference(options, frames[i].disparity_view(), frames[i].colour_view());
    EXPECT_TRUE(MatchesWithinBound(reference, r.cloud, r.reply.position_error_bound()));
  }
  EXPECT_TRUE(stream->CloseSend().ok());
  Result end;
  EXPECT_FALSE(stream->Read(&end));
  const absl::Status finish = stream->Finish();
  EXPECT_TRUE(finish.ok()) << finish;
  EXPECT_EQ(stream->Finish(), finish);  // idempotent
  const absl::Status late = stream->Send(frames[0].disparity_view(), frames[0].colour_view());
  EXPECT_EQ(late.code(), absl::StatusCode::kFailedPrecondition) << late;
}

TEST_F(ClientTest, ReconfigureAppliesToTheFollowingFrames) {
  const SyntheticFrame f = Render(320, 240, 2);
  const PipelineOptions fine = OptionsFor(f.camera, 0.03f);
  const PipelineOptions coarse = OptionsFor(f.camera, 0.2f);
  std::unique_ptr<Stream> stream = Open(ConfigFor(fine));
  ASSERT_NE(stream, nullptr);
  ASSERT_TRUE(stream->Send(f.disparity_view(), f.colour_view()).ok());
  ASSERT_TRUE(stream->Reconfigure(ConfigFor(coarse)).ok());
  ASSERT_TRUE(stream->Send(f.disparity_view(), f.colour_view()).ok());
  Result a, b;
  ASSERT_TRUE(stream->Read(&a));
  ASSERT_TRUE(stream->Read(&b));
  ASSERT_TRUE(a.ok() && b.ok()) << a.status << " / " << b.status;
  const PointCloud fine_ref = Reference(fine, f.disparity_view(), f.colour_view());
  const PointCloud coarse_ref = Reference(coarse, f.disparity_view(), f.colour_view());
  ASSERT_LT(coarse_ref.size(), fine_ref.size());
  EXPECT_TRUE(MatchesWithinBound(fine_ref, a.cloud, a.reply.position_error_bound()));
  EXPECT_TRUE(MatchesWithinBound(coarse_ref, b.cloud, b.reply.position_error_bound()));
  EXPECT_TRUE(stream->Finish().ok());
}

TEST_F(ClientTest, FrameErrorSurfacesAndTheStreamGoesOn) {
  const SyntheticFrame good = Render(160, 120, 1);
  const SyntheticFrame other = Render(80, 60, 1);
  const PipelineOptions options = OptionsFor(good.camera, 0.05f);
  std::unique_ptr<Stream> stream = Open(ConfigFor(options));
  ASSERT_NE(stream, nullptr);
  FrameMeta bad_meta;
  bad_meta.sequence = 100;
  bad_meta.frame_id = "bad";
  bad_meta.capture_time_unix_ns = 777;
  const std::string garbage = "this is not a PNG file";
  ASSERT_TRUE(stream->Send(good.disparity_view(), good.colour_view()).ok());             // 0
  ASSERT_TRUE(stream->Send(good.disparity_view(), other.colour_view(), bad_meta).ok());  // 100
  ASSERT_TRUE(stream->Send(EncodedImage{garbage}, good.colour_view()).ok());             // 101
  ASSERT_TRUE(stream->Send(good.disparity_view(), good.colour_view()).ok());             // 102

  Result r;
  ASSERT_TRUE(stream->Read(&r));
  EXPECT_TRUE(r.ok()) << r.status;
  EXPECT_EQ(r.sequence, 0u);

  ASSERT_TRUE(stream->Read(&r));
  EXPECT_EQ(r.status.code(), absl::StatusCode::kInvalidArgument) << r.status;
  EXPECT_FALSE(r.status.message().empty());
  EXPECT_EQ(r.sequence, 100u);
  EXPECT_EQ(r.frame_id, "bad");
  EXPECT_FALSE(r.config_rejected);
  EXPECT_EQ(r.capture_time_unix_ns, 777);  // from the client's record of the frame
  EXPECT_GT(r.times.send_unix_ns, 0);
  EXPECT_TRUE(r.cloud.empty());
  EXPECT_EQ(r.draco_bytes(), 0u);

  ASSERT_TRUE(stream->Read(&r));
  EXPECT_EQ(r.status.code(), absl::StatusCode::kInvalidArgument) << r.status;
  EXPECT_EQ(r.sequence, 101u);

  ASSERT_TRUE(stream->Read(&r));
  EXPECT_TRUE(r.ok()) << r.status;
  EXPECT_EQ(r.sequence, 102u);
  EXPECT_GT(r.cloud.size(), 0u);
  const absl::Status finish = stream->Finish();
  EXPECT_TRUE(finish.ok()) << finish;
}

TEST_F(ClientTest, ARejectedReconfigureIsReportedAndTheOldConfigStays) {
  const SyntheticFrame f = Render(160, 120, 3);
  const PipelineOptions options = OptionsFor(f.camera, 0.05f);
  const PointCloud reference = Reference(options, f.disparity_view(), f.colour_view());
  std::unique_ptr<Stream> stream = Open(ConfigFor(options));
  ASSERT_NE(stream, nullptr);
  StreamConfig bad = ConfigFor(options);
  bad.mutable_voxel_grid()->set_leaf_x(0.0f);
  ASSERT_TRUE(stream->Reconfigure(bad).ok());
  // Sequence 0 and no frame_id: exactly what a config error carries, so only the message can
  // tell the two apart.
  ASSERT_TRUE(stream->Send(f.disparity_view(), f.colour_view()).ok());

  Result r;
  ASSERT_TRUE(stream->Read(&r));
  EXPECT_EQ(r.status.code(), absl::StatusCode::kInvalidArgument) << r.status;
  EXPECT_TRUE(r.config_rejected) << r.status;
  EXPECT_NE(r.status.message().find("voxel_grid"), std::string::npos) << r.status;
  EXPECT_EQ(r.times.send_unix_ns, 0);  // no frame's send record was taken for it

  ASSERT_TRUE(stream->Read(&r));
  ASSERT_TRUE(r.ok()) << r.status;
  EXPECT_FALSE(r.config_rejected);
  EXPECT_EQ(r.sequence, 0u);
  EXPECT_GT(r.times.send_unix_ns, 0);  // its own record, still there
  EXPECT_TRUE(MatchesWithinBound(reference, r.cloud, r.reply.position_error_bound()));
  EXPECT_TRUE(stream->Finish().ok());
}

TEST_F(ClientTest, SenderAndReaderOnTwoThreads) {
  const SyntheticFrame f = Render(160, 120, 4, DisparityEncoding::kU16);
  const PipelineOptions options = OptionsFor(f.camera, 0.05f);
  const PointCloud reference = Reference(options, f.disparity_view(), f.colour_view());
  std::unique_ptr<Stream> stream = Open(ConfigFor(options));
  ASSERT_NE(stream, nullptr);
  constexpr int kFrames = 40;
  std::thread sender([&] {
    for (int i = 0; i < kFrames; ++i) {
      EXPECT_TRUE(stream->Send(f.disparity_view(), f.colour_view()).ok());
    }
    EXPECT_TRUE(stream->CloseSend().ok());
  });
  int received = 0;
  Result r;
  while (stream->Read(&r)) {
    EXPECT_TRUE(r.ok()) << r.status;
    EXPECT_EQ(r.sequence, static_cast<std::uint64_t>(received));
    EXPECT_EQ(r.cloud.size(), reference.size());
    ++received;
  }
  sender.join();
  EXPECT_EQ(received, kFrames);
  EXPECT_TRUE(stream->Finish().ok());
}

TEST_F(ClientTest, CallbackReceiverDeliversEveryReplyBeforeFinishReturns) {
  const SyntheticFrame f = Render(160, 120, 6);
  const PipelineOptions options = OptionsFor(f.camera, 0.05f);
  std::mutex mu;
  std::vector<Result> results;
  StreamOptions stream_options;
  stream_options.on_result = [&](Result&& r) {
    std::lock_guard<std::mutex> lock(mu);
    results.push_back(std::move(r));
  };
  std::unique_ptr<Stream> stream = Open(ConfigFor(options), stream_options);
  ASSERT_NE(stream, nullptr);
  for (int i = 0; i < 10; ++i) {
    FrameMeta meta;
    meta.sequence = 1000 + 2 * i;  // not contiguous
    ASSERT_TRUE(stream->Send(f.disparity_view(), f.colour_view(), meta).ok());
  }
  Result unused;
  EXPECT_FALSE(stream->Read(&unused));  // callback mode owns the reading
  const absl::Status finish = stream->Finish();
  EXPECT_TRUE(finish.ok()) << finish;
  std::lock_guard<std::mutex> lock(mu);
  ASSERT_EQ(results.size(), 10u);
  for (int i = 0; i < 10; ++i) {
    EXPECT_TRUE(results[i].ok()) << results[i].status;
    EXPECT_EQ(results[i].sequence, static_cast<std::uint64_t>(1000 + 2 * i));
    EXPECT_GT(results[i].cloud.size(), 0u);
    EXPECT_GT(results[i].times.send_unix_ns, 0);
  }
}

TEST_F(ClientTest, LatestDeliveryAnswersTheLastFrameAndCountsTheRest) {
  const SyntheticFrame f = Render(640, 480, 9);
  PipelineOptions options = OptionsFor(f.camera, 0.03f);
  options.passthrough.enabled = false;  // more work per frame, so that frames pile up
  StreamConfig config = MakeStreamConfig(options);
  config.set_delivery(v1::DELIVERY_LATEST);
  std::unique_ptr<Stream> stream = Open(config);
  ASSERT_NE(stream, nullptr);
  constexpr int kFrames = 12;
  std::vector<Result> results;
  std::thread reader([&] {
    Result r;
    while (stream->Read(&r)) results.push_back(std::move(r));
  });
  for (int i = 0; i < kFrames; ++i) {
    EXPECT_TRUE(stream->Send(f.disparity_view(), f.colour_view()).ok());
  }
  EXPECT_TRUE(stream->CloseSend().ok());
  reader.join();
  EXPECT_TRUE(stream->Finish().ok());
  ASSERT_FALSE(results.empty());
  // Every frame comes back exactly once: answered, or (DELIVERY_LATEST) replaced in the client
  // before it was sent, or skipped by the server for a newer one.
  std::set<std::uint64_t> seen;
  std::uint64_t previous = 0, answered = 0;
  for (const Result& r : results) {
    EXPECT_TRUE(seen.insert(r.sequence).second) << "frame " << r.sequence << " came back twice";
    if (r.fate != FrameFate::kAnswered) {
      EXPECT_TRUE(r.fate == FrameFate::kReplaced || r.fate == FrameFate::kDropped)
          << FateName(r.fate);
      EXPECT_EQ(r.status.code(), absl::StatusCode::kAborted) << r.status;
      continue;
    }
    EXPECT_TRUE(r.ok()) << r.status;
    if (answered > 0) {
      EXPECT_GT(r.sequence, previous);
    }
    ++answered;
    previous = r.sequence;
    // The send record was found even when earlier frames were skipped.
    EXPECT_GT(r.times.send_unix_ns, 0) << "sequence " << r.sequence;
  }
  EXPECT_EQ(seen.size(), static_cast<std::size_t>(kFrames));
  EXPECT_EQ(previous, static_cast<std::uint64_t>(kFrames - 1));  // the newest is answered
  const Result& last = results.back();
  EXPECT_EQ(last.fate, FrameFate::kAnswered);
  EXPECT_EQ(last.frames_replaced, stream->frames_replaced());
  EXPECT_EQ(answered + last.frames_dropped + last.frames_replaced,
            static_cast<std::uint64_t>(kFrames));
}

// StreamOptions::rate_control on loopback: every answered frame carries the controller's
// estimate, the server's byte count grows with each frame, and no more frames are in flight
// than the window allows (the rest are replaced, each still coming back once).
TEST_F(ClientTest, RateControlReportsItsEstimateAndKeepsItsWindow) {
  const SyntheticFrame f = Render(320, 240, 4);
  StreamConfig config = MakeStreamConfig(OptionsFor(f.camera, 0.03f));
  config.set_delivery(v1::DELIVERY_LATEST);
  StreamOptions options;
  options.rate_control = RateControlOptions{};
  std::unique_ptr<Stream> stream = Open(config, std::move(options));
  ASSERT_NE(stream, nullptr);
  constexpr int kFrames = 40;
  const std::vector<Result> results = SendAll(*stream, f, kFrames);
  ASSERT_EQ(results.size(), static_cast<std::size_t>(kFrames));
  std::uint64_t previous_bytes = 0;
  int answered = 0;
  for (const Result& r : results) {
    if (r.fate != FrameFate::kAnswered) continue;
    ++answered;
    ASSERT_TRUE(r.rate.has_value()) << "sequence " << r.sequence;
    EXPECT_GT(r.rate->target_bps, 0);
    EXPECT_GE(r.rate->frames_in_flight, RateControlOptions{}.min_frames_in_flight);
    EXPECT_LE(r.rate->frames_in_flight, RateControlOptions{}.max_frames_in_flight);
    EXPECT_GT(r.reply.stream_bytes_received(), previous_bytes) << "sequence " << r.sequence;
    previous_bytes = r.reply.stream_bytes_received();
    EXPECT_GT(r.reply.receive_time_unix_ns(), 0);
  }
  EXPECT_GT(answered, 0);
  ASSERT_TRUE(stream->rate().has_value());
  // Sent as fast as Send is called: the window held most of them back, replaced.
  EXPECT_GT(stream->frames_replaced(), 0u);
}

// The replies start capped at the controller's starting bitrate over the camera's frame rate,
// from the camera's second frame, before any reply has come back (docs/links.md, round seven):
// frames sent as fast as Send returns make a high frame rate, so a cap at the floor
// (ReplyCapFollower::kMinCapBytes) that these clouds cannot meet; the server says so on each reply
// after it. Before, no cap came until the downlink showed overuse, which loopback never does.
TEST_F(ClientTest, RateControlCapsTheRepliesFromTheStart) {
  const SyntheticFrame f = Render(320, 240, 4);
  StreamConfig config = MakeStreamConfig(OptionsFor(f.camera, 0.03f));
  StreamOptions options;
  options.rate_control = RateControlOptions{};
  std::unique_ptr<Stream> stream = Open(config, std::move(options));
  ASSERT_NE(stream, nullptr);
  constexpr int kFrames = 10;
  const std::vector<Result> results = SendAll(*stream, f, kFrames);
  int over_cap = 0;
  for (const Result& r : results) {
    if (r.fate != FrameFate::kAnswered || r.sequence < 2) continue;
    ASSERT_TRUE(r.rate.has_value()) << "sequence " << r.sequence;
    EXPECT_GT(r.rate->reply_target_bps, 0) << "sequence " << r.sequence;
    if (r.reply.has_over_cap()) ++over_cap;
  }
  EXPECT_GT(over_cap, 0) << "no reply after the camera's second frame was capped";
}

TEST_F(ClientTest, DestroyingAnUnfinishedStreamCancelsIt) {
  const SyntheticFrame f = Render(160, 120, 6);
  std::unique_ptr<Stream> stream = Open(ConfigFor(OptionsFor(f.camera)));
  ASSERT_NE(stream, nullptr);
  ASSERT_TRUE(stream->Send(f.disparity_view(), f.colour_view()).ok());
  stream.reset();  // must neither hang nor crash
  // The server is still fine for the next caller.
  EXPECT_TRUE(client_->GetInfo().ok());
}

TEST_F(ClientTest, StreamOutlivesItsClient) {
  const SyntheticFrame f = Render(160, 120, 7);
  std::unique_ptr<Stream> stream = Open(ConfigFor(OptionsFor(f.camera, 0.05f)));
  ASSERT_NE(stream, nullptr);
  client_.reset();
  ASSERT_TRUE(stream->Send(f.disparity_view(), f.colour_view()).ok());
  Result r;
  ASSERT_TRUE(stream->Read(&r));
  EXPECT_TRUE(r.ok()) << r.status;
  EXPECT_GT(r.cloud.size(), 0u);
  EXPECT_TRUE(stream->Finish().ok());
}

TEST_F(ClientTest, CancelEndsABlockedRead) {
  std::unique_ptr<Stream> stream = Open(StreamConfig());
  ASSERT_NE(stream, nullptr);
  // The canceller acts once this thread is inside Read and asleep in the kernel (a blocked call
  // announces nothing, so its thread's state is polled).
  const pid_t reader = testing::CurrentThreadId();
  std::atomic<bool> reading{false};
  std::atomic<bool> seen_blocked{false};
  std::thread canceller([&] {
    seen_blocked =
        testing::Eventually([&] { return reading.load() && testing::ThreadIsBlocked(reader); });
    stream->Cancel();
  });
  Result r;
  reading.store(true);
  EXPECT_FALSE(stream->Read(&r));  // nothing was sent: only the cancel ends this
  canceller.join();
  EXPECT_TRUE(seen_blocked.load()) << "the Read never blocked";
  EXPECT_EQ(stream->Finish().code(), absl::StatusCode::kCancelled);
}

TEST_F(ClientTest, DecodingCanBeSwitchedOff) {
  ClientOptions options;
  options.decode_clouds = false;
  absl::StatusOr<std::unique_ptr<Client>> c = Client::Connect(shared_target(), options);
  ASSERT_TRUE(c.ok()) << c.status();
  const SyntheticFrame f = Render(160, 120, 1);
  absl::StatusOr<Result> r =
      (*c)->Process(f.disparity_view(), f.colour_view(), ConfigFor(OptionsFor(f.camera, 0.05f)));
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_TRUE(r->cloud.empty());
  EXPECT_GT(r->reply.point_count(), 0u);
  EXPECT_GT(r->draco_bytes(), 0u);
}

// ---------------------------------------------------------------------------------------------
// New Tsukuba: the real frames, read as a robot would (cv::imread; the colour PNGs are RGBA, so
// this also exercises the BGRA path), against the pipeline on core's own image loading.

TEST_F(ClientTest, TsukubaProcessAndStreamEqualThePipeline) {
  CLOUDCAST_REQUIRE_TSUKUBA();
  const std::vector<std::string> ids = {"00001", "00600", "01200"};
  const PipelineOptions options = OptionsFor(CameraModel::PclCompatible(640, 480), 0.03f);
  std::unique_ptr<Stream> stream = Open(ConfigFor(options));
  ASSERT_NE(stream, nullptr);
  std::vector<PointCloud> references;
  for (const std::string& id : ids) {
    SCOPED_TRACE(id);
    const std::string dpath = cloudcast::testing::TsukubaDisparityPath(id);
    const std::string cpath = cloudcast::testing::TsukubaColourPath(id);
    absl::StatusOr<OwnedDisparity> d = LoadDisparity(dpath);
    absl::StatusOr<OwnedColor> c = LoadColor(cpath);
    ASSERT_TRUE(d.ok() && c.ok()) << d.status() << c.status();
    references.push_back(Reference(options, d->view(), c->view()));

    const cv::Mat disparity = cv::imread(dpath, cv::IMREAD_UNCHANGED);
    const cv::Mat colour = cv::imread(cpath, cv::IMREAD_UNCHANGED);
    ASSERT_EQ(disparity.type(), CV_8UC1);
    ASSERT_FALSE(colour.empty());
    absl::StatusOr<Result> r = ProcessMats(*client_, disparity, colour, ConfigFor(options));
    ASSERT_TRUE(r.ok()) << r.status();
    EXPECT_TRUE(MatchesWithinBound(references.back(), r->cloud, r->reply.position_error_bound()));

    FrameMeta meta;
    meta.frame_id = id;
    ASSERT_TRUE(SendMats(*stream, disparity, colour, meta).ok());
  }
  for (std::size_t i = 0; i < ids.size(); ++i) {
    Result r;
    ASSERT_TRUE(stream->Read(&r));
    ASSERT_TRUE(r.ok()) << r.status;
    EXPECT_EQ(r.frame_id, ids[i]);
    EXPECT_TRUE(MatchesWithinBound(references[i], r.cloud, r.reply.position_error_bound()));
  }
  EXPECT_TRUE(stream->Finish().ok());
}

}  // namespace
}  // namespace cloudcast::client
