// cloudcast-load's parts: the histogram against exact percentiles, the schedule, the frame
// store's wire bytes, and fleets against a real cloudcast server and the null server on
// loopback. No assertion on a time value: orderings and counts only.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <thread>

#include "cloudcast/core/draco_codec.h"
#include "cloudcast/load/fleet.h"
#include "cloudcast/load/frame_log.h"
#include "cloudcast/load/frame_store.h"
#include "cloudcast/load/histogram.h"
#include "cloudcast/load/memory_watch.h"
#include "cloudcast/load/null_server.h"
#include "cloudcast/load/report.h"
#include "cloudcast/load/schedule.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/server/server.h"
#include "cloudcast/v1/cloudcast.grpc.pb.h"
#include "support/frame_store_requests.h"
#include "support/waiting.h"

namespace cloudcast::load {
namespace {

using std::chrono::milliseconds;
using std::chrono::nanoseconds;
using std::chrono::seconds;

TEST(HistogramTest, BucketsCoverEveryValueWithinAThousandth) {
  for (std::int64_t v : {0L, 1L, 2047L, 2048L, 2049L, 4095L, 4096L, 123456789L, 1L << 40}) {
    const int i = Histogram::IndexOf(v);
    EXPECT_LE(Histogram::LowestOf(i), v) << v;
    EXPECT_GE(Histogram::HighestOf(i), v) << v;
    EXPECT_LE(Histogram::HighestOf(i) - Histogram::LowestOf(i), std::max<std::int64_t>(v / 1024, 0))
        << v;
  }
  EXPECT_EQ(Histogram::IndexOf((std::int64_t{1} << 42) - 1), Histogram::BucketCount() - 1);
}

TEST(HistogramTest, PercentilesMatchExactOnesOfRandomSamples) {
  std::mt19937_64 rng(42);
  // Log-normal latencies from microseconds to seconds, as a loaded server gives.
  std::lognormal_distribution<double> dist(std::log(5e6), 1.5);
  for (int round = 0; round < 5; ++round) {
    Histogram h;
    std::vector<std::int64_t> values;
    const int n = 1000 + round * 7919;
    for (int i = 0; i < n; ++i) {
      values.push_back(static_cast<std::int64_t>(dist(rng)));
      h.Record(values.back());
    }
    std::sort(values.begin(), values.end());
    for (double p : {0.0, 1.0, 10.0, 50.0, 90.0, 99.0, 99.9, 100.0}) {
      std::size_t rank = static_cast<std::size_t>(std::ceil(p / 100 * n - 1e-9));
      rank = std::clamp<std::size_t>(rank, 1, n);
      const std::int64_t exact = values[rank - 1];
      const std::int64_t got = h.Percentile(p);
      EXPECT_GE(got, exact) << "p" << p;
      EXPECT_LE(got - exact, exact / 1024 + 1) << "p" << p;
    }
    EXPECT_EQ(h.min(), values.front());
    EXPECT_EQ(h.max(), values.back());
    EXPECT_EQ(h.count(), static_cast<std::uint64_t>(n));
    const std::vector<std::uint64_t> bins = h.CountBetween({0, 1000000, 10000000, h.max() + 1});
    EXPECT_EQ(bins[0] + bins[1] + bins[2], h.count());
  }
}

TEST(HistogramTest, AddMergesAndResetEmpties) {
  Histogram a, b;
  for (int i = 1; i <= 100; ++i) a.Record(i * 1000);
  for (int i = 101; i <= 200; ++i) b.Record(i * 1000);
  a.Add(b);
  EXPECT_EQ(a.count(), 200u);
  EXPECT_EQ(a.min(), 1000);
  EXPECT_EQ(a.max(), 200000);
  a.Reset();
  EXPECT_EQ(a.count(), 0u);
  EXPECT_EQ(a.Percentile(50), 0);
}

TEST(ScheduleTest, ConstantRateFixesEveryIntendedTime) {
  auto s = Schedule::Create({ScheduleKind::kConst, 30});
  ASSERT_TRUE(s.ok());
  nanoseconds t = s->First(0.5);
  EXPECT_EQ(t.count(), 1'000'000'000 / 60);
  for (int i = 1; i <= 300; ++i) t = s->Next(t);
  // 300 periods of 1/30 s: 10 s after the first frame, to within rounding per frame.
  EXPECT_NEAR(static_cast<double>(t.count()), 1e9 / 60 + 10e9, 300);
}

TEST(ScheduleTest, StepAndLineRampsRiseToTheirEnd) {
  ScheduleOptions step{ScheduleKind::kStep, 10, 10, 40, seconds(2)};
  auto s = Schedule::Create(step);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->RateAt(seconds(0)), 10);
  EXPECT_EQ(s->RateAt(milliseconds(1999)), 10);
  EXPECT_EQ(s->RateAt(seconds(2)), 20);
  EXPECT_EQ(s->RateAt(seconds(100)), 40);
  ScheduleOptions line{ScheduleKind::kLine, 10, 5, 30, seconds(1)};
  auto l = Schedule::Create(line);
  ASSERT_TRUE(l.ok());
  EXPECT_LT(l->RateAt(seconds(1)), l->RateAt(seconds(2)));
  EXPECT_EQ(l->RateAt(seconds(100)), 30);
}

TEST(ScheduleTest, BadRampsNameTheFlag) {
  auto bad = Schedule::Create({ScheduleKind::kStep, 10, 0, 40, seconds(1)});
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("--load-step"), std::string::npos);
  auto away = Schedule::Create({ScheduleKind::kStep, 10, -5, 40, seconds(1)});
  ASSERT_FALSE(away.ok());
  EXPECT_NE(away.status().message().find("--load-end"), std::string::npos);
  auto zero = Schedule::Create({ScheduleKind::kConst, 0});
  ASSERT_FALSE(zero.ok());
}

FrameStore SmallStore(int frames = 3, std::uint32_t w = 64, std::uint32_t h = 48) {
  FrameSourceOptions o;
  o.source.synthetic_width = w;
  o.source.synthetic_height = h;
  o.synthetic_frames = frames;
  return FrameStore::Prepare(o).value();
}

// --frame-log's lines: the header's columns on every line, the latency from the intended time,
// and a replica name with a comma or a quote quoted as CSV has it.
TEST(FrameLogTest, LinesHaveTheHeadersColumnsAndQuoteAnAwkwardInstance) {
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("frame_log_test_" + std::to_string(getpid()) + ".csv"))
                               .string();
  auto log = FrameLog::Open(path, "--frame-log");
  ASSERT_TRUE(log.ok()) << log.status();
  FrameLogRow row;
  row.intended_unix_ns = 1'000'000'000;
  row.received_unix_ns = 1'123'456'000;
  row.instance = "replica-1";
  (*log)->Add(row);
  row.instance = "a,b\"c";
  (*log)->Add(row);
  ASSERT_TRUE((*log)->Close().ok());
  std::ifstream in(path);
  std::string header, plain, awkward;
  ASSERT_TRUE(std::getline(in, header) && std::getline(in, plain) && std::getline(in, awkward));
  const auto columns = [](const std::string& s) { return std::count(s.begin(), s.end(), ','); };
  EXPECT_EQ(columns(plain), columns(header));
  EXPECT_NE(plain.find(",123.456,"), std::string::npos) << plain;
  EXPECT_EQ(plain.substr(plain.rfind(',') + 1), "replica-1");
  EXPECT_EQ(awkward.substr(awkward.size() - 9), ",\"a,b\"\"c\"") << awkward;
  std::filesystem::remove(path);
  EXPECT_FALSE(FrameLog::Open("/no/such/folder/x.csv", "--frame-log").ok());
}

