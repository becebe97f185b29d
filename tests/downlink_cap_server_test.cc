// The downlink cap end to end (issue 26, contract revision 4): a real server on loopback, the
// client library's SetMaxCloudBytes. Replies stay under the cap or say they cannot (OverCap
// naming config.draco.max_cloud_bytes and the bounds that stopped the server), never past the
// error bound; no cap is today's behaviour byte for byte; bad values get errors naming the field.
#include <grpcpp/grpcpp.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "cloudcast/client/client.h"
#include "cloudcast/client/config.h"
#include "cloudcast/datasets/tsukuba.h"
#include "cloudcast/testing/metrics_scrape.h"
#include "cloudcast/v1/cloudcast.grpc.pb.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "support/client_fixture.h"
#include "support/program_support.h"
#include "support/test_support.h"

namespace cloudcast {
namespace {

using ::testing::Contains;
using ::testing::HasSubstr;
using ::testing::Not;
using ::testing::StartsWith;

class DownlinkCapTest : public testing::SharedServerClientTest {
 protected:
  static void SetUpTestSuite() {
    SharedServerClientTest::SetUpTestSuite();
    auto frames = tsukuba::LoadAll(testing::TsukubaDir());
    if (frames.ok()) frames_ = new std::vector<tsukuba::Frame>(*std::move(frames));
  }
  static void TearDownTestSuite() {
    delete frames_;
    frames_ = nullptr;
    SharedServerClientTest::TearDownTestSuite();
  }
  static const tsukuba::Frame& Frame(const std::string& id) {
    for (const tsukuba::Frame& f : *frames_) {
      if (f.id == id) return f;
    }
    return frames_->front();
  }
  static client::StreamConfig Capped(std::uint64_t bytes) {
    client::StreamConfig config;
    config.set_delivery(v1::DELIVERY_ALL);
    EXPECT_TRUE(client::SetMaxCloudBytes(bytes, &config).ok());
    return config;
  }
  absl::StatusOr<client::Result> Process(const std::string& id,
                                         const client::StreamConfig& config) {
    const tsukuba::Frame& f = Frame(id);
    return client_->Process(f.disparity.view(), f.colour.view(), config);
  }

