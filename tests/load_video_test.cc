// cloudcast-load's video uplink (--encoding h264, issue 27): the prepared picture sequence, video
// streams against a real server that never see a keyframe request or a frame error (colour and
// stereo pairs, DELIVERY_ALL and DELIVERY_LATEST, the sequence looping at its IDR), a stream that
// answers the server's keyframe request by going back to its IDR, no picture ever replaced under
// overload, and the --h264-* flags' errors. Counts only, never times.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cloudcast/load/fleet.h"
#include "cloudcast/load/frame_store.h"
#include "cloudcast/load/null_server.h"
#include "cloudcast/load/report.h"
#include "support/frame_store_requests.h"
#include "support/program_support.h"
#include "support/server_fixture.h"
#include "support/test_support.h"

namespace cloudcast::load {
namespace {

using nlohmann::json;
using std::chrono::seconds;
using testing::RunResult;

// The request of frame `index` of `store`, parsed back.
v1::StreamRequest Parsed(const FrameStore& store, std::size_t index) {
  return testing::ParsedRequest(store, index, index + 1, 1);
}

FrameSourceOptions SyntheticVideo(std::uint32_t w, std::uint32_t h, int frames,
                                  sources::FrameKind kind, int keyframe_interval) {
  FrameSourceOptions o;
  o.source.synthetic_width = w;
  o.source.synthetic_height = h;
  o.synthetic_frames = frames;
  o.kind = kind;
  video::FrameEncoderOptions v;
  v.encoder.preset = "ultrafast";
  v.encoder.crf = 20;
  v.encoder.keyframe_interval = keyframe_interval;
  o.video = v;
  return o;
}

TEST(VideoFrameStoreTest, ASequenceOfWholeKeyframeIntervalsStartingAtAnIdr) {
  FrameStore store =
      FrameStore::Prepare(SyntheticVideo(64, 48, 3, sources::FrameKind::kDisparity, 4)).value();
  ASSERT_TRUE(store.video().has_value());
  EXPECT_EQ(store.encoding(), "h264");
  // 3 source frames cycled up to a whole keyframe interval.
  EXPECT_EQ(store.video()->length, 4u);
  EXPECT_EQ(store.size(), 4u);
  EXPECT_EQ(store.video()->keyframe, (std::vector<bool>{true, false, false, false}));
  EXPECT_GT(store.video()->video_bytes_mean, 0);
  for (std::size_t i = 0; i < store.size(); ++i) {
    const v1::Frame f = Parsed(store, i).frame();
    ASSERT_TRUE(f.color().has_video()) << i;
    EXPECT_EQ(f.color().video().picture_index(), i);
    EXPECT_EQ(f.color().video().keyframe(), i == 0);
    EXPECT_EQ(f.color().video().width(), 64u);
    EXPECT_TRUE(f.disparity().has_compressed()) << "disparity lossless, zstd";
  }
}

TEST(VideoFrameStoreTest, StereoPairsAreOneInterleavedBitstream) {
  FrameStore store =
      FrameStore::Prepare(SyntheticVideo(64, 48, 2, sources::FrameKind::kStereo, 60)).value();
  EXPECT_EQ(store.video()->length, 60u);
  for (std::size_t i : {0u, 1u, 59u}) {
    const v1::Frame f = Parsed(store, i).frame();
    ASSERT_TRUE(f.color().has_video() && f.right().has_video()) << i;
    EXPECT_EQ(f.right().video().layout(), v1::VIDEO_LAYOUT_INTERLEAVED);
    EXPECT_EQ(f.color().video().picture_index(), 2 * i);
    EXPECT_EQ(f.right().video().picture_index(), 2 * i + 1);
  }
}

// Live video (--encoding h264 --rate-control): the store keeps the raw frames for each stream's
// encoder and sends each frame's geometry alone as its tail; the pictures a stream's encoder
// makes are appended per send and the whole parses as one Frame.
TEST(VideoFrameStoreTest, LiveVideoKeepsTheRawFramesAndSendsThePicturesBesideTheGeometry) {
  for (const sources::FrameKind kind :
       {sources::FrameKind::kDisparity, sources::FrameKind::kStereo}) {
    SCOPED_TRACE(sources::Name(kind));
    FrameSourceOptions o = SyntheticVideo(64, 48, 3, kind, 60);
    o.live_video = true;
    FrameStore store = FrameStore::Prepare(o).value();
    ASSERT_TRUE(store.live_video().has_value());
    EXPECT_FALSE(store.video().has_value());
    EXPECT_EQ(store.encoding(), "h264");
    EXPECT_NE(store.description().find("encoded live"), std::string::npos) << store.description();
    ASSERT_EQ(store.live_video()->originals.size(), 3u);
    EXPECT_EQ(store.size(), 3u);
    video::FrameEncoder encoder(store.live_video()->encoder);
    sources::UplinkFrame uplink;
    for (std::size_t i = 0; i < store.size(); ++i) {
      const v1::Frame tail = Parsed(store, i).frame();
      EXPECT_FALSE(tail.has_color()) << i;
      EXPECT_FALSE(tail.has_right()) << i;
      EXPECT_EQ(tail.has_disparity(), kind == sources::FrameKind::kDisparity);
      ASSERT_TRUE(uplink.Encode(store.live_video()->originals[i], store.live_video()->raw).ok());
      auto coded = encoder.Encode(uplink.input(), i + 1);
      ASSERT_TRUE(coded.ok()) << coded.status();
      auto pictures = PictureFields(*coded);
      ASSERT_TRUE(pictures.ok()) << pictures.status();
      grpc::ByteBuffer bytes = store.RequestWith(i, i + 1, 77, *pictures);
      std::vector<grpc::Slice> slices;
      ASSERT_TRUE(bytes.Dump(&slices).ok());
      std::string joined;
      for (auto& sl : slices) joined.append(reinterpret_cast<const char*>(sl.begin()), sl.size());
      v1::StreamRequest request;
      ASSERT_TRUE(request.ParseFromString(joined));
      const v1::Frame& f = request.frame();
      EXPECT_EQ(f.sequence(), i + 1);
      EXPECT_EQ(f.capture_time_unix_ns(), 77);
      EXPECT_EQ(f.frame_id(), tail.frame_id());
      ASSERT_TRUE(f.color().has_video()) << i;
      EXPECT_EQ(f.color().video().keyframe(), i == 0);
      if (kind == sources::FrameKind::kStereo) {
        ASSERT_TRUE(f.right().has_video()) << i;
      } else {
        EXPECT_TRUE(f.disparity().has_compressed()) << "disparity lossless, zstd";
      }
    }
  }
}

// ---------------------------------------------------------------------------------------------

class VideoFleetTest : public ::testing::Test {
 protected:
  static FleetOptions Options(const std::string& target, double fps, std::uint64_t frames,
                              bool lossless) {
    FleetOptions o;
    o.server = target;
    o.streams = 1;
    o.schedule.start = fps;
    o.duration = seconds(30);  // the frame count ends these runs
    o.frames = frames;
    o.drain_timeout = seconds(30);
    o.config.set_delivery(lossless ? v1::DELIVERY_ALL : v1::DELIVERY_LATEST);
    o.config.mutable_passthrough()->set_enabled(false);
    return o;
  }
  static Report Run(const FleetOptions& o, const FrameStore& store) {
    auto fleet = Fleet::Connect(o, &store);
    EXPECT_TRUE(fleet.ok()) << fleet.status();
    const FleetResult r = (*fleet)->Run();
    return MakeReport(**fleet, r, store.description(), "test", json::object());
  }
};

// A sequence with a picture missing (as after a loss): the server refuses the picture after the
// gap and asks for an IDR; the stream answers by going back to its IDR, and the frames after it
// are answered. One frame in flight, so every step is known.
TEST_F(VideoFleetTest, AKeyframeRequestSendsTheSequenceBackToItsIdr) {
  FrameStore made =
      FrameStore::Prepare(SyntheticVideo(64, 48, 8, sources::FrameKind::kDisparity, 0)).value();
  std::vector<v1::Frame> frames;
  for (std::size_t i = 0; i < 8; ++i) {
    if (i != 3) frames.push_back(Parsed(made, i).frame());  // pictures 0, 1, 2, 4, 5, 6, 7
  }
  FrameStore store = FrameStore::FromVideoFrames(frames, made.camera(), "gap").value();
  auto server = testing::StartTestServer();
  ASSERT_NE(server, nullptr);
  FleetOptions o = Options(server->address(), 30, 10, true);
  o.closed_loop = true;
  o.in_flight = 1;
  const Report report = Run(o, store);
  const Totals& t = report.totals;
  // Sent: p0 p1 p2 p4 (refused, IDR asked) p0 p1 p2 p4 (refused) p0 p1.
  EXPECT_EQ(t.sent, 10u);
  EXPECT_EQ(t.answered, 8u) << json(report.errors).dump();
  EXPECT_EQ(t.frame_errors, 2u);
  EXPECT_EQ(report.status_codes.at("FAILED_PRECONDITION"), 2u);
  EXPECT_EQ(t.keyframe_needed, 2u);
  EXPECT_EQ(t.keyframe_restarts, 2u);
  EXPECT_EQ(t.keyframes_sent, 3u);
}

// Far more frames due than one worker processes, DELIVERY_LATEST: the server skips stale frames
// after decoding them and the stream skips frames due while one waits, before encoding; no
// picture is ever replaced, so no frame is refused and no IDR is asked for.
TEST_F(VideoFleetTest, OverloadUnderLatestNeverBreaksTheBitstream) {
  server::ServerOptions options = testing::TestServerOptions();
  options.threads = 1;
  options.max_queued_frames = 1;
  auto server = testing::StartTestServer(options);
  ASSERT_NE(server, nullptr);
  FrameStore store =
      FrameStore::Prepare(SyntheticVideo(640, 480, 4, sources::FrameKind::kDisparity, 30)).value();
  FleetOptions o = Options(server->address(), 1000, 300, false);
  o.config.mutable_voxel_grid()->set_enabled(false);  // a slow frame, by construction
  const Report report = Run(o, store);
  const Totals& t = report.totals;
  EXPECT_EQ(t.sent + t.skipped + t.unsent, 300u);
  EXPECT_EQ(t.replaced, 0u);
  EXPECT_GT(t.drops + t.skipped, 0u);
  EXPECT_EQ(t.frame_errors, 0u) << json(report.errors).dump();
  EXPECT_EQ(t.keyframe_needed, 0u);
  EXPECT_EQ(t.answered + t.drops + t.lost, t.sent);
  EXPECT_GT(t.answered, 0u);
}

// Live video under rate control against a real server: each stream's encoder follows its
// controller's target (a stream held to 0.5 Mbit/s sends far smaller pictures than one allowed
// 8), every frame due is accounted for (answered, replaced raw while the stream had no room, or
// unsent at the end), and no picture is lost to a replacement (no reply asks for an IDR).
TEST_F(VideoFleetTest, LiveVideoFollowsEachStreamsRateController) {
  auto server = testing::StartTestServer();
  ASSERT_NE(server, nullptr);
  FrameSourceOptions so = SyntheticVideo(640, 480, 4, sources::FrameKind::kDisparity, 60);
  so.live_video = true;
  FrameStore store = FrameStore::Prepare(so).value();
  auto run = [&](double mbps) {
    FleetOptions o = Options(server->address(), 30, 60, false);
    o.streams = 2;
    client::RateControlOptions rc;
    rc.start_bps = mbps * 1e6;
    rc.max_bps = mbps * 1e6;
    o.rate_control = rc;
    return Run(o, store);
  };
  const Report low = run(0.5);
  const Report high = run(8);
  for (const Report* r : {&low, &high}) {
    const Totals& t = r->totals;
    EXPECT_EQ(t.frame_errors, 0u) << json(r->errors).dump();
    EXPECT_EQ(t.keyframe_needed, 0u);
    EXPECT_EQ(t.lost, 0u);
    EXPECT_EQ(t.sent + t.replaced + t.unsent, 60u);
    EXPECT_EQ(t.answered + t.drops, t.sent);
    EXPECT_GT(t.answered, 30u);
    // Each frame sent was encoded once, when it was due (one submitted after the run's end is
    // encoded and then left unsent); the encoder's CPU time was counted.
    EXPECT_GE(t.live_encoded, t.sent);
    EXPECT_LE(t.live_encoded, t.sent + t.unsent);
    EXPECT_GT(r->live_encode_us.Percentile(50), 0);
    EXPECT_GE(r->live_encode_us.Percentile(99), r->live_encode_us.Percentile(50));
  }
  // The encoder's own count of the pictures' bytes tells the two rates apart as well.
  EXPECT_LT(low.live_picture_bytes_per_frame(), 0.6 * high.live_picture_bytes_per_frame())
      << low.live_picture_bytes_per_frame() << " against " << high.live_picture_bytes_per_frame();
  // The pictures' bytes: what went out over the geometry each frame carries anyway.
  const auto pictures = [&](const Report& r) {
    return static_cast<double>(r.totals.bytes_sent) / static_cast<double>(r.totals.sent) -
           store.MeanRequestBytes();
  };
  EXPECT_LT(pictures(low), 0.6 * pictures(high))
      << pictures(low) << " against " << pictures(high) << " (geometry " << store.MeanRequestBytes()
      << ")";
}

// ---------------------------------------------------------------------------------------------

class LoadVideoCliTest : public testing::ScratchDirTest {
 protected:
  RunResult Run(std::vector<std::string> args) {
    return testing::RunProgram(testing::BinDir() + "/cloudcast-load", args, dir_.string());
  }
  std::vector<std::string> Source() const {
    if (testing::HaveTsukuba()) return {"--tsukuba", testing::TsukubaDir()};
    return {"--synthetic", "320x240", "--synthetic-frames", "4"};
  }
};

// cloudcast-load --encoding h264 against a real server, colour (disparity frames) and stereo pairs
// (one interleaved bitstream, coded grey and in colour), DELIVERY_ALL and DELIVERY_LATEST: every
// frame sent is answered (or, LATEST, skipped by the server after decoding), none is an error,
// no reply asks for an IDR, and the sequence loops at its IDR (--h264-keyframe-interval 10).
TEST_F(LoadVideoCliTest, EveryFrameIsAnsweredWithoutKeyframeRequests) {
  auto server = testing::StartTestServer();
  ASSERT_NE(server, nullptr);
  struct Case {
    std::string input;
    std::vector<std::string> extra;
    bool lossless;
  };
  const std::vector<Case> cases = {
      {"disparity", {}, true},
      {"disparity", {}, false},
      {"stereo", {"--h264-grey", "--h264-preset", "superfast", "--h264-crf", "4"}, true},
      {"stereo", {}, false},
      // docs/video.md's fast-decode colour setting: 4:4:4, CAVLC, no deblocking.
      {"disparity",
       {"--h264-444", "--h264-crf", "23", "--h264-x264-params",
        "no-deblock=1:cabac=0:no-psy=1:aq-mode=0:partitions=all"},
       true},
  };
  int n = 0;
  for (const Case& c : cases) {
    const std::string name = c.input + std::to_string(n++);
    SCOPED_TRACE(name);
    std::vector<std::string> args = {"--server",
                                     server->address(),
                                     "--input",
                                     c.input,
                                     "--encoding",
                                     "h264",
                                     "--h264-keyframe-interval",
                                     "10",
                                     "--streams",
                                     "2",
                                     "--fps",
                                     "30",
                                     "--frames",
                                     "50",
                                     "--json",
                                     Path(name + ".json"),
                                     "--html",
                                     Path(name + ".html"),
                                     "-q"};
    args.insert(args.end(), c.extra.begin(), c.extra.end());
    const std::vector<std::string> source = Source();
    args.insert(args.end(), source.begin(), source.end());
    if (c.input == "stereo")
      args.insert(args.end(), {"--matcher", "sgm", "--num-disparities", "64"});
    if (c.lossless) args.push_back("--lossless");
    const RunResult r = Run(args);
    ASSERT_EQ(r.code, 0) << r;
    EXPECT_NE(r.out.find(", h264 ("), std::string::npos) << r;
    const json j = json::parse(testing::ReadText(Path(name + ".json")));
    const json& frames = j["frames"];
    const json& video = j["encoding"]["video"];
    EXPECT_EQ(frames["frameErrors"], 0) << j["errorDistribution"];
    EXPECT_EQ(video["repliesAskingForKeyframe"], 0) << video;
    EXPECT_EQ(video["keyframesAskedFor"], 0) << video;
    EXPECT_EQ(frames["lost"], 0) << frames;
    EXPECT_EQ(frames["replaced"], 0) << frames;
    const std::uint64_t sent = frames["sent"];
    if (c.lossless) {
      EXPECT_EQ(sent, 50u) << frames;
      EXPECT_EQ(frames["answered"], 50) << frames;
    } else {
      EXPECT_EQ(sent + frames["skipped"].get<std::uint64_t>(), 50u) << frames;
      EXPECT_EQ(frames["answered"].get<std::uint64_t>() + frames["dropped"].get<std::uint64_t>(),
                sent)
          << frames;
    }
    // 25 frames a stream through a sequence of 10 with an IDR at its start: 3 each.
    EXPECT_EQ(video["sequenceFrames"], 10) << video;
    if (sent == 50u) {
      EXPECT_EQ(video["keyframesSent"], 6) << video;
    }
    EXPECT_EQ(j["encoding"]["name"], "h264");
    EXPECT_EQ(j["options"]["encoding"], "h264");
    // A fraction of the raw frame (a 640x480 colour image alone is 900 KB).
    EXPECT_GT(j["encoding"]["bytesPerFrame"].get<double>(), 1000) << j["encoding"];
    EXPECT_LT(j["encoding"]["bytesPerFrame"].get<double>(), 200 * 1024) << j["encoding"];
    EXPECT_GT(j["generator"]["cpuSeconds"].get<double>(), 0);
    const std::string html = testing::ReadText(Path(name + ".html"));
    EXPECT_NE(html.find("<th>encoding</th><td>h264, "), std::string::npos);
    EXPECT_NE(html.find("KB sent a frame"), std::string::npos);
  }
}

// --encoding h264 --rate-control: each stream encodes live; the report says so (text, JSON,
// HTML) and carries the controller's figures; every frame sent is answered without a keyframe
// request.
TEST_F(LoadVideoCliTest, RateControlWithH264EncodesLivePerStream) {
  auto server = testing::StartTestServer();
  ASSERT_NE(server, nullptr);
  std::vector<std::string> args = {"--server",
                                   server->address(),
                                   "--encoding",
                                   "h264",
                                   "--rate-control",
                                   "--streams",
                                   "2",
                                   "--fps",
                                   "30",
                                   "--frames",
                                   "40",
                                   "--json",
                                   Path("live.json"),
                                   "--html",
                                   Path("live.html")};
  const std::vector<std::string> source = Source();
  args.insert(args.end(), source.begin(), source.end());
  const RunResult r = Run(args);
  ASSERT_EQ(r.code, 0) << r;
  EXPECT_NE(r.out.find("encoded live per stream"), std::string::npos) << r;
  const json j = json::parse(testing::ReadText(Path("live.json")));
  const json& video = j["encoding"]["video"];
  EXPECT_EQ(video["live"], true) << video;
  EXPECT_EQ(video["repliesAskingForKeyframe"], 0) << video;
  EXPECT_GE(video["keyframesSent"].get<int>(), 2) << video;  // each stream starts at an IDR
  // What encoding live cost the generator's cores, and what it made.
  EXPECT_GE(video["encodedFrames"].get<std::uint64_t>(), j["frames"]["sent"].get<std::uint64_t>())
      << video;
  EXPECT_GT(video["pictureBytesPerFrame"].get<double>(), 0) << video;
  EXPECT_GT(video["encodeMsPerFrameMedian"].get<double>(), 0) << video;
  EXPECT_GE(video["encodeMsPerFrameP99"].get<double>(),
            video["encodeMsPerFrameMedian"].get<double>())
      << video;
  EXPECT_NE(r.out.find("encoder CPU"), std::string::npos) << r;
  EXPECT_EQ(j["encoding"]["name"], "h264");
  EXPECT_TRUE(j.contains("rateControl")) << j.dump().substr(0, 2000);
  const json& frames = j["frames"];
  EXPECT_EQ(frames["frameErrors"], 0) << j["errorDistribution"];
  EXPECT_EQ(frames["lost"], 0) << frames;
  EXPECT_EQ(frames["answered"].get<std::uint64_t>() + frames["dropped"].get<std::uint64_t>(),
            frames["sent"].get<std::uint64_t>())
      << frames;
  EXPECT_GT(frames["answered"].get<std::uint64_t>(), 20u) << frames;
  const std::string html = testing::ReadText(Path("live.html"));
  EXPECT_NE(html.find("encoded live by each stream"), std::string::npos);
}

TEST_F(LoadVideoCliTest, BadH264FlagsExitTwoNamingTheFlag) {
  auto null = NullServer::Start("127.0.0.1:0", "null").value();
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
      {{"--h264-crf", "60"}, "--h264-crf"},
      {{"--h264-crf", "nan"}, "--h264-crf"},
      {{"--h264-preset", "placebo"}, "--h264-preset"},
      {{"--h264-mbps", "0"}, "--h264-mbps"},
      {{"--h264-keyframe-interval", "-1"}, "--h264-keyframe-interval"},
      {{"--h264-threads", "0"}, "--h264-threads"},
      {{"--h264-444=maybe"}, "--h264-444"},
  };
  for (const auto& [args, flag] : cases) {
    std::vector<std::string> full = {
        "--server", null->address(), "--synthetic", "64x48", "--frames", "2", "--encoding", "h264"};
    full.insert(full.end(), args.begin(), args.end());
    const RunResult r = Run(full);
    EXPECT_FALSE(r.crashed()) << r;
    EXPECT_NE(r.code, 0) << args[0] << "\n" << r;
    EXPECT_NE((r.out + r.err).find(flag), std::string::npos) << args[0] << "\n" << r;
  }
  // Settings of an encoding not asked for, and what video streams do not take yet.
  const std::vector<std::pair<std::vector<std::string>, std::string>> misuse = {
      {{"--h264-crf", "18"}, "--h264-crf needs --encoding h264"},
      {{"--encoding", "zstd", "--h264-grey"}, "--h264-grey needs --encoding h264"},
      {{"--encoding", "h264", "--resilient"}, "--resilient does not take --encoding h264"},
      {{"--encoding", "zstd", "--rate-control"}, "--rate-control chooses the encoding"},
  };
  for (const auto& [args, message] : misuse) {
    std::vector<std::string> full = {"--server", null->address(), "--synthetic",
                                     "64x48",    "--frames",      "2"};
    full.insert(full.end(), args.begin(), args.end());
    const RunResult r = Run(full);
    EXPECT_EQ(r.code, 2) << args[0] << "\n" << r;
    EXPECT_NE(r.err.find(message), std::string::npos) << args[0] << "\n" << r;
  }
}

// The --h264-* flags are cloudcast-client's too (cli::VideoFlags): the same checks there.
TEST_F(LoadVideoCliTest, CloudcastClientSharesTheFlagsAndTheirChecks) {
  const std::string client = testing::BinDir() + "/cloudcast-client";
  const RunResult misuse =
      testing::RunProgram(client, {"--no-window", "--h264-crf", "3"}, dir_.string());
  EXPECT_EQ(misuse.code, 2) << misuse;
  EXPECT_NE(misuse.err.find("--h264-crf needs --encoding h264"), std::string::npos) << misuse;
  const RunResult nan = testing::RunProgram(
      client, {"--no-window", "--encoding", "h264", "--h264-mbps", "nan"}, dir_.string());
  EXPECT_NE(nan.code, 0) << nan;
  EXPECT_NE(nan.err.find("--h264-mbps"), std::string::npos) << nan;
}

}  // namespace
}  // namespace cloudcast::load
