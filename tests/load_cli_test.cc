// cloudcast-load and cloudcast-null-server as programs: flag errors that name the flag, the
// health probe, SIGTERM ending a run with its report written, and the HTML page rendered by
// Debian's chromium, headless, with its charts checked in the screenshot.
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_split.h"
#include "cloudcast/load/null_server.h"
#include "support/program_support.h"
#include "support/server_fixture.h"
#include "support/test_support.h"
#include "support/waiting.h"

extern char** environ;

namespace cloudcast::testing {
namespace {

using nlohmann::json;

std::string Load() { return BinDir() + "/cloudcast-load"; }

class LoadCliTest : public ScratchDirTest {
 protected:
  void SetUp() override {
    ScratchDirTest::SetUp();
    null_ = load::NullServer::Start("127.0.0.1:0", "null").value();
  }
  RunResult Run(std::vector<std::string> args) { return RunProgram(Load(), args, dir_.string()); }
  std::unique_ptr<load::NullServer> null_;
};

TEST_F(LoadCliTest, BadFlagsExitTwoNamingTheFlag) {
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
      {{"--streams", "0"}, "--streams"},
      {{"--fps", "nan"}, "--fps"},
      {{"--duration", "0"}, "--frames"},
      {{"--duration", "99999"}, "--duration"},
      {{"--frames", "1.5"}, "--frames"},
      {{"--schedule", "step"}, "--load-step"},
      {{"--schedule", "zigzag"}, "--schedule"},
      {{"--load-end", "10"}, "--schedule"},
      {{"--encoding", "webp"}, "--encoding"},
      {{"--fps", "30", "--in-flight", "2"}, "--in-flight"},
      {{"--synthetic", "0x10"}, "--synthetic"},
      {{"--json", "/nonexistent/dir/r.json"}, "--json"},
      {{"--tsukuba", "/nonexistent"}, "--tsukuba"},
      {{"--lb", "random"}, "--lb"},
      {{"--reconnect-timeout", "3"}, "--resilient"},
      {{"--resilient", "--reconnect-timeout", "0"}, "--reconnect-timeout"},
      {{"--input", "lidar"}, "--input"},
      {{"--matcher", "sgbm"}, "--matcher applies to --input stereo only"},
      {{"--input", "stereo", "--num-disparities", "100"}, "--num-disparities is 100"},
      {{"--input", "stereo", "--matcher", "census"}, "--matcher"},
      {{"--depth-glob", "z/*.png"}, "--depth-glob does not apply to --input disparity"},
      {{"--input", "stereo", "--colour-glob", "c/*.png"}, "needs --right-glob"},
      {{"--rate-target-delay-ms", "15"}, "--rate-target-delay-ms needs --rate-control"},
      {{"--rate-control", "--rate-max-mbps", "inf"}, "--rate-max-mbps"},
      {{"--max-point-error", "-0.01"}, "--max-point-error"},
      {{"--max-point-error", "nan"}, "--max-point-error"},
      {{"--max-point-error", "inf"}, "--max-point-error"},
      {{"--max-point-error", "0.01"}, "--max-point-error needs an encoding that compresses"},
      {{"--max-point-error", "0.01", "--input", "stereo", "--encoding", "zstd"},
       "--max-point-error applies to disparity and depth frames"},
  };
  for (const auto& [args, flag] : cases) {
    std::vector<std::string> full = {"--server", null_->address(), "--synthetic", "64x48"};
    if (args[0] == "--synthetic" || args[0] == "--tsukuba") full = {"--server", null_->address()};
    full.insert(full.end(), args.begin(), args.end());
    const RunResult r = Run(full);
    EXPECT_FALSE(r.crashed()) << r;
    EXPECT_NE(r.code, 0) << args[0] << "\n" << r;
    EXPECT_NE((r.out + r.err).find(flag), std::string::npos) << args[0] << "\n" << r;
  }
}

// --max-point-error explains its unit, what it bounds and its lossless value.
TEST_F(LoadCliTest, HelpExplainsTheMaxPointError) {
  const RunResult r = Run({"--help"});
  ASSERT_EQ(r.code, 0) << r;
  const std::size_t at = r.out.find("--max-point-error");
  ASSERT_NE(at, std::string::npos) << r;
  // The description as one line (the help wraps it).
  std::string text;
  for (char c : r.out.substr(at, 1400)) {
    const bool space = c == ' ' || c == '\n';
    if (!space || (!text.empty() && text.back() != ' ')) text += space ? ' ' : c;
  }
  for (const char* words : {"metres", "per point", "half-resolution", "0 = lossless", "stereo"}) {
    EXPECT_NE(text.find(words), std::string::npos) << words << "\n" << text;
  }
}

// Every --input against a real server: every frame is answered with a cloud, none with an
// error, and the report says what the frames held.
TEST_F(LoadCliTest, EveryInputKindIsAnsweredByARealServer) {
  const std::unique_ptr<server::Server> server = StartTestServer();
  ASSERT_NE(server, nullptr);
  std::vector<std::string> source = {"--synthetic", "320x240", "--synthetic-frames", "2"};
  if (HaveTsukuba()) source = {"--tsukuba", TsukubaDir()};
  for (const std::string input : {"disparity", "depth", "stereo"}) {
    SCOPED_TRACE(input);
    std::vector<std::string> args = {"--server",
                                     server->address(),
                                     "--input",
                                     input,
                                     "--streams",
                                     "2",
                                     "--fps",
                                     "0",
                                     "--frames",
                                     "6",
                                     "--lossless",
                                     "--json",
                                     Path(input + ".json"),
                                     "-q"};
    args.insert(args.end(), source.begin(), source.end());
    if (input == "stereo") args.insert(args.end(), {"--matcher", "sgm", "--num-disparities", "64"});
    const RunResult r = Run(args);
    ASSERT_EQ(r.code, 0) << r;
    EXPECT_NE(r.out.find(" " + input + " frames, "), std::string::npos) << r;
    const json j = json::parse(ReadText(Path(input + ".json")));
    EXPECT_EQ(j["frames"]["answered"], 6) << j["frames"];
    EXPECT_EQ(j["frames"]["frameErrors"], 0) << j["errorDistribution"];
    // Clouds came back, not empty replies: a few KB of Draco each.
    EXPECT_GT(j["frames"]["bytesReceived"].get<double>(), 6 * 1000.0) << j["frames"];
    EXPECT_EQ(j["options"]["input"], input);
    if (input == "stereo") {
      EXPECT_NE(j["options"]["config"].get<std::string>().find("num_disparities: 64"),
                std::string::npos)
          << j["options"]["config"];
    }
  }
}

// --frame-log: a line per answered frame, each step of its way in order on the one clock client
// and server share here (write, the server's receipt and send, receipt), its latency from the
// intended time, and what the server made of it; a folder that does not exist is a usage error.
TEST_F(LoadCliTest, FrameLogHasALinePerAnsweredFrameInTheOrderOfItsWay) {
  const std::unique_ptr<server::Server> server = StartTestServer();
  ASSERT_NE(server, nullptr);
  const RunResult r =
      Run({"--server", server->address(), "--synthetic", "320x240", "--synthetic-frames", "2",
           "--streams", "2", "--fps", "30", "--frames", "12", "--lossless", "--json",
           Path("r.json"), "--frame-log", Path("frames.csv"), "-q"});
  ASSERT_EQ(r.code, 0) << r;
  std::ifstream in(Path("frames.csv"));
  std::string line;
  ASSERT_TRUE(std::getline(in, line));
  std::vector<std::string> header = absl::StrSplit(line, ',');
  ASSERT_EQ(header.size(), 21u) << line;
  EXPECT_EQ(header[0], "stream");
  EXPECT_EQ(header[7], "latency_ms");
  std::map<std::string, std::size_t> column;
  for (std::size_t i = 0; i < header.size(); ++i) column[header[i]] = i;
  int rows = 0;
  std::set<std::pair<int, std::uint64_t>> frames;
  while (std::getline(in, line)) {
    ++rows;
    const std::vector<std::string> f = absl::StrSplit(line, ',');
    ASSERT_EQ(f.size(), header.size()) << line;
    auto i64 = [&](const char* name) { return std::stoll(f[column.at(name)]); };
    frames.insert({static_cast<int>(i64("stream")), static_cast<std::uint64_t>(i64("sequence"))});
    EXPECT_LE(i64("intended_unix_ns") - 50'000'000, i64("written_unix_ns")) << line;
    EXPECT_LE(i64("written_unix_ns"), i64("server_receive_unix_ns")) << line;
    EXPECT_LE(i64("server_receive_unix_ns"), i64("server_send_unix_ns")) << line;
    EXPECT_LE(i64("server_send_unix_ns"), i64("received_unix_ns")) << line;
    EXPECT_NEAR(std::stod(f[column.at("latency_ms")]),
                static_cast<double>(i64("received_unix_ns") - i64("intended_unix_ns")) / 1e6, 0.01)
        << line;
    EXPECT_GT(i64("image_bytes"), 0) << line;
    EXPECT_GT(i64("reply_bytes"), 0) << line;
    EXPECT_GT(i64("points"), 0) << line;
    EXPECT_GT(i64("pipeline_us"), 0) << line;
    EXPECT_FALSE(f[column.at("instance")].empty()) << line;
  }
  const json j = json::parse(ReadText(Path("r.json")));
  EXPECT_EQ(rows, j["frames"]["answered"].get<int>());
  EXPECT_EQ(rows, 12);
  EXPECT_EQ(frames.size(), 12u);  // each frame once

  const RunResult bad = Run({"--server", server->address(), "--synthetic", "64x48", "--frames", "1",
                             "--frame-log", Path("no/such/folder/frames.csv")});
  EXPECT_EQ(bad.code, 2) << bad;
  EXPECT_NE(bad.err.find("--frame-log"), std::string::npos) << bad;
}

TEST_F(LoadCliTest, UnreachableServerExitsOneNamingIt) {
  const RunResult r = Run({"--server", "127.0.0.1:1", "--connect-timeout", "0.3", "--synthetic",
                           "64x48", "--frames", "5"});
  EXPECT_EQ(r.code, 1) << r;
  EXPECT_NE(r.err.find("--server 127.0.0.1:1"), std::string::npos) << r;
}

TEST_F(LoadCliTest, ProbeAnswersZeroWhenServingAndOneOtherwise) {
  const RunResult ok = Run({"--probe", "--server", null_->address()});
  EXPECT_EQ(ok.code, 0) << ok;
  EXPECT_NE(ok.out.find("SERVING"), std::string::npos) << ok;
  const RunResult bad = Run({"--probe", "--server", "127.0.0.1:1", "--connect-timeout", "0.3"});
  EXPECT_EQ(bad.code, 1) << bad;
  const RunResult unknown =
      Run({"--probe", "--server", null_->address(), "--probe-service", "no.such.Service"});
  EXPECT_EQ(unknown.code, 1) << unknown;
}

TEST_F(LoadCliTest, BoundedByFramesWritesTableAndJson) {
  const RunResult r =
      Run({"--server", null_->address(), "--synthetic", "64x48", "--streams", "3", "--fps", "100",
           "--frames", "30", "--lossless", "--json", Path("r.json"), "-q"});
  ASSERT_EQ(r.code, 0) << r;
  EXPECT_NE(r.out.find("latency (intended)"), std::string::npos) << r;
  const json j = json::parse(ReadText(Path("r.json")));
  EXPECT_EQ(j["count"], 30);
  EXPECT_EQ(j["frames"]["answered"], 30);
  EXPECT_EQ(j["endReason"], "normal");
  EXPECT_EQ(j["options"]["concurrency"], 3);
  // One account per stream, and the balancing a single address gets.
  ASSERT_EQ(j["streams"].size(), 3u);
  for (const json& s : j["streams"]) {
    EXPECT_EQ(s["sent"], 10) << s;
    EXPECT_EQ(s["answered"], 10) << s;
    EXPECT_EQ(s["replicas"], json::array({"null"})) << s;
  }
  EXPECT_EQ(j["loadBalancing"]["policy"], "pick_first");
  EXPECT_EQ(j["resilience"]["enabled"], false);
  EXPECT_EQ(j["replicas"]["null"]["streams"], 3);
}

TEST_F(LoadCliTest, SigtermEndsTheRunAndStillWritesTheReport) {
  const std::string json_path = Path("term.json"), out = Path("term.out"), err = Path("term.err");
  const std::string command = ShellQuote(Load()) + " --server " + null_->address() +
                              " --synthetic 160x120 --streams 2 --fps 50 --duration 120 --json " +
                              ShellQuote(json_path) + " >" + ShellQuote(out) + " 2>" +
                              ShellQuote(err);
  pid_t pid = 0;
  const char* argv[] = {"/bin/sh", "-c", command.c_str(), nullptr};
  // exec, so the signal reaches cloudcast-load itself rather than the shell.
  const std::string exec_command = "exec " + command;
  argv[2] = exec_command.c_str();
  ASSERT_EQ(posix_spawn(&pid, "/bin/sh", nullptr, nullptr, const_cast<char**>(argv), environ), 0);
  // Once progress lines show frames flowing: the child's stderr announces nothing to wait on.
  EXPECT_TRUE(cloudcast::testing::Eventually(
      [&] { return ReadText(err).find("frames/s") != std::string::npos; }));
  ASSERT_EQ(kill(pid, SIGTERM), 0);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status)) << ReadText(err);
  EXPECT_EQ(WEXITSTATUS(status), 0) << ReadText(err);
  const json j = json::parse(ReadText(json_path));
  EXPECT_EQ(j["endReason"], "cancel");
  EXPECT_GT(j["frames"]["answered"].get<int>(), 0);
  EXPECT_NE(ReadText(out).find("cancel"), std::string::npos);
}