TEST(FrameStoreTest, RequestsParseAsStreamRequestsWithPatchedFields) {
  FrameStore store = SmallStore();
  ASSERT_EQ(store.size(), 3u);
  for (std::uint64_t seq : {1ull, 127ull, 128ull, 1ull << 40}) {
    const v1::StreamRequest request =
        testing::ParsedRequest(store, seq, seq, 1'700'000'000'000'000'000 + seq);
    ASSERT_TRUE(request.has_frame());
    EXPECT_EQ(request.frame().sequence(), seq);
    EXPECT_EQ(request.frame().capture_time_unix_ns(), 1'700'000'000'000'000'000 + seq);
    EXPECT_EQ(request.frame().frame_id(), "synthetic_" + std::to_string(seq % 3));
    EXPECT_EQ(request.frame().disparity().raw().width(), 64u);
    EXPECT_EQ(request.frame().color().raw().pixels().size(), 64u * 48 * 3);
  }
}

TEST(FrameStoreTest, PngAndJpegUplinksEncodeTheImages) {
  FrameSourceOptions o;
  o.source.synthetic_width = 64;
  o.source.synthetic_height = 48;
  o.synthetic_frames = 1;
  o.uplink.encoding = sources::Uplink::kJpeg;
  FrameStore store = FrameStore::Prepare(o).value();
  const v1::StreamRequest request = testing::ParsedRequest(store, 0, 1, 1);
  EXPECT_FALSE(request.frame().color().encoded().empty());
  EXPECT_FALSE(request.frame().disparity().encoded().empty());  // 16-bit disparity as PNG
}