  inline static std::vector<tsukuba::Frame>* frames_ = nullptr;
};

#define REQUIRE_FRAMES()                          \
  do {                                            \
    CLOUDCAST_REQUIRE_TSUKUBA();                  \
    ASSERT_NE(frames_, nullptr) << "New Tsukuba"; \
  } while (0)

// What every capped reply promises.
void ExpectCapKept(const client::Result& r, std::uint64_t cap) {
  ASSERT_TRUE(r.ok()) << r.status;
  const v1::CloudReply& reply = r.reply;
  // The server's default bound: a quarter of the 3 cm leaf.
  EXPECT_LE(reply.position_error_bound(), 0.0075f);
  EXPECT_GE(reply.color_bits(), 5);
  EXPECT_LE(reply.color_bits(), 8);
  EXPECT_EQ(r.cloud.size(), reply.point_count());  // the cloud decodes, whole
  if (reply.has_over_cap()) {
    const v1::OverCap& over = reply.over_cap();
    EXPECT_EQ(over.field(), "config.draco.max_cloud_bytes");
    EXPECT_EQ(over.max_cloud_bytes(), cap);
    EXPECT_EQ(over.cloud_bytes(), reply.draco().size());
    EXPECT_GT(reply.draco().size(), cap);
    EXPECT_THAT(over.limited_by(), Contains("config.draco.max_position_error"));
    EXPECT_THAT(over.limited_by(), Contains("config.draco.min_color_bits"));
    EXPECT_EQ(reply.color_bits(), 5);  // at the colour floor
    EXPECT_THAT(over.message(), HasSubstr("config.draco.max_cloud_bytes"));
  } else {
    EXPECT_LE(reply.draco().size(), cap);
  }
}

TEST_F(DownlinkCapTest, GetInfoNamesRevision5AndTheDefaults) {
  absl::StatusOr<v1::ServerInfo> info = client_->GetInfo();
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->contract_revision(), "5");
  EXPECT_TRUE(info->defaults().draco().has_max_cloud_bytes());
  EXPECT_EQ(info->defaults().draco().max_cloud_bytes(), 0u);
  EXPECT_EQ(info->defaults().draco().min_color_bits(), 5);
  EXPECT_TRUE(info->defaults().draco().has_cap_min_points_per_voxel());
  EXPECT_EQ(info->defaults().draco().cap_min_points_per_voxel(), 0u);
}

TEST_F(DownlinkCapTest, StreamRepliesStayUnderTheCapOrSaySo) {
  REQUIRE_FRAMES();
  // 36,000 bytes: New Tsukuba clouds take 1.7 to 79 KB uncapped; some fit at 8 colour bits,
  // some need fewer, frame 00400 (27,557 points) cannot within the bound.
  constexpr std::uint64_t kCap = 36000;
  auto stream = client_->OpenStream(Capped(kCap));
  ASSERT_TRUE(stream.ok()) << stream.status();
  for (const tsukuba::Frame& f : *frames_) {
    ASSERT_TRUE((*stream)->Send(f.disparity.view(), f.colour.view()).ok());
  }
  int under = 0, over = 0, lowered = 0;
  for (std::size_t i = 0; i < frames_->size(); ++i) {
    client::Result r;
    ASSERT_TRUE((*stream)->Read(&r));
    SCOPED_TRACE("frame " + (*frames_)[i].id);
    ExpectCapKept(r, kCap);
    (r.reply.has_over_cap() ? over : under) += 1;
    lowered += r.reply.color_bits() < 8 || r.reply.position_bits() < 10;
  }
  EXPECT_TRUE((*stream)->Finish().ok());
  EXPECT_GE(over, 1);     // 00400
  EXPECT_GE(under, 5);    // the small and empty ones, and those the bits brought under
  EXPECT_GE(lowered, 2);  // 00001 and 01200 came under by coarser bits
}

TEST_F(DownlinkCapTest, ALooserBoundMeetsWhatTheDefaultCannot) {
  REQUIRE_FRAMES();
  // Frame 00001 takes 33 KB at the default bound's floors (10 position bits, 5 colour bits).
  client::StreamConfig config = Capped(30000);
  absl::StatusOr<client::Result> r = Process("00001", config);
  ASSERT_TRUE(r.ok()) << r.status();
  ExpectCapKept(*r, 30000);
  EXPECT_TRUE(r->reply.has_over_cap());
  config.mutable_draco()->set_max_position_error(0.03f);  // the whole leaf
  r = Process("00001", config);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_FALSE(r->reply.has_over_cap()) << r->reply.over_cap().message();
  EXPECT_LE(r->reply.draco().size(), 30000u);
  EXPECT_LE(r->reply.position_error_bound(), 0.03f);
  EXPECT_LT(r->reply.position_bits(), 10);
}

TEST_F(DownlinkCapTest, AnImpossibleCapStillSendsTheCloudAndNamesTheField) {
  REQUIRE_FRAMES();
  absl::StatusOr<client::Result> r = Process("00001", Capped(64));
  ASSERT_TRUE(r.ok()) << r.status();
  ExpectCapKept(*r, 64);
  ASSERT_TRUE(r->reply.has_over_cap());
  EXPECT_GT(r->cloud.size(), 10000u);
  EXPECT_EQ(r->reply.position_bits(), 10);  // the fewest that keep 0.0075 on this cloud
}

TEST_F(DownlinkCapTest, NoCapIsTodaysReply) {
  REQUIRE_FRAMES();
  client::StreamConfig none;
  absl::StatusOr<client::Result> plain = Process("00001", none);
  ASSERT_TRUE(plain.ok()) << plain.status();
  client::StreamConfig zero;
  ASSERT_TRUE(client::SetMaxCloudBytes(0, &zero).ok());
  zero.mutable_draco()->set_max_cloud_bytes(0);  // stated, not just unset
  absl::StatusOr<client::Result> capped_zero = Process("00001", zero);
  ASSERT_TRUE(capped_zero.ok()) << capped_zero.status();
  EXPECT_TRUE(plain->reply.draco() == capped_zero->reply.draco()) << "0 changed the cloud";
  EXPECT_EQ(plain->reply.position_bits(), 10);
  EXPECT_EQ(plain->reply.color_bits(), 8);
  EXPECT_FALSE(plain->reply.has_over_cap());
  EXPECT_FALSE(capped_zero->reply.has_over_cap());
  // A cap the uncapped cloud meets is met (perhaps a step coarser: the server predicts, it does
  // not try every step).
  absl::StatusOr<client::Result> roomy = Process("00001", Capped(plain->reply.draco().size()));
  ASSERT_TRUE(roomy.ok()) << roomy.status();
  EXPECT_FALSE(roomy->reply.has_over_cap());
  EXPECT_LE(roomy->reply.draco().size(), plain->reply.draco().size());
}

// Contract revision 5: past the bits, the cap may drop the voxels of fewest points when the
// client allows it (DracoConfig.cap_min_points_per_voxel), and each cloud is then exactly the
// voxel grid's with the minimum the reply names.
TEST_F(DownlinkCapTest, TheCapDropsTheSparsestVoxelsOnlyWhereBitsCannotMeetIt) {
  REQUIRE_FRAMES();
  auto with_minimum = [](client::StreamConfig c, std::uint32_t cap_min, std::uint32_t min) {
    if (cap_min > 0) c.mutable_draco()->set_cap_min_points_per_voxel(cap_min);
    if (min > 0) c.mutable_voxel_grid()->set_min_points_per_voxel(min);
    return c;
  };
  auto process = [&](const client::StreamConfig& c) {
    absl::StatusOr<client::Result> r = Process("00001", c);
    EXPECT_TRUE(r.ok()) << r.status();
    return r.ok() ? *std::move(r) : client::Result{};
  };
  // Frame 00001 takes 33 KB at the floors: over a 30,000-byte cap, under it without its lone
  // points.
  const client::Result bits_only = process(Capped(30000));
  ASSERT_TRUE(bits_only.reply.has_over_cap());
  EXPECT_EQ(bits_only.reply.min_points_per_voxel(), 0u);
  const client::Result dropped = process(with_minimum(Capped(30000), 4, 0));
  ExpectCapKept(dropped, 30000);
  EXPECT_FALSE(dropped.reply.has_over_cap()) << dropped.reply.over_cap().message();
  EXPECT_EQ(dropped.reply.min_points_per_voxel(), 2u);  // the first step that fits
  EXPECT_LT(dropped.reply.point_count(), bits_only.reply.point_count());
  EXPECT_EQ(dropped.reply.counts().after_voxel_grid(), dropped.reply.point_count());
  // Exactly the cloud a stream asking for that minimum gets, byte for byte.
  const client::Result asked = process(with_minimum(Capped(30000), 0, 2));
  EXPECT_TRUE(asked.reply.draco() == dropped.reply.draco());
  EXPECT_EQ(asked.reply.min_points_per_voxel(), 2u);

  // Where the bits meet the cap, no voxel goes.
  const client::Result roomy = process(with_minimum(Capped(100000), 4, 0));
  EXPECT_FALSE(roomy.reply.has_over_cap());
  EXPECT_EQ(roomy.reply.min_points_per_voxel(), 0u);
  EXPECT_EQ(roomy.reply.point_count(), bits_only.reply.point_count());

  // A cap nothing meets: the minimum goes as far as allowed, and the reply names that bound too.
  const client::Result impossible = process(with_minimum(Capped(64), 3, 0));
  ExpectCapKept(impossible, 64);
  ASSERT_TRUE(impossible.reply.has_over_cap());
  EXPECT_EQ(impossible.reply.min_points_per_voxel(), 3u);
  EXPECT_THAT(impossible.reply.over_cap().limited_by(),
              Contains("config.draco.cap_min_points_per_voxel"));
  EXPECT_THAT(impossible.reply.over_cap().message(),
              HasSubstr("voxels of at least 3 points (config.draco.cap_min_points_per_voxel)"));
  EXPECT_TRUE(process(with_minimum(Capped(64), 0, 3)).reply.draco() == impossible.reply.draco());
  EXPECT_THAT(bits_only.reply.over_cap().limited_by(),
              Not(Contains("config.draco.cap_min_points_per_voxel")));

  // Never an empty cloud: a minimum no voxel reaches stops at the last that keeps points.
  const client::Result most = process(with_minimum(Capped(64), 64, 0));
  ASSERT_TRUE(most.reply.has_over_cap());
  EXPECT_GT(most.reply.point_count(), 0u);
  EXPECT_GT(most.reply.min_points_per_voxel(), 3u);
  EXPECT_LT(most.reply.min_points_per_voxel(), 64u);
  EXPECT_FALSE(most.reply.has_empty());

  // Too large a minimum is refused, naming the field.
  absl::StatusOr<client::Result> bad = Process("00001", with_minimum(Capped(30000), 65, 0));
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(bad.status().message()),
              HasSubstr("config.draco.cap_min_points_per_voxel is 65"));
}

