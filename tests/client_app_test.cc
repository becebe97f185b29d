// Tests of cloudcast-client: its statistics and session in-process (its frame sources are
// cloudcast_sources, tested by sources_test), and the real binary against an in-process server
// on a loopback port: the live viewer's snapshot under Xvfb (visible and hidden window), --record
// in every format checked against the server's own replies, --no-window statistics and JSON,
// --open of cloudcast-process output, and the errors of bad flags and files.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <future>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <random>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/match.h"
#include "app/session.h"
#include "app/stats.h"
#include "app/viewer.h"
#include "cloudcast/client/client.h"
#include "cloudcast/client/opencv.h"
#include "cloudcast/core/stereo.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/io/cloud_io.h"
#include "cloudcast/sources/frame_source.h"
#include "support/mats.h"
#include "support/program_support.h"
#include "support/server_fixture.h"
#include "support/test_support.h"
#include "support/xvfb_support.h"

namespace cloudcast::client::app {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

// ---------------------------------------------------------------------------------------------
// Helpers

// A fresh folder per test, removed afterwards.
using TempDirTest = cloudcast::testing::ScratchDirTest;
using cloudcast::testing::SameMat;
using cloudcast::testing::TestColour;
using cloudcast::testing::TestDisparity8;
using cloudcast::testing::WriteVideo;
using sources::LimitFrames;
using sources::OpenSynthetic;
using sources::OpenTsukuba;
using sources::SourceOptions;
using sources::Uplink;

TEST(ClientStatsTest, PercentilesAndCounts) {
  std::vector<double> v;
  for (int i = 1; i <= 100; ++i) v.push_back(101 - i);
  EXPECT_EQ(Percentile(v, 50), 50);
  EXPECT_EQ(Percentile(v, 90), 90);
  EXPECT_EQ(Percentile(v, 99), 99);
  EXPECT_EQ(Percentile(v, 100), 100);
  EXPECT_EQ(Percentile({}, 50), 0);

  StreamStats stats;
  for (int i = 0; i < 4; ++i) stats.RecordSent(1000);
  Result ok;
  ok.capture_time_unix_ns = 1'000'000'000;
  ok.times.receive_unix_ns = 1'000'000'000 + 5'000'000;  // 5 ms
  ok.times.receive = std::chrono::steady_clock::now();
  ok.reply.set_point_count(100);
  ok.reply.set_draco(std::string(50, 'x'));
  ok.frames_dropped = 1;
  stats.RecordResult(ok);
  Result error;
  error.status = absl::InvalidArgumentError("frame.disparity: bad");
  error.frames_dropped = 2;
  stats.RecordResult(error);
  Result config;
  config.status = absl::InvalidArgumentError("config.voxel_grid.leaf: bad");
  config.config_rejected = true;
  stats.RecordResult(config);

  const StatsSnapshot s = stats.Snapshot();
  EXPECT_EQ(s.sent, 4u);
  EXPECT_EQ(s.received, 1u);
  EXPECT_EQ(s.errors, 1u);  // the config error is not a frame
  EXPECT_EQ(s.dropped, 2u);
  EXPECT_EQ(s.points, 100u);
  EXPECT_EQ(s.draco_bytes, 50u);
  EXPECT_NEAR(s.latency_p50_ms, 5.0, 1e-9);
  const Json j = Json::parse(StreamStats::ToJson(s, false).dump());
  EXPECT_EQ(j["frames"]["sent"], 4);
  EXPECT_EQ(j["frames"]["errors"], 1);
  EXPECT_DOUBLE_EQ(j["latency_ms"]["p99"].get<double>(), 5.0);
  EXPECT_DOUBLE_EQ(j["mean_points_per_frame"].get<double>(), 100.0);
}

Result CloudResult(std::uint64_t sequence, std::size_t points) {
  Result r;
  r.sequence = sequence;
  r.cloud.ResizeUnorganized(points);
  return r;
}

TEST(CloudMailboxTest, ReplacePolicyKeepsTheNewestAndCountsTheRest) {
  CloudMailbox mailbox(/*wait_for_viewer=*/false);
  for (std::uint64_t i = 0; i < 3; ++i) {
    Result r = CloudResult(i, 10 + i);
    mailbox.Put(r);
  }
  PointCloud cloud;
  CloudMeta meta;
  ASSERT_TRUE(mailbox.Take(&cloud, &meta, std::chrono::milliseconds(0)));
  EXPECT_EQ(meta.sequence, 2u);
  EXPECT_EQ(cloud.size(), 12u);
  EXPECT_EQ(mailbox.skipped(), 2u);
  EXPECT_FALSE(mailbox.Take(&cloud, &meta, std::chrono::milliseconds(1)));
  Result error;
  error.status = absl::InvalidArgumentError("bad frame");
  mailbox.Put(error);  // errors carry no cloud
  EXPECT_FALSE(mailbox.has_new());
}

TEST(CloudMailboxTest, WaitPolicyHoldsTheReceiverUntilTheViewerTakes) {
  CloudMailbox mailbox(/*wait_for_viewer=*/true);
  std::atomic<int> put{0};
  std::thread receiver([&] {
    for (std::uint64_t i = 0; i < 4; ++i) {
      Result r = CloudResult(i, 5);
      mailbox.Put(r);
      ++put;
    }
  });
  // The mailbox tells when a Put has had to wait (the 10 s only turn a hang into a failure).
  // EXPECT, not ASSERT: the receiver must be released and joined whatever happens.
  constexpr std::chrono::seconds kHang(10);
  EXPECT_TRUE(mailbox.WaitForPutsHeld(1, kHang));
  EXPECT_EQ(put.load(), 1);  // the second Put waits for the first cloud to be taken
  PointCloud cloud;
  CloudMeta meta;
  EXPECT_TRUE(mailbox.Take(&cloud, &meta, std::chrono::milliseconds(1000)));
  EXPECT_EQ(meta.sequence, 0u);
  EXPECT_TRUE(mailbox.WaitForPutsHeld(2, kHang));
  EXPECT_EQ(put.load(), 2);  // the second went in; the third waits
  EXPECT_TRUE(mailbox.Take(&cloud, &meta, std::chrono::milliseconds(1000)));
  EXPECT_EQ(meta.sequence, 1u);
  EXPECT_TRUE(mailbox.WaitForPutsHeld(3, kHang));
  EXPECT_EQ(put.load(), 3);  // the fourth waits behind the third
  mailbox.Close();           // the viewer is gone: the waiting Put must not hang
  receiver.join();
  EXPECT_EQ(put.load(), 4);
  EXPECT_EQ(mailbox.skipped(), 0u);
}

// ---------------------------------------------------------------------------------------------
// The session in-process, against a loopback server.

class ClientSessionTest : public testing::SharedServer<TempDirTest> {};

TEST_F(ClientSessionTest, SessionPacesFramesAndAnswersEveryOneLosslessly) {
  auto source = LimitFrames(*OpenSynthetic(160, 120), 8);
  SessionOptions options;
  options.server = shared_target();
  options.fps = 20;
  options.config.set_delivery(v1::DELIVERY_ALL);
  StreamStats stats;
  std::vector<std::uint64_t> sequences;
  std::vector<std::size_t> points;
  auto session = Session::Start(options, source.get(), &stats, [&](Result& r) {
    EXPECT_TRUE(r.ok()) << r.status;
    sequences.push_back(r.sequence);
    points.push_back(r.cloud.size());
  });
  ASSERT_TRUE(session.ok()) << session.status();
  EXPECT_TRUE((*session)->Wait().ok());
  EXPECT_EQ(sequences, (std::vector<std::uint64_t>{0, 1, 2, 3, 4, 5, 6, 7}));
  for (std::size_t n : points) EXPECT_GT(n, 0u);
  const StatsSnapshot s = stats.Snapshot();
  EXPECT_EQ(s.sent, 8u);
  EXPECT_EQ(s.received, 8u);
  EXPECT_EQ(s.errors, 0u);
  EXPECT_GT(s.latency_p50_ms, 0);
}

TEST_F(ClientSessionTest, SessionPaceHoldsFramesBackUntilTheirTime) {
  // At one frame per 1000 s the first frame goes at once and the second waits for its time,
  // although the in-flight window (2) has room and the first is answered: stopping the session
  // then leaves exactly one frame sent. (Unpaced, the second goes with the first.)
  auto source = LimitFrames(*OpenSynthetic(160, 120), 8);
  SessionOptions options;
  options.server = shared_target();
  options.fps = 0.001;
  options.config.set_delivery(v1::DELIVERY_ALL);
  StreamStats stats;
  std::promise<void> first_answered;
  bool answered = false;  // the receiving thread's own
  auto session = Session::Start(options, source.get(), &stats, [&](Result& r) {
    EXPECT_TRUE(r.ok()) << r.status;
    if (!answered) first_answered.set_value();
    answered = true;
  });
  ASSERT_TRUE(session.ok()) << session.status();
  // The 60 s only turn a hang into a failure.
  EXPECT_EQ(first_answered.get_future().wait_for(std::chrono::seconds(60)),
            std::future_status::ready);
  EXPECT_FALSE((*session)->done());
  (*session)->Stop();
  EXPECT_TRUE((*session)->Wait().ok());
  const StatsSnapshot s = stats.Snapshot();
  EXPECT_EQ(s.sent, 1u);
  EXPECT_EQ(s.received, 1u);
}

TEST_F(ClientSessionTest, SessionSendsEncodedImages) {
  for (Uplink encoding : {Uplink::kPng, Uplink::kJpeg}) {
    SCOPED_TRACE(Name(encoding));
    auto source = LimitFrames(*OpenSynthetic(160, 120), 3);
    SessionOptions options;
    options.server = shared_target();
    options.uplink.encoding = encoding;
    options.config.set_delivery(v1::DELIVERY_ALL);
    StreamStats stats;
    auto session = Session::Start(options, source.get(), &stats, nullptr);
    ASSERT_TRUE(session.ok()) << session.status();
    EXPECT_TRUE((*session)->Wait().ok());
    const StatsSnapshot s = stats.Snapshot();
    EXPECT_EQ(s.received, 3u);
    EXPECT_EQ(s.errors, 0u);
    EXPECT_GT(s.points, 0u);
    // Encoded frames are smaller than raw ones (float disparity + BGR: 7 bytes per pixel).
    EXPECT_LT(s.uplink_bytes / 3, 160u * 120u * 7u);
  }
}

// --encoding h264: the colour images go as H.264 pictures (the first an IDR), in a fraction of
// the raw bytes, and every frame is answered with a cloud.
TEST_F(ClientSessionTest, SessionSendsH264Colour) {
  auto source = LimitFrames(*OpenSynthetic(160, 120), 5);
  SessionOptions options;
  options.server = shared_target();
  options.uplink.encoding = Uplink::kRaw;
  video::FrameEncoderOptions video;
  video.encoder.crf = 20;
  options.video = video;
  options.config.set_delivery(v1::DELIVERY_ALL);
  StreamStats stats;
  std::vector<std::uint64_t> keyframe_requests;
  auto session = Session::Start(options, source.get(), &stats, [&](client::Result& r) {
    keyframe_requests.push_back(static_cast<std::uint64_t>(r.reply.keyframe_needed_size()));
  });
  ASSERT_TRUE(session.ok()) << session.status();
  EXPECT_TRUE((*session)->Wait().ok());
  const StatsSnapshot s = stats.Snapshot();
  EXPECT_EQ(s.received, 5u);
  EXPECT_EQ(s.errors, 0u);
  EXPECT_GT(s.points, 0u);
  EXPECT_EQ(keyframe_requests, std::vector<std::uint64_t>(5, 0));
  // The colour (3 bytes a pixel) shrinks to H.264 pictures, and the disparity (float: 4 bytes a
  // pixel) goes lossless, zstd: both together under 2 bytes a pixel, less than the raw disparity
  // alone (it went raw before; cloudcast-load and the bridges already sent it zstd).
  EXPECT_LT(s.uplink_bytes / 5, 160u * 120u * 2u);
}

// --rate-control --encoding h264: the stream encodes each frame when it can send it, at the rate
// controller's target (less the raw disparity's share, capped by the encoder's bitrate), so under
// DELIVERY_LATEST no picture is lost and no reply is an error or asks for a keyframe.
TEST_F(ClientSessionTest, SessionSendsH264UnderRateControl) {
  auto source = LimitFrames(*OpenSynthetic(160, 120), 20);
  SessionOptions options;
  options.server = shared_target();
  options.uplink.encoding = Uplink::kRaw;
  video::FrameEncoderOptions video;
  video.encoder.crf = 20;
  video.encoder.bitrate_bps = 2'000'000;
  video.encoder.keyframe_interval = 0;
  options.video = video;
  options.rate_control = client::RateControlOptions{};
  options.config.set_delivery(v1::DELIVERY_LATEST);
  StreamStats stats;
  std::uint64_t keyframe_requests = 0, rates = 0;
  auto session = Session::Start(options, source.get(), &stats, [&](client::Result& r) {
    keyframe_requests += r.keyframe_needed.size();
    if (r.rate) ++rates;
  });
  ASSERT_TRUE(session.ok()) << session.status();
  EXPECT_TRUE((*session)->Wait().ok());
  const StatsSnapshot s = stats.Snapshot();
  EXPECT_GT(s.received, 0u);
  EXPECT_EQ(s.errors, 0u);
  EXPECT_EQ(keyframe_requests, 0u);
  EXPECT_EQ(rates, s.received);
}

TEST_F(ClientSessionTest, SessionReportsAnUnreachableServer) {
  auto source = OpenSynthetic(16, 16);
  SessionOptions options;
  options.server = "127.0.0.1:1";
  options.connect_timeout = std::chrono::milliseconds(300);
  StreamStats stats;
  auto session = Session::Start(options, source->get(), &stats, nullptr);
  ASSERT_FALSE(session.ok());
  EXPECT_EQ(session.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(session.status().message().find("--server 127.0.0.1:1"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// The cloudcast-client binary.

using cloudcast::testing::BinDir;
using cloudcast::testing::ReadText;
using cloudcast::testing::RunResult;
using cloudcast::testing::ShellQuote;

// Counts what a snapshot shows: pixels that differ from the background (the corner pixel below
// the overlay) and distinct colours among them.
struct PictureStats {
  int foreground = 0;
  std::size_t colours = 0;
};
PictureStats Analyse(const std::string& png) {
  PictureStats s;
  const cv::Mat image = cv::imread(png, cv::IMREAD_COLOR);
  if (image.empty()) return s;
  const cv::Vec3b background = image.at<cv::Vec3b>(image.rows - 1, image.cols - 1);
  std::set<std::uint32_t> colours;
  // The overlay's rows (top 40 pixels) are left out: text alone must not pass.
  for (int y = 40; y < image.rows; ++y) {
    for (int x = 0; x < image.cols; ++x) {
      const cv::Vec3b p = image.at<cv::Vec3b>(y, x);
      if (p == background) continue;
      ++s.foreground;
      colours.insert((p[0] >> 3) << 10 | (p[1] >> 3) << 5 | (p[2] >> 3));
    }
  }
  s.colours = colours.size();
  return s;
}

class ClientProgramTest : public ClientSessionTest {
 protected:
  void SetUp() override {
    ClientSessionTest::SetUp();
    ASSERT_TRUE(fs::exists(Binary())) << Binary() << " is missing: build cloudcast-client";
  }
  static std::string Binary() { return BinDir() + "/cloudcast-client"; }

  // Runs the client; `env` prefixes the command (e.g. "env -u DISPLAY").
  RunResult Run(const std::vector<std::string>& args, const std::string& env = "") const {
    return RunProgram(Binary(), args, env);
  }
  RunResult RunProgram(const std::string& binary, const std::vector<std::string>& args,
                       const std::string& env = "") const {
    return cloudcast::testing::RunProgram(binary, args, dir_.string(), env);
  }

  // The default input of the tests: the New Tsukuba folder when present, else the synthetic
  // scene (10 frames either way).
  static std::vector<std::string> SourceArgs() {
    if (cloudcast::testing::HaveTsukuba()) return {"--tsukuba", cloudcast::testing::TsukubaDir()};
    return {"--synthetic", "640x480", "--frames", "10"};
  }
  static std::vector<std::string> Join(std::vector<std::string> a,
                                       const std::vector<std::string>& b) {
    a.insert(a.end(), b.begin(), b.end());
    return a;
  }
};

TEST_F(ClientProgramTest, StreamsAndWritesANonTrivialSnapshot) {
  CLOUDCAST_REQUIRE_DISPLAY();
  if (!cloudcast::testing::HaveTsukuba()) {
    std::printf("[ info     ] New Tsukuba data not found: streaming the synthetic scene\n");
  }
  for (const bool hidden : {false, true}) {
    SCOPED_TRACE(hidden ? "hidden window" : "visible window");
    const std::string png = Path(hidden ? "hidden.png" : "visible.png");
    const std::string json = Path("view.json");
    // --lossless with --fps 0: no frame is dropped by the server, and the display paces the
    // stream (no cloud is replaced before it is drawn), so the 3rd cloud shown is the 3rd frame
    // whatever the machine's load. (Some New Tsukuba frames lie wholly outside the paper's
    // passthrough, z = 615 / d in [3, 12]: 00800 and 01800 give empty clouds, 00200 and 00600 a
    // few thousand points; 00400, the 3rd, gives 27,557.)
    std::vector<std::string> args =
        Join(SourceArgs(), {"--server", shared_target(), "--lossless", "--snapshot", png,
                            "--snapshot-after", "3", "--json", json, "--window", "640x480"});
    if (hidden) args.push_back("--hidden");
    const RunResult r = Run(args);
    ASSERT_TRUE(r.exited && r.code == 0) << r;
    ASSERT_TRUE(fs::exists(png)) << r;
    const PictureStats p = Analyse(png);
    EXPECT_GT(p.foreground, 640 * 440 / 20) << "too few points drawn in " << png;
    EXPECT_GT(p.colours, 20u) << "the points should carry the frame's colours";
    EXPECT_NE(r.err.find("snapshot written to"), std::string::npos) << r;
    const Json j = Json::parse(ReadText(json));
    EXPECT_EQ(j["frames"]["displayed"].get<int>(), 3);
    EXPECT_EQ(j["viewer_skipped"].get<int>(), 0);
    EXPECT_GT(j["displayed_fps"].get<double>(), 0);
  }
}

// A stream that ends on an empty cloud (its filters kept nothing) is pictured by its last cloud
// with points, and the log says so: an empty picture helps nobody.
TEST_F(ClientProgramTest, SnapshotAtAnEmptyEndShowsTheLastCloudWithPoints) {
  CLOUDCAST_REQUIRE_DISPLAY();
  fs::create_directories(dir_ / "d");
  fs::create_directories(dir_ / "c");
  // f1, f2: a tilted plane at disparities 60..90, inside the default passthrough (z = 615 / d in
  // [3, 12]); f3: no valid disparity at all.
  for (int i = 1; i <= 3; ++i) {
    cv::Mat d(120, 160, CV_8UC1, cv::Scalar(0));
    for (int y = 0; y < d.rows && i < 3; ++y) {
      for (int x = 0; x < d.cols; ++x) d.at<std::uint8_t>(y, x) = 60 + (x + y + i) % 31;
    }
    ASSERT_TRUE(cv::imwrite(Path("d/f" + std::to_string(i) + ".png"), d));
    ASSERT_TRUE(cv::imwrite(Path("c/f" + std::to_string(i) + ".png"), TestColour(160, 120, i)));
  }
  const std::string png = Path("end.png");
  const RunResult r = Run({"--disparity-glob", Path("d/*.png"), "--colour-glob", Path("c/*.png"),
                           "--camera-preset", "new_tsukuba", "--server", shared_target(),
                           "--lossless", "--hidden", "--snapshot", png, "--window", "640x480"});
  ASSERT_TRUE(r.exited && r.code == 0) << r;
  const PictureStats p = Analyse(png);
  EXPECT_GT(p.foreground, 640 * 440 / 20) << "the snapshot is empty: " << png;
  EXPECT_GT(p.colours, 20u);
  EXPECT_NE(r.err.find("the last cloud (frame f3) was empty: the snapshot shows frame f2"),
            std::string::npos)
      << r;
}

// The README's example on the New Tsukuba folder: at the paper's parameters (the server's
// defaults) its last frame, 01800, keeps no point, and 01600 before it under 2,000.
TEST_F(ClientProgramTest, SnapshotOfTheTsukubaFolderShowsItsLastCloudWithPoints) {
  CLOUDCAST_REQUIRE_DISPLAY();
  CLOUDCAST_REQUIRE_TSUKUBA();
  const std::string png = Path("tsukuba.png");
  const RunResult r =
      Run({"--tsukuba", cloudcast::testing::TsukubaDir(), "--server", shared_target(), "--lossless",
           "--hidden", "--snapshot", png, "--window", "640x480"});
  ASSERT_TRUE(r.exited && r.code == 0) << r;
  const PictureStats p = Analyse(png);
  // 01600's few hundred points, in the view the first cloud (00001) framed.
  EXPECT_GT(p.foreground, 200) << "the snapshot is empty: " << png;
  EXPECT_NE(r.err.find("the last cloud (frame tsukuba_01800) was empty: the snapshot shows "
                       "frame tsukuba_01600"),
            std::string::npos)
      << r;
}

TEST_F(ClientProgramTest, RecordedFilesHoldTheRepliesPointCounts) {
  // The reference: the same frames through the server one by one, with the same settings.
  auto reference_source =
      LimitFrames(cloudcast::testing::HaveTsukuba()
                      ? *OpenTsukuba(cloudcast::testing::TsukubaDir(), "daylight", SourceOptions{})
                      : *OpenSynthetic(640, 480),
                  10);
  ClientOptions client_options;
  auto client = Client::Connect(shared_target(), client_options);
  ASSERT_TRUE(client.ok()) << client.status();
  StreamConfig config;
  SetCamera(reference_source->info().camera, &config);
  config.mutable_camera()->clear_cx();
  config.mutable_camera()->clear_cy();
  std::vector<std::uint32_t> expected;
  sources::SourceFrame f;
  while (*reference_source->Next(&f)) {
    auto r = ProcessMats(**client, f.disparity(), f.colour(), config);
    ASSERT_TRUE(r.ok()) << r.status();
    expected.push_back(r->reply.point_count());
  }
  ASSERT_EQ(expected.size(), 10u);

  for (const std::string format : {"pcd", "ply", "drc"}) {
    SCOPED_TRACE(format);
    const std::string dir = Path("rec_" + format);
    const RunResult r = Run(
        Join(SourceArgs(), {"--server", shared_target(), "--no-window", "--lossless", "--record",
                            dir, "--record-format", format, "--json", Path("rec.json")}),
        "env -u DISPLAY");
    ASSERT_TRUE(r.exited && r.code == 0) << r;
    EXPECT_NE(r.out.find("recorded: 10 " + format + " files"), std::string::npos) << r;
    double total = 0;
    for (std::size_t i = 0; i < expected.size(); ++i) {
      char name[32];
      std::snprintf(name, sizeof(name), "cloud_%06zu.%s", i, format.c_str());
      PointCloud cloud;
      const absl::Status s = LoadCloud((fs::path(dir) / name).string(), &cloud);
      ASSERT_TRUE(s.ok()) << s;
      EXPECT_EQ(cloud.size(), expected[i]) << name;
      total += cloud.size();
    }
    const Json j = Json::parse(ReadText(Path("rec.json")));
    EXPECT_EQ(j["record"]["files"], 10);
    EXPECT_NEAR(j["mean_points_per_frame"].get<double>(), total / 10, 1e-9);
  }
}

TEST_F(ClientProgramTest, NoWindowPrintsStatisticsAndJson) {
  const std::string json = Path("stats.json");
  // No display at all: --no-window must not touch GL.
  const RunResult r = Run(Join(SourceArgs(), {"--server", shared_target(), "--no-window",
                                              "--lossless", "--json", json, "--progress", "0.05"}),
                          "env -u DISPLAY");
  ASSERT_TRUE(r.exited && r.code == 0) << r;
  EXPECT_NE(r.out.find("frames: sent 10, received 10, dropped 0, errors 0"), std::string::npos)
      << r;
  EXPECT_NE(r.out.find("latency (capture to reply, ms): p50"), std::string::npos) << r;
  EXPECT_NE(r.out.find("per cloud:"), std::string::npos) << r;
  const Json j = Json::parse(ReadText(json));
  EXPECT_EQ(j["status"], "ok");
  EXPECT_EQ(j["frames"]["sent"], 10);
  EXPECT_EQ(j["frames"]["received"], 10);
  EXPECT_EQ(j["frames"]["dropped"], 0);
  EXPECT_EQ(j["frames"]["errors"], 0);
  EXPECT_FALSE(j.contains("displayed_fps"));
  EXPECT_GT(j["fps"].get<double>(), 0);
  const double p50 = j["latency_ms"]["p50"], p90 = j["latency_ms"]["p90"],
               p99 = j["latency_ms"]["p99"];
  EXPECT_GT(p50, 0);
  EXPECT_LE(p50, p90);
  EXPECT_LE(p90, p99);
  EXPECT_GT(j["mean_points_per_frame"].get<double>(), 0);
  EXPECT_GT(j["mean_draco_bytes_per_frame"].get<double>(), 0);
  EXPECT_EQ(j["source"]["width"], 640);
}

// --rate-control: the progress lines carry the controller's target, round trip, queueing delay
// and the JPEG quality it set; with --lossless it is a usage error naming both flags.
TEST_F(ClientProgramTest, RateControlShowsItsTargetInTheProgressLines) {
  const RunResult r =
      Run(Join(SourceArgs(), {"--server", shared_target(), "--no-window", "--rate-control",
                              "--encoding", "jpeg", "--fps", "30", "--progress", "0.05"}),
          "env -u DISPLAY");
  ASSERT_TRUE(r.exited && r.code == 0) << r;
  const std::string all = r.out + r.err;
  EXPECT_NE(all.find("Mbit/s, rtt"), std::string::npos) << r;
  EXPECT_NE(all.find("JPEG quality"), std::string::npos) << r;
  // ... and the resolution the adaptive JPEG coder sent it at (half below quality 10).
  EXPECT_TRUE(std::regex_search(all, std::regex("JPEG quality [0-9]+ at (full|half) resolution")))
      << r;
  // With H.264 too: the encoder's bitrate follows the target, and no picture is lost.
  const RunResult h264 =
      Run(Join(SourceArgs(),
               {"--server", shared_target(), "--no-window", "--rate-control", "--encoding", "h264",
                "--h264-preset", "ultrafast", "--fps", "30", "--progress", "0.05"}),
          "env -u DISPLAY");
  ASSERT_TRUE(h264.exited && h264.code == 0) << h264;
  EXPECT_NE((h264.out + h264.err).find("Mbit/s, rtt"), std::string::npos) << h264;
  // The summary (stdout): "frames: sent N, received N, dropped N, errors 0".
  const std::size_t summary = h264.out.find("frames: sent");
  ASSERT_NE(summary, std::string::npos) << h264;
  const std::string line = h264.out.substr(summary, h264.out.find('\n', summary) - summary);
  EXPECT_TRUE(absl::EndsWith(line, "errors 0")) << line;
  const RunResult bad = Run(Join(SourceArgs(), {"--server", shared_target(), "--no-window",
                                                "--rate-control", "--lossless"}),
                            "env -u DISPLAY");
  EXPECT_EQ(bad.code, 2) << bad;
  EXPECT_NE((bad.out + bad.err).find("--rate-control"), std::string::npos) << bad;
  // The controller's settings (cli/rate_flags.h) need it.
  const RunResult orphan = Run(Join(SourceArgs(), {"--server", shared_target(), "--no-window",
                                                   "--rate-target-delay-ms", "15"}),
                               "env -u DISPLAY");
  EXPECT_EQ(orphan.code, 2) << orphan;
  EXPECT_NE((orphan.out + orphan.err).find("--rate-target-delay-ms needs --rate-control"),
            std::string::npos)
      << orphan;
}

TEST_F(ClientProgramTest, DefaultSourceIsTsukubaWhenPresentElseSynthetic) {
  const RunResult r = Run({"--server", shared_target(), "--no-window", "--frames", "3",
                           "--lossless", "--json", Path("default.json")},
                          "env -u DISPLAY");
  ASSERT_TRUE(r.exited && r.code == 0) << r;
  const Json j = Json::parse(ReadText(Path("default.json")));
  EXPECT_EQ(j["source"]["kind"], cloudcast::testing::HaveTsukuba() ? "tsukuba" : "synthetic");
  EXPECT_EQ(j["source"]["width"], 640);
  EXPECT_EQ(j["source"]["height"], 480);
  EXPECT_EQ(j["frames"]["received"], 3);
}

TEST_F(ClientProgramTest, OpensTheFilesCloudcastProcessWrites) {
  CLOUDCAST_REQUIRE_DISPLAY();
  const std::string process = BinDir() + "/cloudcast-process";
  ASSERT_TRUE(fs::exists(process)) << process << " is missing: build cloudcast-process";
  std::vector<std::string> input = {"--synthetic", "640x480"};
  if (cloudcast::testing::HaveTsukuba()) {
    input = {"--disparity", cloudcast::testing::TsukubaDisparityPath("00001"), "--colour",
             cloudcast::testing::TsukubaColourPath("00001")};
  }
  for (const std::string ext : {"pcd", "ply", "drc"}) {
    SCOPED_TRACE(ext);
    const std::string cloud = Path("frame." + ext);
    const RunResult made = RunProgram(process, Join(input, {"--out", cloud, "--quiet"}));
    ASSERT_TRUE(made.exited && made.code == 0) << made;
    const std::string png = Path("open_" + ext + ".png");
    const RunResult r =
        Run({"--open", cloud, "--snapshot", png, "--snapshot-after", "2", "--window", "640x480"});
    ASSERT_TRUE(r.exited && r.code == 0) << r;
    const PictureStats p = Analyse(png);
    EXPECT_GT(p.foreground, 640 * 440 / 20) << png;
    EXPECT_GT(p.colours, 20u) << png;
  }
}

TEST_F(ClientProgramTest, HelpDocumentsEveryFlagWithDefaults) {
  const RunResult r = Run({"--help"}, "env -u DISPLAY");
  ASSERT_TRUE(r.exited && r.code == 0) << r;
  for (const char* flag : {"--tsukuba",
                           "--illumination",
                           "--disparity-glob",
                           "--colour-glob",
                           "--disparity-video",
                           "--colour-video",
                           "--synthetic",
                           "--disparity",
                           "--colour",
                           "--open",
                           "--loop",
                           "--frames",
                           "--server",
                           "--connect-timeout",
                           "--fps",
                           "--in-flight",
                           "--lossless",
                           "--encoding",
                           "--jpeg-quality",
                           "--h264-preset",
                           "--h264-crf",
                           "--h264-mbps",
                           "--h264-keyframe-interval",
                           "--h264-threads",
                           "--h264-444",
                           "--h264-grey",
                           "--h264-separate-stereo",
                           "--h264-lossless",
                           "--h264-x264-params",
                           "--focal",
                           "--baseline",
                           "--disparity-scale",
                           "--axis",
                           "--min",
                           "--max",
                           "--negative",
                           "--no-passthrough",
                           "--leaf",
                           "--draco-bits",
                           "--draco-speed",
                           "--cap-min-points-per-voxel",
                           "--no-window",
                           "--window",
                           "--hidden",
                           "--point-size",
                           "--snapshot",
                           "--snapshot-after",
                           "--exit-at-end",
                           "--record",
                           "--record-format",
                           "--json",
                           "--progress",
                           "--quiet",
                           "--input",
                           "--depth-glob",
                           "--right-glob",
                           "--depth-video",
                           "--right-video",
                           "--depth",
                           "--right",
                           "--matcher",
                           "--min-disparity",
                           "--num-disparities",
                           "--block-size",
                           "--p1",
                           "--p2",
                           "--uniqueness-ratio",
                           "--speckle-window-size",
                           "--speckle-range",
                           "--disp12-max-diff",
                           "--paths",
                           "--return-disparity",
                           "Examples:"}) {
    EXPECT_NE(r.out.find(flag), std::string::npos) << flag;
  }
  for (const std::string& default_shown : std::vector<std::string>{
           "--server HOST:PORT=localhost:50051", "--fps FLOAT=0",
           "--in-flight INT:INT in [1 - 64]=2", "--leaf FLOAT=0.03", "--snapshot-after N=10",
           "--record-format TEXT:{pcd,ply,drc}=pcd",
           // The matcher's defaults are StereoParams{}'s.
           "--input TEXT:{disparity,depth,stereo}=disparity",
           "--num-disparities INT=" + std::to_string(StereoParams{}.num_disparities),
           "--block-size INT=" + std::to_string(StereoParams{}.block_size),
           "--matcher TEXT:{sgm,sgbm,sgbm-3way,hh,bm}=sgm"}) {
    EXPECT_NE(r.out.find(default_shown), std::string::npos) << default_shown;
  }
}

TEST_F(ClientProgramTest, BadFlagsAndFilesGiveClearErrors) {
  fs::create_directories(dir_ / "d");
  fs::create_directories(dir_ / "c");
  cv::imwrite(Path("d/1.png"), TestDisparity8(8, 6, 1));
  cv::imwrite(Path("d/2.png"), TestDisparity8(8, 6, 2));
  cv::imwrite(Path("c/1.png"), TestColour(8, 6, 1));
  struct Case {
    std::vector<std::string> args;
    int code;
    std::string message;  // in stderr
  };
  const std::vector<Case> cases = {
      {{"--frobnicate"}, 2, "--frobnicate"},
      {{"--fps", "fast"}, 2, "--fps"},
      {{"--fps", "nan"}, 2, "--fps"},
      {{"--synthetic", "0x5"}, 2, "--synthetic"},
      {{"--encoding", "webp"}, 2, "--encoding"},
      {{"--encoding", "h264", "--h264-preset", "placebo"}, 2, "--h264-preset"},
      {{"--encoding", "h264", "--h264-x264-params", "ref=4:bframes=3"},
       2,
       "--h264-x264-params: 'ref=4:bframes=3': 'bframes' is the encoder's own"},
      {{"--encoding", "h264", "--h264-x264-params", "ref=4;touch x"},
       2,
       "the character ';' is none of x264's"},
      {{"--encoding", "h264", "--h264-lossless", "--h264-crf", "10"}, 2, "--h264-lossless"},
      {{"--h264-lossless"}, 2, "--h264-lossless needs --encoding h264"},
      {{"--record-format", "xyz"}, 2, "--record-format"},
      {{"--min", "5", "--max", "1"}, 2, "--min (5) must not exceed --max (1)"},
      {{"--synthetic", "64x48", "--tsukuba", "x"}, 2, "choose one source"},
      {{"--disparity-glob", "d/*.png"}, 2, "needs --colour-glob"},
      {{"--input", "lidar"}, 2, "--input"},
      {{"--input", "stereo", "--colour-glob", "c/*.png"}, 2, "needs --right-glob (--input stereo)"},
      {{"--depth-glob", "d/*.png", "--colour-glob", "c/*.png"},
       2,
       "--depth-glob does not apply to --input disparity (it takes --disparity-glob and "
       "--colour-glob)"},
      {{"--right", "r.png"}, 2, "--right does not apply to --input disparity"},
      {{"--matcher", "sgbm"}, 2, "--matcher applies to --input stereo only"},
      {{"--input", "depth", "--block-size", "7"}, 2, "--block-size applies to --input stereo"},
      {{"--input", "stereo", "--num-disparities", "100"}, 2, "--num-disparities is 100"},
      {{"--input", "stereo", "--matcher", "bm", "--block-size", "3"}, 2, "--block-size is 3"},
      {{"--input", "stereo", "--matcher", "census"}, 2, "--matcher"},
      {{"--open", Path("x.pcd"), "--input", "depth"}, 2, "--input does not apply to --open"},
      {{"--input", "depth", "--depth", Path("d/1.png"), "--colour", Path("c/1.png"), "--no-window"},
       1,
       "--depth: depth image"},
      {{"--no-window", "--snapshot", Path("a.png")}, 2, "--snapshot needs a window"},
      {{"--snapshot", Path("a.jpg")}, 2, "must end in .png"},
      {{"--json", Path("no/such/dir/x.json"), "--no-window"}, 2, "does not exist"},
      {{"--open", Path("x.pcd"), "--fps", "3"}, 2, "--fps does not apply to --open"},
      {{"--tsukuba", Path("missing"), "--no-window"}, 1, "--tsukuba: no folder"},
      {{"--disparity-glob", Path("d/*.png"), "--colour-glob", Path("c/*.png"), "--no-window"},
       1,
       "matches 2 files but --colour-glob"},
      {{"--disparity", Path("d/1.png"), "--colour", Path("c/none.png"), "--no-window"},
       1,
       "c/none.png"},
      {{"--synthetic", "64x48", "--no-window", "--server", "127.0.0.1:1", "--connect-timeout",
        "0.3"},
       1,
       "--server 127.0.0.1:1"},
      {{"--open", Path("none.pcd")}, 1, "none.pcd"},
      {{"--open", Path("d/1.png")}, 1, ".pcd, .ply, .drc"},
  };
  for (const Case& c : cases) {
    std::string line;
    for (const std::string& a : c.args) line += a + " ";
    SCOPED_TRACE(line);
    const RunResult r = Run(c.args, "env -u DISPLAY");
    ASSERT_TRUE(r.exited) << r;
    EXPECT_EQ(r.code, c.code) << r;
    EXPECT_NE(r.err.find(c.message), std::string::npos) << r;
  }
}

// Every --input through the shared server, headless: the clouds come back, the summary and the
// JSON say which input went, and a stereo pair's lines carry the server's match time. New
// Tsukuba's depth frames are its ground-truth disparity converted, so they give the disparity
// frames' clouds.
TEST_F(ClientProgramTest, StreamsEveryInputKind) {
  std::vector<std::string> source = {"--synthetic", "320x240"};
  if (cloudcast::testing::HaveTsukuba()) source = {"--tsukuba", cloudcast::testing::TsukubaDir()};
  std::map<std::string, double> points;
  for (const std::string input : {"disparity", "depth", "stereo"}) {
    SCOPED_TRACE(input);
    const std::string json = Path(input + ".json");
    const RunResult r =
        Run(Join(source, {"--input", input, "--server", shared_target(), "--no-window", "--frames",
                          "3", "--lossless", "--print-frames", "--progress", "0", "--json", json}),
            "env -u DISPLAY");
    ASSERT_TRUE(r.exited && r.code == 0) << r;
    EXPECT_NE(r.out.find("frames: sent 3, received 3, dropped 0, errors 0"), std::string::npos)
        << r;
    EXPECT_NE(r.out.find("input: " + input), std::string::npos) << r;
    EXPECT_EQ(r.out.find("  rectify ") != std::string::npos, input == "stereo") << r;
    EXPECT_EQ(r.out.find("  match ") != std::string::npos, input == "stereo") << r;
    const Json j = Json::parse(ReadText(json));
    EXPECT_EQ(j["source"]["input"], input);
    EXPECT_EQ(j["frames"]["errors"], 0);
    points[input] = j["mean_points_per_frame"].get<double>();
    EXPECT_GT(points[input], 1000) << input;
  }
  if (cloudcast::testing::HaveTsukuba()) {
    // The same z = f * b / d on both sides; float rounding may move a point across a voxel edge.
    EXPECT_NEAR(points["depth"], points["disparity"], 0.01 * points["disparity"]);
  }
}

// --h264-lossless: stereo pairs coded grey at qp 0 (with x264 options of the user's) reach the
// server's matcher exactly as the raw pairs' grey: the same disparities, so as many points in
// every cloud (a near-lossless CRF changes the count).
TEST_F(ClientProgramTest, LosslessH264StereoPairsGiveTheRawPairsClouds) {
  std::map<std::string, Json> runs;
  for (const std::string mode : {"raw", "h264"}) {
    SCOPED_TRACE(mode);
    const std::string json = Path("lossless_" + mode + ".json");
    std::vector<std::string> args = {"--synthetic", "320x240", "--input", "stereo", "--server",
                                     shared_target(), "--no-window", "--frames", "4", "--lossless",
                                     "--progress", "0", "--json", json};
    if (mode == "h264") {
      args = Join(args, {"--encoding", "h264", "--h264-lossless", "--h264-grey",
                         "--h264-preset", "superfast", "--h264-x264-params",
                         "partitions=all:ref=4"});
    }
    const RunResult r = Run(args, "env -u DISPLAY");
    ASSERT_TRUE(r.exited && r.code == 0) << r;
    EXPECT_NE(r.out.find("frames: sent 4, received 4, dropped 0, errors 0"), std::string::npos)
        << r;
    runs[mode] = Json::parse(ReadText(json));
  }
  EXPECT_GT(runs["raw"]["mean_points_per_frame"].get<double>(), 1000);
  // (Their Draco bytes differ: the points are grey.)
  EXPECT_EQ(runs["h264"]["mean_points_per_frame"], runs["raw"]["mean_points_per_frame"]);
}

// A stereo pair given as files (a glob per camera), with the matcher tuned and the disparity
// map asked back: every frame is matched.
TEST_F(ClientProgramTest, StreamsStereoGlobsWithMatcherFlags) {
  fs::create_directories(dir_ / "l");
  fs::create_directories(dir_ / "r");
  auto synthetic =
      sources::OpenSynthetic(320, 240, DisparityEncoding::kF32, sources::FrameKind::kStereo);
  ASSERT_TRUE(synthetic.ok()) << synthetic.status();
  for (int i = 0; i < 2; ++i) {
    sources::SourceFrame pair;
    ASSERT_TRUE(*(*synthetic)->Next(&pair));
    cv::imwrite(Path("l/" + std::to_string(i) + ".png"), pair.colour());
    cv::imwrite(Path("r/" + std::to_string(i) + ".png"), pair.right());
  }
  const RunResult r = Run({"--input",
                           "stereo",
                           "--colour-glob",
                           Path("l/*.png"),
                           "--right-glob",
                           Path("r/*.png"),
                           "--matcher",
                           "sgbm",
                           "--num-disparities",
                           "64",
                           "--block-size",
                           "5",
                           "--return-disparity",
                           "--focal",
                           "307.5",  // the synthetic camera's at 320 px
                           "--baseline",
                           std::to_string(kSyntheticStereoBaseline),
                           "--server",
                           shared_target(),
                           "--no-window",
                           "--lossless",
                           "--print-frames",
                           "--progress",
                           "0"},
                          "env -u DISPLAY");
  ASSERT_TRUE(r.exited && r.code == 0) << r;
  EXPECT_NE(r.out.find("frames: sent 2, received 2, dropped 0, errors 0"), std::string::npos) << r;
  EXPECT_NE(r.out.find("(+ disparity map)"), std::string::npos) << r;
}

// The robot example: --help, a bad --input named, and every kind's frames answered with clouds
// (the synthetic scene as each kind; a stereo pair's replies carry the server's match time).
TEST_F(ClientProgramTest, RobotExampleSendsEveryInputKind) {
  const std::string example = BinDir() + "/cloudcast-robot-example";
  if (!fs::exists(example)) GTEST_SKIP() << example << " is not built";
  const RunResult help = RunProgram(example, {"--help"});
  ASSERT_TRUE(help.exited && help.code == 0) << help;
  EXPECT_NE(help.out.find("--input KIND"), std::string::npos) << help;
  const RunResult bad = RunProgram(example, {"--input", "lidar"});
  EXPECT_EQ(bad.code, 2) << bad;
  EXPECT_NE(bad.err.find("--input must be disparity, depth or stereo"), std::string::npos) << bad;
  const RunResult misplaced = RunProgram(example, {"--matcher", "sgbm"});
  EXPECT_EQ(misplaced.code, 2) << misplaced;
  EXPECT_NE(misplaced.err.find("--matcher applies to --input stereo only"), std::string::npos)
      << misplaced;
  for (const std::string input : {"disparity", "depth", "stereo"}) {
    SCOPED_TRACE(input);
    std::vector<std::string> args = {"--input", input, shared_target(), "2"};
    if (input == "stereo") args.insert(args.begin(), {"--matcher", "sgm"});
    const RunResult r = RunProgram(example, args);
    ASSERT_TRUE(r.exited && r.code == 0) << r;
    EXPECT_NE(r.out.find("frame 1: "), std::string::npos) << r;
    EXPECT_EQ(r.out.find(" 0 points"), std::string::npos) << r;
    EXPECT_EQ(r.out.find("server matched the pair") != std::string::npos, input == "stereo") << r;
    EXPECT_NE(r.out.find("stream finished: OK"), std::string::npos) << r;
  }
}

TEST_F(ClientProgramTest, StreamsLosslessVideos) {
  std::vector<cv::Mat> disparities, colours;
  for (int i = 0; i < 6; ++i) {
    cv::Mat d(120, 160, CV_8UC1);
    // A tilted plane at disparities 60..90: z = 615 / d lies inside the default passthrough.
    for (int y = 0; y < d.rows; ++y) {
      for (int x = 0; x < d.cols; ++x) d.at<std::uint8_t>(y, x) = 60 + (x + y + i) % 31;
    }
    disparities.push_back(d);
    colours.push_back(TestColour(160, 120, i));
  }
  if (!WriteVideo(Path("d.mkv"), "FFV1", disparities) ||
      !WriteVideo(Path("c.mkv"), "FFV1", colours)) {
    GTEST_SKIP() << "this OpenCV build cannot write FFV1";
  }
  const RunResult r =
      Run({"--disparity-video", Path("d.mkv"), "--colour-video", Path("c.mkv"), "--camera-preset",
           "new_tsukuba", "--server", shared_target(), "--no-window", "--lossless", "--loop",
           "--frames", "15", "--json", Path("v.json")},
          "env -u DISPLAY");
  ASSERT_TRUE(r.exited && r.code == 0) << r;
  EXPECT_EQ(r.err.find("not known to be lossless"), std::string::npos) << r;
  const Json j = Json::parse(ReadText(Path("v.json")));
  EXPECT_EQ(j["source"]["kind"], "video");
  EXPECT_EQ(j["frames"]["received"], 15);
  EXPECT_EQ(j["frames"]["errors"], 0);
  EXPECT_GT(j["mean_points_per_frame"].get<double>(), 100);
}

}  // namespace
}  // namespace cloudcast::client::app
