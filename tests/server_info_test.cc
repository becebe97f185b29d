// What the server says about itself, end to end: health checking and reflection (spoken through
// the generic stub), GetInfo's limits and defaults, the Prometheus endpoint's counters; and the
// server's flags and config file.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "cloudcast/server/cli.h"
#include "cloudcast/server/options.h"
#include "cloudcast/testing/metrics_scrape.h"
#include "support/program_support.h"
#include "support/replica_support.h"
#include "support/server_support.h"

namespace cloudcast::server {
namespace {

using std::chrono::milliseconds;

TEST_F(ServerTest, HealthCheckingAndReflectionAnswer) {
  const auto channel = testing::NewChannel(shared_server());
  EXPECT_EQ(HealthStatus(channel, ""), 1);  // SERVING
  EXPECT_EQ(HealthStatus(channel, "cloudcast.v1.CloudCast"), 1);

  // list_services (field 7) -> list_services_response (6) -> service (1) -> name (1).
  const auto listed = Reflect(channel, 7, "");
  const auto* list = FieldOf(*listed, 6);
  ASSERT_NE(list, nullptr);
  google::protobuf::UnknownFieldSet services;
  ASSERT_TRUE(services.ParseFromString(list->length_delimited()));
  std::vector<std::string> names;
  for (int i = 0; i < services.field_count(); ++i) {
    google::protobuf::UnknownFieldSet service;
    ASSERT_TRUE(service.ParseFromString(services.field(i).length_delimited()));
    if (const auto* name = FieldOf(service, 1)) names.push_back(name->length_delimited());
  }
  EXPECT_NE(std::find(names.begin(), names.end(), "cloudcast.v1.CloudCast"), names.end());
  EXPECT_NE(std::find(names.begin(), names.end(), "grpc.health.v1.Health"), names.end());

  // file_containing_symbol (4) -> file_descriptor_response (4) -> file_descriptor_proto (1).
  const auto file = Reflect(channel, 4, "cloudcast.v1.CloudCast");
  const auto* response = FieldOf(*file, 4);
  ASSERT_NE(response, nullptr);
  google::protobuf::UnknownFieldSet files;
  ASSERT_TRUE(files.ParseFromString(response->length_delimited()));
  bool found = false;
  for (int i = 0; i < files.field_count(); ++i) {
    google::protobuf::FileDescriptorProto proto;
    ASSERT_TRUE(proto.ParseFromString(files.field(i).length_delimited()));
    for (const auto& service : proto.service()) {
      if (service.name() != "CloudCast") continue;
      found = true;
      std::vector<std::string> methods;
      for (const auto& m : service.method()) methods.push_back(m.name());
      EXPECT_EQ(methods, (std::vector<std::string>{"Stream", "Process", "GetInfo"}));
    }
  }
  EXPECT_TRUE(found);
}

TEST_F(ServerTest, GetInfoReportsLimitsAndDefaults) {
  v1::ServerInfo info;
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  ASSERT_TRUE(stub_->GetInfo(&ctx, v1::GetInfoRequest(), &info).ok());
  const ServerOptions defaults;
  EXPECT_FALSE(info.version().empty());
  EXPECT_EQ(info.limits().max_message_bytes(), 64u << 20);
  EXPECT_EQ(info.limits().max_side(), 16384u);
  EXPECT_EQ(info.limits().max_pixels(), 1u << 24);
  EXPECT_EQ(info.limits().max_streams(), 64u);
  EXPECT_EQ(info.limits().idle_timeout_seconds(), 60u);
  EXPECT_EQ(info.limits().max_queued_frames(), 4u);
  // Issue 18's limits a client can act on.
  EXPECT_EQ(info.limits().work_memory_bytes(), 320u << 20);
  EXPECT_EQ(info.limits().work_bytes_per_pixel(), 128u);
  EXPECT_EQ(info.limits().max_streams_per_client(), 32u);
  EXPECT_EQ(info.limits().max_process_per_client(), 32u);
  EXPECT_EQ(info.limits().shed_quiet_after_ms(), 2000u);
  EXPECT_EQ(info.contract_revision(), "5");
  // The suite's server runs with the preset new_tsukuba as its operator's defaults
  // (TestServerOptions); the contract's own, without a camera: contract_test.
  const v1::StreamConfig& d = info.defaults();
  EXPECT_EQ(d.camera().fx(), 615.0);
  EXPECT_EQ(d.camera().fy(), 615.0);
  EXPECT_FALSE(d.camera().has_cx());
  EXPECT_EQ(d.camera().baseline(), 1.0);
  EXPECT_EQ(d.camera().invalid_disparities().values_size(), 2);
  EXPECT_TRUE(d.passthrough().enabled());
  EXPECT_EQ(d.passthrough().axis(), v1::AXIS_Z);
  EXPECT_EQ(d.passthrough().min(), 3.0f);
  EXPECT_EQ(d.passthrough().max(), 12.0f);
  EXPECT_TRUE(d.voxel_grid().enabled());
  EXPECT_FLOAT_EQ(d.voxel_grid().leaf(), 0.03f);
  EXPECT_EQ(d.draco().position_bits(), DracoOptions{}.position_bits);
  EXPECT_EQ(d.draco().color_bits(), 8);
  EXPECT_EQ(d.draco().encode_speed(), 10);
  EXPECT_FLOAT_EQ(d.draco().max_position_error(), 0.0075f);
  EXPECT_EQ(d.delivery(), v1::DELIVERY_LATEST);
  EXPECT_EQ(info.disparity_encodings_size(), 3);
  EXPECT_EQ(info.color_encodings_size(), 4);
  EXPECT_NE(std::find(info.image_formats().begin(), info.image_formats().end(), "jpeg"),
            info.image_formats().end());
  EXPECT_EQ(info.worker_threads(), 2u);
  EXPECT_EQ(info.draco_version(), "1.5.5");
}

TEST(ServerMetricsTest, PrometheusEndpointServesTheCounters) {
  ServerOptions options = testing::TestServerOptions();
  options.metrics_listen = "127.0.0.1:0";
  auto server = testing::StartTestServer(options);
  ASSERT_NE(server, nullptr);
  ASSERT_GT(server->metrics_port(), 0);
  auto stub = testing::NewStub(*server);
  v1::Frame bad = MakeFrame(Frames()[0], 2);
  bad.clear_color();
  const StreamResult result =
      RunStream(*stub, {ConfigRequest(ConfigFor(Params{}, v1::DELIVERY_ALL)),
                        FrameRequest(MakeFrame(Frames()[0], 1)), FrameRequest(bad),
                        FrameRequest(MakeFrame(Frames()[1 % Frames().size()], 3, Input::kPng))});
  ASSERT_TRUE(result.status.ok());
  const std::string text = cloudcast::server::ScrapeMetrics(server->metrics_port());
  ASSERT_NE(text.find("200 OK"), std::string::npos) << text.substr(0, 200);
  EXPECT_EQ(MetricValue(text, "cloudcast_frames_processed_total"), 2.0);
  EXPECT_EQ(MetricValue(text, "cloudcast_streams_accepted_total"), 1.0);
  EXPECT_GT(MetricValue(text, "cloudcast_bytes_received_total"), 640.0 * 480 * 4);
  EXPECT_GT(MetricValue(text, "cloudcast_bytes_sent_total"), 0.0);
  EXPECT_GT(MetricValue(text, "cloudcast_core_cpu_seconds_total"), 0.0);
  EXPECT_GE(MetricValue(text, "cloudcast_worker_cpu_seconds_total"),
            MetricValue(text, "cloudcast_core_cpu_seconds_total"));
  EXPECT_GT(MetricValue(text, "cloudcast_process_cpu_seconds_total"), 0.0);
  EXPECT_NE(text.find("cloudcast_frame_errors_total{code=\"INVALID_ARGUMENT\"} 1"),
            std::string::npos);
  EXPECT_NE(text.find("cloudcast_active_streams"), std::string::npos);
  for (const char* stage : {"decode", "pipeline", "encode", "queue", "total"}) {
    EXPECT_NE(text.find(std::string("cloudcast_stage_seconds_count{stage=\"") + stage + "\"}"),
              std::string::npos)
        << stage;
  }
  EXPECT_NE(text.find("cloudcast_stage_seconds_count{stage=\"decode\"} 1"), std::string::npos);
}

TEST(ServerOptionsTest, FlagsAndConfigFile) {
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("cloudcast_server_test_" + std::to_string(getpid()) + ".toml"))
                               .string();
  {
    std::ofstream out(path);
    out << "max-streams = 8\nidle-timeout = 2.5\ndelivery = \"all\"\nleaf = 0.05\n"
           "listen = \"127.0.0.1:6000\"\n";
  }
  CLI::App app;
  ServerFlags flags(app);
  std::vector<std::string> args = {"--config", path, "--leaf", "0.07"};
  std::reverse(args.begin(), args.end());  // CLI11 takes them last-first
  ASSERT_NO_THROW(app.parse(args));
  auto options = flags.Options();
  ASSERT_TRUE(options.ok()) << options.status();
  EXPECT_EQ(options->max_streams, 8u);
  EXPECT_EQ(options->idle_timeout, milliseconds(2500));
  EXPECT_EQ(options->defaults.delivery, Delivery::kAll);
  EXPECT_FLOAT_EQ(options->defaults.frame.pipeline.voxel.leaf_x, 0.07f);  // the command line wins
  EXPECT_EQ(options->listen, "127.0.0.1:6000");
  EXPECT_EQ(options->max_queued_frames, 4u);  // untouched default
  std::filesystem::remove(path);