// Pixels of roughly `bgr` in `image`.
int CountColour(const cv::Mat& image, cv::Vec3b bgr) {
  int n = 0;
  for (int y = 0; y < image.rows; ++y) {
    for (int x = 0; x < image.cols; ++x) {
      const cv::Vec3b p = image.at<cv::Vec3b>(y, x);
      if (std::abs(p[0] - bgr[0]) + std::abs(p[1] - bgr[1]) + std::abs(p[2] - bgr[2]) < 40) ++n;
    }
  }
  return n;
}

TEST_F(LoadCliTest, HtmlReportRendersItsChartsInHeadlessChromium) {
  const std::string chromium = "/usr/bin/chromium";
  if (!std::filesystem::exists(chromium)) {
    GTEST_SKIP() << "Debian's chromium is not installed (scripts/setup --long installs it, as ./scripts/test --all does): the HTML "
                    "page cannot be rendered here";
  }
  const RunResult r = Run({"--server", null_->address(), "--synthetic", "160x120", "--streams", "4",
                           "--fps", "60", "--duration", "3", "--html", Path("r.html"), "-q"});
  ASSERT_EQ(r.code, 0) << r;
  const std::string html = ReadText(Path("r.html"));
  EXPECT_EQ(html.find("<script"), std::string::npos);
  EXPECT_NE(html.find("<svg id=\"downlink-chart\""), std::string::npos);  // the replies
  // Nothing from the network: the only address is the SVG namespace, which is no download.
  std::string rest = html;
  for (std::size_t at;
       (at = rest.find("xmlns=\"http://www.w3.org/2000/svg\"")) != std::string::npos;) {
    rest.erase(at, 34);
  }
  EXPECT_EQ(rest.find("http://"), std::string::npos);
  EXPECT_EQ(rest.find("https://"), std::string::npos);
  const std::string png = Path("r.png");
  const RunResult shot =
      RunProgram(chromium,
                 {"--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--user-data-dir=" + Path("chrome-profile"), "--screenshot=" + png,
                  "--window-size=1000,1400", "file://" + Path("r.html")},
                 dir_.string(), "timeout 120");
  ASSERT_TRUE(std::filesystem::exists(png)) << shot;
  const cv::Mat image = cv::imread(png, cv::IMREAD_COLOR);
  ASSERT_FALSE(image.empty());
  // The p99 line (#e45756), the p50 line and the histogram's bars (#4c78a8), and the
  // throughput line (#54a24b) are drawn.
  EXPECT_GT(CountColour(image, {0x56, 0x57, 0xe4}), 200);
  EXPECT_GT(CountColour(image, {0xa8, 0x78, 0x4c}), 1000);
  EXPECT_GT(CountColour(image, {0x4b, 0xa2, 0x54}), 200);
  // Keep the screenshot where a person can look at it.
  std::filesystem::copy_file(png, std::string(CLOUDCAST_BIN_DIR) + "/../load_report_screenshot.png",
                             std::filesystem::copy_options::overwrite_existing);
}

}  // namespace
}  // namespace cloudcast::testing
