// The benchmark programs' own behaviour (never their times): cloudcast-e2e-bench measuring two
// server binaries in turn, and scripts/bench-against building another commit's server for it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "support/program_support.h"

namespace cloudcast {
namespace {

using testing::BinDir;
using testing::ReadText;
using testing::RunProgram;

class E2eBenchTest : public testing::ScratchDirTest {
 protected:
  std::string Bench() const { return BinDir() + "/cloudcast-e2e-bench"; }
  std::string Server() const { return BinDir() + "/cloudcast-server"; }
  // The shortest cases the bench allows: one stream, raw frames.
  std::vector<std::string> Short() const {
    return {"--seconds", "0.5", "--streams", "1", "--encodings", "raw"};
  }
};

double MedianOf(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.size() % 2 != 0 ? v[v.size() / 2] : (v[v.size() / 2 - 1] + v[v.size() / 2]) / 2;
}

TEST_F(E2eBenchTest, CompareBinRunsBothServersInTurnAndPrintsTheirMedians) {
  std::vector<std::string> args = Short();
  for (const char* a :
       {"--paced-fps", "20", "--rounds", "2", "--label", "left", "--compare-label", "right"}) {
    args.push_back(a);
  }
  args.insert(args.end(),
              {"--server-bin", Server(), "--compare-bin", Server(), "--json", Path("e2e.json")});
  const testing::RunResult r = RunProgram(Bench(), args, dir_.string());
  ASSERT_EQ(r.code, 0) << r;
  EXPECT_NE(r.out.find("medians over 2 rounds (left and right in turn"), std::string::npos) << r;
  EXPECT_NE(r.out.find("x: left / right"), std::string::npos) << r;

  const auto j = nlohmann::json::parse(ReadText(Path("e2e.json")));
  EXPECT_EQ(j["rounds"], 2);
  ASSERT_EQ(j["servers"].size(), 2u);
  EXPECT_EQ(j["servers"][0]["label"], "left");
  EXPECT_EQ(j["servers"][1]["label"], "right");
  // 2 rounds x 2 modes (throughput, paced) x 2 servers, the servers' order flipped in round 2.
  const auto& cases = j["cases"];
  ASSERT_EQ(cases.size(), 8u) << j.dump(1);
  const std::vector<std::string> order = {"left",  "right", "left",  "right",
                                          "right", "left",  "right", "left"};
  for (std::size_t i = 0; i < cases.size(); ++i) {
    SCOPED_TRACE(cases[i].dump());
    EXPECT_EQ(cases[i]["server"], order[i]);
    EXPECT_EQ(cases[i]["round"], i < 4 ? 1 : 2);
    EXPECT_EQ(cases[i]["mode"], i % 4 < 2 ? "throughput" : "paced 20 fps");
    EXPECT_GT(cases[i]["frames"].get<int>(), 0);
    EXPECT_EQ(cases[i]["errors"], 0);
    EXPECT_GT(cases[i]["server_cpu_ms_per_frame"].get<double>(), 0);
    EXPECT_GT(cases[i]["latency_ms_p50"].get<double>(), 0);
  }
  // One median per case and server, each the median of that pair's two rounds.
  const auto& medians = j["medians"];
  ASSERT_EQ(medians.size(), 4u) << j.dump(1);
  for (const auto& m : medians) {
    std::vector<double> fps, cpu, client;
    int frames = 0;
    for (const auto& c : cases) {
      if (c["server"] == m["server"] && c["mode"] == m["mode"]) {
        frames += c["frames"].get<int>();
        fps.push_back(c["fps"].get<double>());
        cpu.push_back(c["server_cpu_ms_per_frame"].get<double>());
        client.push_back(c["client_cpu_ms_per_frame"].get<double>());
      }
    }
    ASSERT_EQ(fps.size(), 2u) << m.dump();
    EXPECT_DOUBLE_EQ(m["fps"].get<double>(), MedianOf(fps)) << m.dump();
    EXPECT_DOUBLE_EQ(m["server_cpu_ms_per_frame"].get<double>(), MedianOf(cpu)) << m.dump();
    EXPECT_DOUBLE_EQ(m["client_cpu_ms_per_frame"].get<double>(), MedianOf(client)) << m.dump();
    EXPECT_GT(m["client_cpu_ms_per_frame"].get<double>(), 0) << m.dump();
    EXPECT_EQ(m["frames"].get<int>(), frames) << m.dump();  // summed over the rounds
    EXPECT_EQ(m["round"], 0) << m.dump();
  }
  EXPECT_EQ(medians[0]["server"], "left");
  EXPECT_EQ(medians[1]["server"], "right");
}

TEST_F(E2eBenchTest, OneServerOneRoundKeepsThePlainTable) {
  std::vector<std::string> args = Short();
  args.insert(args.end(), {"--paced-fps", "0", "--json", Path("e2e.json")});
  const testing::RunResult r = RunProgram(Bench(), args, dir_.string());
  ASSERT_EQ(r.code, 0) << r;
  EXPECT_EQ(r.out.find("medians over"), std::string::npos) << r;
  EXPECT_NE(r.out.find("\nenc  streams mode"), std::string::npos) << r;
  const auto j = nlohmann::json::parse(ReadText(Path("e2e.json")));
  ASSERT_EQ(j["cases"].size(), 1u);
  EXPECT_EQ(j["cases"][0]["server"], "this");
  EXPECT_EQ(j["medians"].size(), 1u);
  // By default every stream is a robot with a connection of its own (a Client each, and a
  // Client is a connection: client_test's EveryClientHasAConnectionOfItsOwn).
  EXPECT_EQ(j["shared_connection"], false);
  EXPECT_NE(r.out.find("a connection per stream"), std::string::npos) << r;
}

TEST_F(E2eBenchTest, SharedConnectionPutsAllStreamsOnOne) {
  const testing::RunResult r =
      RunProgram(Bench(),
                 {"--seconds", "0.5", "--streams", "2", "--encodings", "raw", "--paced-fps", "0",
                  "--shared-connection", "--json", Path("e2e.json")},
                 dir_.string());
  ASSERT_EQ(r.code, 0) << r;
  EXPECT_NE(r.out.find("all streams on one connection"), std::string::npos) << r;
  const auto j = nlohmann::json::parse(ReadText(Path("e2e.json")));
  EXPECT_EQ(j["shared_connection"], true);
  ASSERT_EQ(j["cases"].size(), 1u);
  EXPECT_EQ(j["cases"][0]["streams"], 2);
  EXPECT_GT(j["cases"][0]["frames"].get<int>(), 0);
  EXPECT_EQ(j["cases"][0]["errors"], 0);
}

// A server that refuses the frames (here: every frame is larger than its --max-pixels; in
// practice an older server that does not know an uplink encoding) answers fast and cheaply; the
// medians table says its figures are error replies rather than letting them pass as a speed-up.
TEST_F(E2eBenchTest, MediansSayWhenAServerAnsweredWithErrors) {
  const std::string refusing = Path("refusing-server");
  {
    std::ofstream script(refusing);
    script << "#!/bin/sh\nexec '" << Server() << "' \"$@\" --max-pixels 1000\n";
  }
  std::filesystem::permissions(refusing, std::filesystem::perms::owner_all);
  std::vector<std::string> args = Short();
  args.insert(args.end(), {"--paced-fps", "0", "--label", "good", "--compare-bin", refusing,
                           "--compare-label", "refusing", "--json", Path("e2e.json")});
  const testing::RunResult r = RunProgram(Bench(), args, dir_.string());
  ASSERT_EQ(r.code, 0) << r;
  const auto j = nlohmann::json::parse(ReadText(Path("e2e.json")));
  ASSERT_EQ(j["medians"].size(), 2u) << j.dump(1);
  EXPECT_EQ(j["medians"][0]["errors"], 0) << j.dump(1);
  const int errors = j["medians"][1]["errors"].get<int>();
  EXPECT_GT(errors, 0) << j.dump(1);
  EXPECT_EQ(errors, j["medians"][1]["frames"].get<int>()) << j.dump(1);  // every reply
  EXPECT_NE(r.out.find("  (refusing: " + std::to_string(errors) + " of " + std::to_string(errors) +
                       " replies were frame errors: its figures in this row are not clouds)"),
            std::string::npos)
      << r;
  EXPECT_EQ(r.out.find("  (good: "), std::string::npos) << r;
}

TEST_F(E2eBenchTest, BadServerFlagsAreNamed) {
  std::vector<std::string> args = Short();
  args.insert(args.end(), {"--compare-bin", Path("no-such-server")});
  testing::RunResult r = RunProgram(Bench(), args, dir_.string());
  EXPECT_EQ(r.code, 1) << r;
  EXPECT_NE(r.err.find("no cloudcast-server at " + Path("no-such-server") + " (--compare-bin)"),
            std::string::npos)
      << r;

  args = Short();
  args.insert(args.end(), {"--compare-bin", Server(), "--label", "x", "--compare-label", "x"});
  r = RunProgram(Bench(), args, dir_.string());
  EXPECT_EQ(r.code, 1) << r;
  EXPECT_NE(r.err.find("--compare-label must differ from --label"), std::string::npos) << r;
}

// The script end to end: it builds HEAD's server in a worktree of its own (from ccache, after
// the main build) and measures it against this build's. Slow on a cold cache (one server build).
// A worktree the test made is removed afterwards, so that test runs do not pile them up.
TEST_F(E2eBenchTest, BenchAgainstBuildsTheCommitsServerAndComparesIt) {
  const std::string source = CLOUDCAST_SOURCE_DIR;
  const std::string script = source + "/scripts/bench-against";
  const testing::RunResult head =
      RunProgram("git", {"-C", source, "rev-parse", "--short", "HEAD"}, dir_.string());
  ASSERT_EQ(head.code, 0) << head;
  const std::string relative =
      "build-against/" + head.out.substr(0, head.out.find_last_not_of("\n") + 1);
  const std::string worktree = source + "/" + relative;
  const bool existed = std::filesystem::exists(worktree);
  struct RemoveWorktree {
    std::string source, path;
    bool keep;
    ~RemoveWorktree() {
      if (keep) return;
      const std::string command = "git -C " + testing::ShellQuote(source) +
                                  " worktree remove --force " + testing::ShellQuote(path) +
                                  " >/dev/null 2>&1";
      (void)std::system(command.c_str());
    }
  } cleanup{source, worktree, existed};

  const std::string env = "env CLOUDCAST_BUILD_DIR=" + testing::ShellQuote(CLOUDCAST_BUILD_DIR);
  testing::RunResult r = RunProgram(script, {"no-such-revision"}, dir_.string(), env);
  EXPECT_EQ(r.code, 2) << r;
  EXPECT_NE(r.err.find("'no-such-revision' is not a commit"), std::string::npos) << r;

  std::vector<std::string> args = {"HEAD"};
  const std::vector<std::string> s = Short();
  args.insert(args.end(), s.begin(), s.end());
  args.insert(args.end(), {"--paced-fps", "0", "--rounds", "1", "--json", Path("e2e.json")});
  r = RunProgram(script, args, dir_.string(), env);
  ASSERT_EQ(r.code, 0) << r;
  const auto j = nlohmann::json::parse(ReadText(Path("e2e.json")));
  ASSERT_EQ(j["servers"].size(), 2u);
  const std::string built = j["servers"][1]["binary"];
  EXPECT_EQ(built, relative + "/build/bin/cloudcast-server");
  EXPECT_NE(built, j["servers"][0]["binary"].get<std::string>());
  ASSERT_EQ(j["cases"].size(), 2u);
  for (const auto& c : j["cases"]) EXPECT_GT(c["frames"].get<int>(), 0) << c.dump();
}

}  // namespace
}  // namespace cloudcast