TEST(FrameStoreTest, MissingFilesNameTheFlag) {
  FrameSourceOptions o;
  o.source.globs[sources::ImageRole::kDisparity] = "/nonexistent/*.png";
  o.source.globs[sources::ImageRole::kColour] = "/nonexistent/*.png";
  auto store = FrameStore::Prepare(o);
  ASSERT_FALSE(store.ok());
  EXPECT_NE(store.status().message().find("--disparity-glob"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------

class FleetTest : public ::testing::Test {
 protected:
  static std::unique_ptr<server::Server> StartServer(int threads, std::uint32_t queued = 4) {
    server::ServerOptions options;
    // The fleet's configs carry no camera: the paper's, as the server's defaults, stated.
    EXPECT_TRUE(ApplyPreset("new_tsukuba", &options.defaults.frame).ok());
    options.listen = "127.0.0.1:0";
    options.metrics_listen = "";
    options.threads = threads;
    options.max_queued_frames = queued;
    options.instance = "replica-a";
    return server::Server::Start(options).value();
  }

  static FleetOptions Options(const std::string& target, int streams, double fps,
                              std::uint64_t frames, bool lossless) {
    FleetOptions o;
    o.server = target;
    o.streams = streams;
    o.schedule.start = fps;
    o.duration = seconds(30);  // the frame count ends these runs
    o.frames = frames;
    o.drain_timeout = seconds(30);
    o.config.set_delivery(lossless ? v1::DELIVERY_ALL : v1::DELIVERY_LATEST);
    return o;
  }

  static FleetResult Run(const FleetOptions& o, const FrameStore& store, Report* report) {
    auto fleet = Fleet::Connect(o, &store);
    EXPECT_TRUE(fleet.ok()) << fleet.status();
    const FleetResult r = (*fleet)->Run();
    *report = MakeReport(**fleet, r, store.description(), "test", nlohmann::json::object());
    return r;
  }
};

// The adaptive ladder's half-resolution levels carry their own camera (Frame.camera), so the
// server makes the same surface from a quarter of the pixels: each point keeps its depth and its
// place. Without the camera the cloud would be half as far (focal halved, disparity not) or
// squeezed to one side (principal point).
TEST_F(FleetTest, HalfResolutionLevelsMakeTheSameSurface) {
  auto server = StartServer(1);
  FrameSourceOptions o;
  o.source.synthetic_width = 320;
  o.source.synthetic_height = 240;
  o.synthetic_frames = 1;
  o.jpeg_ladder = {90};
  o.half_resolution_ladder = {90};
  FrameStore store = FrameStore::Prepare(o).value();
  ASSERT_EQ(store.levels(), 2u);
  v1::StreamConfig config;  // the frames' camera, as cloudcast-load sends it
  convert::SetCamera(store.camera(), &config);
  config.mutable_camera()->clear_cx();  // the image's centre, at either resolution
  config.mutable_camera()->clear_cy();
  config.mutable_passthrough()->set_enabled(false);  // the whole scene
  ASSERT_TRUE(store.SetStreamCamera(config.camera()).ok());
  EXPECT_LT(store.MeanRequestBytes(1), store.MeanRequestBytes(0) / 2);
  auto stub = v1::CloudCast::NewStub(
      grpc::CreateChannel(server->address(), grpc::InsecureChannelCredentials()));
  struct Summary {
    std::size_t pixels = 0, points = 0;
    double lo[3] = {1e9, 1e9, 1e9}, hi[3] = {-1e9, -1e9, -1e9};
  };
  auto process = [&](std::size_t level) {
    const v1::StreamRequest request = testing::ParsedRequest(store, 0, 1, 1, level);
    v1::ProcessRequest process;
    *process.mutable_frame() = request.frame();
    *process.mutable_config() = config;
    v1::CloudReply reply;
    grpc::ClientContext context;
    const grpc::Status status = stub->Process(&context, process, &reply);
    EXPECT_TRUE(status.ok()) << status.error_message();
    PointCloud cloud;
    EXPECT_TRUE(DecodeDraco(reply.draco(), &cloud).ok());
    Summary s;
    s.pixels = reply.counts().pixels();
    s.points = cloud.size();
    for (const Point& p : cloud.points) {
      const double v[3] = {p.x, p.y, p.z};
      for (int i = 0; i < 3; ++i) {
        s.lo[i] = std::min(s.lo[i], v[i]);
        s.hi[i] = std::max(s.hi[i], v[i]);
      }
    }
    return s;
  };
  const Summary full = process(0), half = process(1);
  EXPECT_EQ(full.pixels, 320u * 240);
  EXPECT_EQ(half.pixels, 160u * 120);
  ASSERT_GT(full.points, 100u);
  ASSERT_GT(half.points, 100u);
  // Fewer points where a half-resolution pixel is wider than the voxel grid's leaf (far away),
  // the same surface's extent on every axis.
  std::printf("points after the voxel grid: full %zu, half %zu\n", full.points, half.points);
  for (int i = 0; i < 3; ++i) {
    const double extent = full.hi[i] - full.lo[i];
    ASSERT_GT(extent, 0) << i;
    EXPECT_NEAR(half.lo[i], full.lo[i], 0.05 * extent) << "axis " << i;
    EXPECT_NEAR(half.hi[i], full.hi[i], 0.05 * extent) << "axis " << i;
  }
}

// The JSON (and the table) say what the replies said of the downlink (contract revision 4): the
// Draco colour bits the server chose and the clouds over the stream's cap.
TEST_F(FleetTest, TheReportCarriesTheDownlinksColourBitsAndOverCap) {
  auto server = StartServer(1);
  FrameStore store = SmallStore(2, 160, 120);
  Report report;
  FleetOptions o = Options(server->address(), 1, 50, 6, true);
  Run(o, store, &report);
  ASSERT_EQ(report.totals.answered, 6u);
  nlohmann::json j = GhzJson(report);
  ASSERT_TRUE(j.contains("downlink")) << j.dump();
  EXPECT_EQ(j["downlink"]["colorBitsMedian"], 8);  // no cap: exact colours
  EXPECT_EQ(j["downlink"]["colorBits"]["8"], 6);
  EXPECT_EQ(j["downlink"]["overCap"], 0);

  // A cap no cloud can meet: every cloud at the floors (5 colour bits by default), over it.
  o.config.mutable_draco()->set_max_cloud_bytes(64);
  Run(o, store, &report);
  ASSERT_EQ(report.totals.answered, 6u);
  j = GhzJson(report);
  EXPECT_EQ(j["downlink"]["colorBitsMedian"], 5);
  EXPECT_EQ(j["downlink"]["colorBits"]["5"], 6);
  EXPECT_EQ(j["downlink"]["overCap"], 6);
  EXPECT_NE(FormatTable(report).find("Draco colour bits 5 (median of the clouds), 6 over the cap"),
            std::string::npos)
      << FormatTable(report);
}

TEST_F(FleetTest, LosslessRunAgainstTheServerAnswersEveryFrame) {
  auto server = StartServer(2);
  FrameStore store = SmallStore(4, 160, 120);
  Report report;
  const FleetResult r = Run(Options(server->address(), 3, 50, 60, true), store, &report);
  EXPECT_EQ(r.end_reason, EndReason::kNormal);
  EXPECT_EQ(report.totals.sent, 60u);
  EXPECT_EQ(report.totals.answered, 60u);
  EXPECT_EQ(report.totals.lost + report.totals.unsent + report.totals.drops, 0u);
  EXPECT_EQ(report.per_instance.at("replica-a"), 60u);
  EXPECT_EQ(report.call_status.at("OK"), 3u);
  EXPECT_EQ(report.latency.count(), 60u);
  // Latency counts from the intended time, never after the actual send.
  for (double p : {0.0, 50.0, 90.0, 100.0}) {
    EXPECT_GE(report.latency.Percentile(p), report.service.Percentile(p)) << p;
  }
}

TEST_F(FleetTest, AnOverloadedServerMakesLateSendsAndTheirWaitCounts) {
  // One worker, one queued frame, 1280x960 frames far faster than it can process them: the
  // stream's writes back up, later frames go late, and their wait is latency, not service time.
  auto server = StartServer(1, 1);
  FrameStore store = SmallStore(2, 1280, 960);
  Report report;
  Run(Options(server->address(), 1, 2000, 150, true), store, &report);
  EXPECT_EQ(report.totals.answered, 150u);
  EXPECT_GT(report.totals.late_flow_control, 0u);
  EXPECT_GT(report.latency.Percentile(90), report.service.Percentile(90));
  EXPECT_GE(report.latency.max(), report.service.max());
  // The time series saw the same frames.
  std::uint64_t answered = 0;
  for (const SecondStats& s : report.series) answered += s.answered;
  EXPECT_EQ(answered, 150u);
}

TEST_F(FleetTest, LatestDeliveryDropsUnderOverloadAndAccountsForEveryFrame) {
  // Overload by construction, not by the machine's speed: without passthrough and voxel grid every
  // valid pixel is compressed, so one frame takes the single worker far longer than the next
  // takes to arrive.
  auto server = StartServer(1, 1);
  FrameStore store = SmallStore(2, 640, 480);
  FleetOptions o = Options(server->address(), 2, 1000, 200, false);
  o.config.mutable_passthrough()->set_enabled(false);
  o.config.mutable_voxel_grid()->set_enabled(false);
  Report report;
  Run(o, store, &report);
  const Totals& t = report.totals;
  // As robots send: a frame still waiting for the write slot when the next is due is replaced
  // in the client; every frame sent is answered, dropped by the server, errored or lost.
  EXPECT_EQ(t.sent + t.replaced + t.unsent, 200u);
  EXPECT_GT(t.drops + t.replaced, 0u);
  EXPECT_EQ(t.answered + t.drops + t.frame_errors + t.lost, t.sent);
}

TEST_F(FleetTest, ClosedLoopKeepsFramesInFlight) {
  auto server = StartServer(2);
  FrameStore store = SmallStore(3, 160, 120);
  FleetOptions o = Options(server->address(), 2, 30, 40, true);
  o.closed_loop = true;
  o.in_flight = 2;
  Report report;
  Run(o, store, &report);
  EXPECT_EQ(report.totals.sent, 40u);
  EXPECT_EQ(report.totals.answered, 40u);
  EXPECT_EQ(report.totals.late(), 0u);
}

TEST_F(FleetTest, NullServerAnswersAndStopEndsTheRunWithCancel) {
  auto null = NullServer::Start("127.0.0.1:0", "null-1").value();
  FrameStore store = SmallStore(2, 320, 240);
  FleetOptions o = Options(null->address(), 4, 100, 0, true);
  o.duration = seconds(60);
  auto fleet = Fleet::Connect(o, &store).value();
  std::thread stopper([&] {
    // Stops once frames are flowing: the recorder's counters announce nothing to wait on.
    EXPECT_TRUE(
        cloudcast::testing::Eventually([&] { return fleet->recorder().totals().answered >= 50; }));
    fleet->Stop();
  });
  const FleetResult r = fleet->Run();
  stopper.join();
  EXPECT_EQ(r.end_reason, EndReason::kCancel);
  const Totals t = fleet->recorder().totals();
  EXPECT_GE(t.answered, 50u);
  EXPECT_EQ(t.answered, t.sent);  // nothing in flight is lost on a clean stop
  EXPECT_EQ(fleet->recorder().per_instance().at("null-1"), t.answered);
}

TEST_F(FleetTest, GhzJsonHasGhzFieldsAndTheExtraOnes) {
  auto null = NullServer::Start("127.0.0.1:0", "null-1").value();
  FrameStore store = SmallStore(2, 64, 48);
  Report report;
  Run(Options(null->address(), 2, 200, 40, true), store, &report);
  const nlohmann::json j = GhzJson(report);
  for (const char* key : {"count", "total", "average", "fastest", "slowest"}) {
    ASSERT_TRUE(j.contains(key)) << key;
    EXPECT_TRUE(j[key].is_number_integer()) << key;
  }
  EXPECT_EQ(j["count"], 40);
  EXPECT_TRUE(j["rps"].is_number());
  ASSERT_TRUE(j["latencyDistribution"].is_array());
  for (const auto& d : j["latencyDistribution"]) {
    EXPECT_TRUE(d["percentage"].is_number());
    EXPECT_TRUE(d["latency"].is_number_integer());
  }
  ASSERT_TRUE(j["histogram"].is_array());
  std::uint64_t in_histogram = 0;
  for (const auto& b : j["histogram"]) {
    EXPECT_TRUE(b["mark"].is_number_float());
    in_histogram += b["count"].get<std::uint64_t>();
  }
  EXPECT_EQ(in_histogram, 40u);
  EXPECT_EQ(j["statusCodeDistribution"]["OK"], 40);
  EXPECT_TRUE(j["errorDistribution"].is_object());
  EXPECT_EQ(j["endReason"], "normal");
  EXPECT_EQ(j["date"].get<std::string>().size(), 20u);  // 2026-12-01T09:00:00Z
  for (const char* key : {"p50", "p90", "p99", "p99.9", "max"}) {
    EXPECT_TRUE(j["intendedLatency"][key].is_number_integer()) << key;
    EXPECT_TRUE(j["serviceTime"][key].is_number_integer()) << key;
  }
  EXPECT_EQ(j["drops"], 0);
  EXPECT_TRUE(j["lateSends"]["total"].is_number_integer());
  EXPECT_EQ(j["framesPerReplica"]["null-1"], 40);
  ASSERT_TRUE(j["timeSeries"].is_array());
  EXPECT_FALSE(j["timeSeries"].empty());
  // Each second's reply bytes add up to the run's.
  std::uint64_t replies = 0;
  for (const auto& s : j["timeSeries"]) replies += s["bytesReceived"].get<std::uint64_t>();
  EXPECT_EQ(replies, j["frames"]["bytesReceived"].get<std::uint64_t>());
  EXPECT_GT(replies, 0u);
}

TEST_F(FleetTest, UnreachableServerIsAClearError) {
  FrameStore store = SmallStore(1, 64, 48);
  FleetOptions o = Options("127.0.0.1:1", 1, 30, 10, true);
  o.connect_timeout = milliseconds(300);
  auto fleet = Fleet::Connect(o, &store);
  ASSERT_FALSE(fleet.ok());
  EXPECT_NE(fleet.status().message().find("--server 127.0.0.1:1"), std::string::npos);
}

}  // namespace
}  // namespace cloudcast::load

namespace cloudcast::load {
namespace {

TEST(MemoryWatchTest, MetricValueReadsTheUnlabelledSampleOnly) {
  const std::string text =
      "# HELP cloudcast_process_resident_memory_bytes x\n"
      "cloudcast_process_resident_memory_bytes_total 5\n"
      "cloudcast_process_resident_memory_bytes{a=\"b\"} 7\n"
      "cloudcast_process_resident_memory_bytes 1.25e+08\n";
  EXPECT_EQ(MetricValue(text, "cloudcast_process_resident_memory_bytes").value(), 1.25e8);
  EXPECT_EQ(MetricValue(text, "missing").status().code(), absl::StatusCode::kNotFound);
  EXPECT_FALSE(MetricValue("m nan\n", "m").ok());
}

TEST(MemoryWatchTest, ScrapesARealServersMemory) {
  server::ServerOptions options;
  options.listen = "127.0.0.1:0";
  options.metrics_listen = "127.0.0.1:0";
  auto server = server::Server::Start(options).value();
  const std::string url = "http://127.0.0.1:" + std::to_string(server->metrics_port()) + "/metrics";
  const std::uint64_t rss = MemoryWatch::Scrape(url).value();
  EXPECT_GT(rss, 1u << 20);  // a process with gRPC loaded holds megabytes
  MemoryWatch watch(url, std::chrono::milliseconds(100));
  watch.Stop();
  const std::vector<MemorySample> samples = watch.samples();
  ASSERT_GE(samples.size(), 2u);  // one at the start, one at the stop
  for (const MemorySample& s : samples) EXPECT_GT(s.rss_bytes, 0u) << s.error;
  EXPECT_FALSE(MemoryWatch::Scrape("http://127.0.0.1:1/metrics").ok());
}

TEST(MemoryWatchTest, SoakFailsOnLossOrGrowthAfterTheWarmUp) {
  auto at = [](double t, double mb) {
    MemorySample s;
    s.t_s = t;
    s.rss_bytes = static_cast<std::uint64_t>(mb * 1e6);
    return s;
  };
  Totals clean;
  clean.sent = clean.answered = 100;
  SoakBounds bounds;
  bounds.warmup_s = 10;
  bounds.max_growth_bytes = 20e6;
  // Growth during the warm-up does not count; after it, up to the bound passes.
  SoakVerdict v =
      JudgeSoak({at(0, 50), at(5, 150), at(10, 160), at(15, 170), at(20, 179)}, clean, bounds);
  EXPECT_TRUE(v.passed) << (v.failures.empty() ? "" : v.failures.front());
  EXPECT_EQ(v.baseline_bytes, 160'000'000u);
  EXPECT_EQ(v.peak_bytes, 179'000'000u);
  v = JudgeSoak({at(0, 50), at(10, 160), at(15, 181)}, clean, bounds);
  ASSERT_FALSE(v.passed);
  EXPECT_NE(v.failures.front().find("grew 21.0 MB"), std::string::npos) << v.failures.front();
  // A lost frame fails it, and so does a DELIVERY_ALL frame left unanswered.
  Totals lost = clean;
  lost.lost = 1;
  EXPECT_FALSE(JudgeSoak({at(0, 50), at(15, 50)}, lost, bounds).passed);
  Totals unanswered = clean;
  unanswered.answered = 99;
  EXPECT_FALSE(JudgeSoak({at(0, 50), at(15, 50)}, unanswered, bounds).passed);
  bounds.lossless = false;  // DELIVERY_LATEST skips stale frames
  EXPECT_TRUE(JudgeSoak({at(0, 50), at(15, 50)}, unanswered, bounds).passed);
  // No sample after the warm-up is no verdict.
  EXPECT_FALSE(JudgeSoak({at(0, 50)}, clean, bounds).passed);
}

}  // namespace
}  // namespace cloudcast::load