// An operator sees how often the cap binds: clouds over it, clouds it thinned.
TEST_F(DownlinkCapTest, MetricsCountCloudsOverTheCapAndCloudsItThinned) {
  REQUIRE_FRAMES();
  server::ServerOptions options = testing::TestServerOptions();
  options.metrics_listen = "127.0.0.1:0";
  std::unique_ptr<server::Server> server = testing::StartTestServer(options);
  ASSERT_NE(server, nullptr);
  auto client = client::Client::Connect(server->address());
  ASSERT_TRUE(client.ok()) << client.status();
  const tsukuba::Frame& f = Frame("00001");
  auto send = [&](std::uint64_t cap, std::uint32_t cap_min) {
    client::StreamConfig c = Capped(cap);
    if (cap_min > 0) c.mutable_draco()->set_cap_min_points_per_voxel(cap_min);
    absl::StatusOr<client::Result> r = (*client)->Process(f.disparity.view(), f.colour.view(), c);
    EXPECT_TRUE(r.ok()) << r.status();
  };
  send(100000, 4);  // under the cap at full bits: neither
  send(30000, 0);   // over at the floors
  send(30000, 4);   // brought under by minimum 2
  send(64, 3);      // thinned, and still over
  const std::string text = server::ScrapeMetrics(server->metrics_port());
  EXPECT_EQ(server::MetricValue(text, "cloudcast_frames_processed_total"), 4.0);
  EXPECT_EQ(server::MetricValue(text, "cloudcast_replies_over_cap_total"), 2.0);
  EXPECT_EQ(server::MetricValue(text, "cloudcast_replies_voxels_dropped_total"), 2.0);
}