  // Every flag shows its default in --help.
  const std::string help = app.help();
  for (const char* flag : {"--listen",
                           "--threads",
                           "--max-message-bytes",
                           "--max-side",
                           "--max-pixels",
                           "--max-streams",
                           "--idle-timeout",
                           "--max-queued-frames",
                           "--shutdown-grace",
                           "--metrics-listen",
                           "--focal",
                           "--axis",
                           "--min",
                           "--max",
                           "--leaf",
                           "--draco-bits",
                           "--draco-speed",
                           "--delivery",
                           "--log-level",
                           "--config",
                           "--tls-cert",
                           "--tls-key",
                           "--tls-client-ca",
                           "--tokens-file",
                           "--no-reflection"}) {
    EXPECT_NE(help.find(flag), std::string::npos) << flag;
  }
  EXPECT_NE(help.find("=0.0.0.0:50051"), std::string::npos) << help;

  CLI::App bad_app;
  ServerFlags bad(bad_app);
  std::vector<std::string> bad_args = {"--max-queued-frames", "0"};
  std::reverse(bad_args.begin(), bad_args.end());
  bad_app.parse(bad_args);
  EXPECT_FALSE(bad.Options().ok());
}

// A misspelt key in --config was silently ignored (CLI11's default): now it is an error that
// names the key, and cloudcast-server exits 2 (a usage error).
TEST(ServerOptionsTest, UnknownConfigKeyIsAnError) {
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("cloudcast_server_test_bad_" + std::to_string(getpid()) + ".toml"))
                               .string();
  {
    std::ofstream out(path);
    out << "max-streams = 8\nmax-streamz = 3\n";
  }
  CLI::App app;
  ServerFlags flags(app);
  std::vector<std::string> args = {"--config", path};
  std::reverse(args.begin(), args.end());
  try {
    app.parse(args);
    ADD_FAILURE() << "the unknown key was accepted";
  } catch (const CLI::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("max-streamz"), std::string::npos) << e.what();
  }
  const testing::RunResult r =
      testing::RunProgram(testing::BinDir() + "/cloudcast-server", {"--config", path},
                          std::filesystem::temp_directory_path().string());
  EXPECT_EQ(r.code, 2) << r;
  EXPECT_NE(r.err.find("max-streamz"), std::string::npos) << r;
  std::filesystem::remove(path);
}