TEST_F(DownlinkCapTest, BadValuesGetErrorsNamingTheField) {
  REQUIRE_FRAMES();
  client::StreamConfig config;
  config.mutable_draco()->set_max_cloud_bytes(10);
  absl::StatusOr<client::Result> r = Process("00001", config);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(r.status().message()), HasSubstr("config.draco.max_cloud_bytes is 10"));

  config.mutable_draco()->clear_max_cloud_bytes();
  config.mutable_draco()->set_min_color_bits(9);
  r = Process("00001", config);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(std::string(r.status().message()), HasSubstr("config.draco.min_color_bits"));

  // On a stream: a FrameError for the config whose FieldViolation names the field.
  auto stub = testing::NewStub(shared_server());
  grpc::ClientContext context;
  auto call = stub->Stream(&context);
  v1::StreamRequest request;
  request.mutable_config()->mutable_draco()->set_max_cloud_bytes(63);
  ASSERT_TRUE(call->Write(request));
  call->WritesDone();
  v1::StreamReply reply;
  ASSERT_TRUE(call->Read(&reply));
  ASSERT_TRUE(reply.has_error());
  EXPECT_EQ(reply.error().kind(), v1::ERROR_KIND_CONFIG);
  EXPECT_EQ(reply.error().code(), 3);
  ASSERT_EQ(reply.error().bad_request().field_violations_size(), 1);
  EXPECT_EQ(reply.error().bad_request().field_violations(0).field(),
            "config.draco.max_cloud_bytes");
  EXPECT_EQ(reply.error().bad_request().field_violations(0).reason(), "INVALID");
  EXPECT_TRUE(call->Finish().ok());

  // The client library's own checks, before anything is sent.
  client::StreamConfig c;
  EXPECT_THAT(std::string(client::SetMaxCloudBytes(5, &c).message()),
              StartsWith("config.draco.max_cloud_bytes is 5"));
  EXPECT_THAT(std::string(client::SetMaxCloudBytes(1000, &c, 9).message()),
              HasSubstr("config.draco.min_color_bits"));
  for (double bad : {-1.0, 0.01, 1e300}) {
    absl::StatusOr<std::uint64_t> b = client::MaxCloudBytesFromKb(bad, "--max-reply-kb");
    EXPECT_FALSE(b.ok());
    EXPECT_THAT(std::string(b.status().message()), StartsWith("--max-reply-kb is "));
  }
  EXPECT_EQ(client::MaxCloudBytesFromKb(12.5, "--max-reply-kb").value_or(0), 12500u);
  EXPECT_EQ(client::MaxCloudBytesFromKb(0, "--max-reply-kb").value_or(1), 0u);
}

// cloudcast-client --max-reply-kb: the cap reaches the server, the progress lines and the JSON
// show the bits and the clouds over the cap; a bad value is refused naming the flag.
TEST_F(DownlinkCapTest, ClientProgramFlag) {
  REQUIRE_FRAMES();
  const std::string binary = testing::BinDir() + "/cloudcast-client";
  ASSERT_TRUE(std::filesystem::exists(binary)) << binary << ": build cloudcast-client";
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() /
      ("cloudcast_downlink_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string json = (dir / "stats.json").string();
  const testing::RunResult r = testing::RunProgram(
      binary,
      {"--tsukuba", testing::TsukubaDir(), "--server", shared_target(), "--no-window",
       "--lossless", "--max-reply-kb", "30", "--json", json, "--progress", "0.01"},
      dir.string(), "env -u DISPLAY");
  ASSERT_TRUE(r.exited && r.code == 0) << r;
  const nlohmann::json j = nlohmann::json::parse(testing::ReadText(json));
  EXPECT_EQ(j["frames"]["received"], 10);
  // At the default bound frames 00001, 00400 and 01400 cannot come under 30 kB (the table in
  // docs/links.md); the others do.
  EXPECT_EQ(j["frames_over_cap"], 3);
  EXPECT_TRUE(j.contains("draco_bits"));
  EXPECT_EQ(j["draco_bits"]["position"], 10);
  EXPECT_NE(r.out.find("Draco bits (last cloud)"), std::string::npos) << r;

  // The cap's voxel step from the command line: the clouds the bits could not bring under it
  // come back thinned, and the JSON counts clouds by the minimum they were made with.
  const std::string thinned_json = (dir / "thinned.json").string();
  const testing::RunResult thinned = testing::RunProgram(
      binary,
      {"--tsukuba", testing::TsukubaDir(), "--server", shared_target(), "--no-window", "--lossless",
       "--max-reply-kb", "30", "--cap-min-points-per-voxel", "8", "--json", thinned_json,
       "--progress", "0"},
      dir.string(), "env -u DISPLAY");
  ASSERT_TRUE(thinned.exited && thinned.code == 0) << thinned;
  const nlohmann::json t = nlohmann::json::parse(testing::ReadText(thinned_json));
  const nlohmann::json& by_min = t["clouds_by_min_points_per_voxel"];
  EXPECT_EQ(by_min.value("0", 0), 7) << by_min;  // the seven the bits brought under
  int thinned_clouds = 0;
  for (const auto& [min_points, clouds] : by_min.items()) {
    if (min_points != "0") thinned_clouds += clouds.get<int>();
  }
  EXPECT_EQ(thinned_clouds, 3) << by_min;  // 00001, 00400 and 01400
  EXPECT_LT(t["frames_over_cap"].get<int>(), 3) << t;
  EXPECT_NE(thinned.out.find("clouds by voxel minimum"), std::string::npos) << thinned;

  const testing::RunResult bad = testing::RunProgram(
      binary,
      {"--tsukuba", testing::TsukubaDir(), "--server", shared_target(), "--no-window",
       "--max-reply-kb", "0.01"},
      dir.string(), "env -u DISPLAY");
  EXPECT_NE(bad.code, 0) << bad;
  EXPECT_NE(bad.err.find("--max-reply-kb is 0.01"), std::string::npos) << bad;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace cloudcast