// --no-reflection reaches the options; reflection is on by default.
TEST(ServerOptionsTest, NoReflectionFlag) {
  for (bool given : {false, true}) {
    CLI::App app;
    ServerFlags flags(app);
    std::vector<std::string> args;
    if (given) args.push_back("--no-reflection");
    app.parse(args);
    auto options = flags.Options();
    ASSERT_TRUE(options.ok()) << options.status();
    EXPECT_EQ(options->reflection, !given);
  }
}

// Servers asked for port 0 say which ports they bound (--ready-file), so that tests and scripts
// never pick a "free" port and then race other processes for it: two at once get two ports, each
// serving gRPC and /metrics where its file says. A file that cannot be written stops the server.
TEST(ServerOptionsTest, ReadyFileNamesTheAddressesItBound) {
  const std::string dir = ::testing::TempDir();
  testing::ServerProcess first("127.0.0.1:0", "first", {}, dir + "/ready_first.log", "warn",
                               "127.0.0.1:0");
  testing::ServerProcess second("127.0.0.1:0", "second", {}, dir + "/ready_second.log", "warn",
                                "127.0.0.1:0");
  for (testing::ServerProcess* server : {&first, &second}) {
    ASSERT_TRUE(server->WaitUntilServing()) << server->log();
    EXPECT_NE(server->address(), "127.0.0.1:0");
    ASSERT_GT(server->metrics_port(), 0);
    EXPECT_NE(ScrapeMetrics(server->metrics_port()).find("cloudcast_active_streams"),
              std::string::npos);
  }
  EXPECT_NE(first.address(), second.address());
  EXPECT_NE(first.metrics_port(), second.metrics_port());

  const testing::RunResult r = testing::RunProgram(
      testing::BinDir() + "/cloudcast-server",
      {"--listen", "127.0.0.1:0", "--metrics-listen", "", "--ready-file",
       dir + "/no-such-folder/ready"},
      dir);
  EXPECT_EQ(r.code, 1) << r;
  EXPECT_NE((r.out + r.err).find("--ready-file"), std::string::npos) << r;
}

}  // namespace
}  // namespace cloudcast::server
