// End-to-end tests of cloudcast-process: the real binary, run through the shell on synthetic
// frames, on image files of every depth written here, and on a New Tsukuba frame. Its files are
// read back by PCL, Open3D and the draco_decoder tool and compared with an in-process run of the
// pipeline and with stock PCL's chain. (image_io and cloud_io on their own: image_io_test.cc,
// cloud_io_test.cc.)
#include <gtest/gtest.h>
#include <open3d/geometry/PointCloud.h>
#include <open3d/io/PointCloudIO.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <string>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "cloudcast/core/camera.h"
#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/filters.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/core/point.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/io/cloud_io.h"
#include "cloudcast/io/image_io.h"
#include "cloudcast/reference/pcl_reference.h"
#include "support/cloud_match.h"
#include "support/image_files.h"
#include "support/program_support.h"
#include "support/test_support.h"

namespace cloudcast {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

// ---------------------------------------------------------------------------------------------
// Running the binary.

std::string Binary() { return std::string(CLOUDCAST_BIN_DIR) + "/cloudcast-process"; }

using testing::Be16;
using testing::Bytes;
using testing::CloudsMatch;
using testing::CloudTolerance;
using testing::FloatTiff;
using testing::Png;
using testing::ReadText;
using testing::RgbaRowsFromBgr;
using testing::RunResult;
using testing::SamePoints;
using testing::ShellQuote;
using testing::WriteFile;

class CliTest : public testing::ScratchDirTest {
 protected:
  void SetUp() override {
    ASSERT_TRUE(fs::exists(Binary())) << Binary() << " is missing: build cloudcast-process";
    testing::ScratchDirTest::SetUp();
  }

  RunResult Run(const std::vector<std::string>& args) const {
    return testing::RunProgram(Binary(), args, dir_.string());
  }

  // Runs and expects success; returns the parsed --json report.
  Json RunOk(std::vector<std::string> args, RunResult* result = nullptr) const {
    const std::string json = Path("report.json");
    args.push_back("--json");
    args.push_back(json);
    const RunResult r = Run(args);
    if (result != nullptr) *result = r;
    EXPECT_TRUE(r.exited && r.code == 0) << r;
    if (!fs::exists(json)) {
      ADD_FAILURE() << "no JSON report written\n" << r;
      return Json::object();
    }
    return Json::parse(ReadText(json), nullptr, /*allow_exceptions=*/false);
  }
};

Json Stage(const Json& report, const std::string& name) {
  if (report.contains("stages")) {
    for (const Json& s : report["stages"]) {
      if (s.value("name", "") == name) return s;
    }
  }
  ADD_FAILURE() << "stage '" << name << "' missing from " << report.dump(2);
  return Json::object();
}

std::uint64_t StagePoints(const Json& report, const std::string& name) {
  return Stage(report, name).value("points", std::uint64_t{0});
}

// ---------------------------------------------------------------------------------------------
// Clouds.

PointCloud FromPclCloud(const pcl::PointCloud<pcl::PointXYZRGB>& in) {
  PointCloud out;
  for (const auto& q : in) out.points.push_back(Point{q.x, q.y, q.z, q.rgba});
  out.width = in.width;
  out.height = in.height;
  return out;
}

PointCloud FromOpen3d(const open3d::geometry::PointCloud& in) {
  PointCloud out;
  for (std::size_t i = 0; i < in.points_.size(); ++i) {
    const auto& p = in.points_[i];
    std::uint32_t rgba = PackRgba(255, 255, 255);
    if (in.HasColors()) {
      const auto& c = in.colors_[i];
      auto byte = [](double v) { return static_cast<std::uint8_t>(std::lround(v * 255.0)); };
      rgba = PackRgba(byte(c(0)), byte(c(1)), byte(c(2)));
    }
    out.points.push_back(
        Point{static_cast<float>(p(0)), static_cast<float>(p(1)), static_cast<float>(p(2)), rgba});
  }
  out.width = static_cast<std::uint32_t>(out.size());
  out.height = 1;
  return out;
}

// What the CLI must produce for a synthetic frame: the fused pipeline run here with `options`
// (camera taken from the render unless `camera` is given).
PointCloud RunPipeline(const DisparityView& disparity, const ColorView& colour,
                       const PipelineOptions& options, StageCounts* counts = nullptr) {
  Pipeline pipeline;
  PointCloud out;
  const absl::Status s = pipeline.Run(options, disparity, colour, &out, counts);
  EXPECT_TRUE(s.ok()) << s;
  return out;
}

SyntheticFrame Render(std::uint32_t w, std::uint32_t h, std::uint64_t frame = 0,
                      DisparityEncoding encoding = DisparityEncoding::kF32) {
  SyntheticOptions o;
  o.width = w;
  o.height = h;
  o.frame = frame;
  o.disparity_encoding = encoding;
  auto rendered = SyntheticScene::Default().Render(o);
  EXPECT_TRUE(rendered.ok()) << rendered.status();
  return rendered.ok() ? *std::move(rendered) : SyntheticFrame{};
}

PointCloud ExpectedSynthetic(std::uint32_t w, std::uint32_t h, std::uint64_t frame = 0,
                             PipelineOptions options = {}, StageCounts* counts = nullptr) {
  const SyntheticFrame f = Render(w, h, frame);
  options.camera = f.camera;
  return RunPipeline(f.disparity_view(), f.colour_view(), options, counts);
}

// ---------------------------------------------------------------------------------------------

// ---------------------------------------------------------------------------------------------
// --help

TEST_F(CliTest, HelpExplainsEveryFlagAndItsDefault) {
  const RunResult r = Run({"--help"});
  ASSERT_TRUE(r.exited && r.code == 0) << r;
  for (const char* flag : {"--colour",
                           "--disparity",
                           "--synthetic",
                           "--frame",
                           "--focal",
                           "--fy",
                           "--cx",
                           "--cy",
                           "--baseline",
                           "--disparity-scale",
                           "--disparity-offset",
                           "--axis",
                           "--min",
                           "--max",
                           "--negative",
                           "--no-passthrough",
                           "--leaf",
                           "--min-points-per-voxel",
                           "--draco-bits",
                           "--draco-speed",
                           "--out",
                           "--json",
                           "--repeat",
                           "--quiet"}) {
    EXPECT_NE(r.out.find(std::string(flag) + " "), std::string::npos) << flag << "\n" << r.out;
  }
  // Defaults as CLI11 prints them (NAME TYPE=default), and the computed ones in words.
  for (const char* shown :
       {"--focal FLOAT=615", "--baseline FLOAT=1", "--disparity-scale FLOAT=1",
        "--disparity-offset FLOAT=0", "=z", "--min FLOAT=3", "--max FLOAT=12", "--leaf FLOAT=0.03",
        "--min-points-per-voxel UINT=0", "[1 - 30]=10", "[0 - 10]=10", "[default: --focal]",
        "[default: width/2", "[default: height/2", "0 switches it off", "640x480", "Example",
        ".pcd, .ply or .drc", "Exit status"}) {
    EXPECT_NE(r.out.find(shown), std::string::npos) << "'" << shown << "' missing\n" << r.out;
  }
  const DracoOptions draco;
  EXPECT_EQ(draco.position_bits, 10) << "DracoOptions' defaults moved: update this test";
  EXPECT_EQ(draco.encode_speed, 10) << "DracoOptions' defaults moved: update this test";
  std::istringstream lines(r.out);
  for (std::string line; std::getline(lines, line);) {
    EXPECT_LE(line.size(), 100u) << "help line over 100 columns: " << line;
  }
}

// ---------------------------------------------------------------------------------------------
// Synthetic input

TEST_F(CliTest, NoInputFlagsRenderTheSyntheticScene) {
  RunResult r;
  const Json report = RunOk({}, &r);
  EXPECT_EQ(report["input"]["kind"], "synthetic");
  EXPECT_EQ(report["input"]["width"], 640);
  EXPECT_EQ(report["input"]["height"], 480);
  EXPECT_NE(r.err.find("--synthetic 640x480"), std::string::npos) << "it must say so\n" << r;
  EXPECT_NE(r.out.find("input:  synthetic scene 640x480"), std::string::npos) << r;
  EXPECT_NE(r.out.find("camera: fx=615"), std::string::npos) << r;
  for (const char* label :
       {"load", "convert", "passthrough", "voxel grid", "fused chain", "draco encode"}) {
    EXPECT_NE(r.out.find(label), std::string::npos) << label << "\n" << r;
  }
  StageCounts counts;
  const PointCloud expected = ExpectedSynthetic(640, 480, 0, {}, &counts);
  EXPECT_EQ(StagePoints(report, "fused_chain"), expected.size());
  EXPECT_EQ(Stage(report, "convert")["valid_points"], counts.valid_points);
}

TEST_F(CliTest, JsonReportsEveryStage) {
  const Json report = RunOk({"--synthetic", "320x240", "--frame", "5", "--out", Path("c.drc")});
  ASSERT_TRUE(report.contains("stages")) << report.dump(2);
  std::vector<std::string> names;
  for (const Json& s : report["stages"]) {
    names.push_back(s["name"]);
    EXPECT_TRUE(s["points"].is_number_unsigned()) << s;
    EXPECT_TRUE(s["ms"].is_number() && s["ms"].get<double>() >= 0) << s;
  }
  EXPECT_EQ(names, (std::vector<std::string>{"load", "convert", "passthrough", "voxel_grid",
                                             "fused_chain", "draco_encode", "write"}));
  StageCounts counts;
  const PointCloud expected = ExpectedSynthetic(320, 240, 5, {}, &counts);
  EXPECT_EQ(StagePoints(report, "load"), 320u * 240u);
  EXPECT_EQ(StagePoints(report, "convert"), 320u * 240u);
  EXPECT_EQ(Stage(report, "convert")["valid_points"], counts.valid_points);
  EXPECT_EQ(StagePoints(report, "passthrough"), counts.after_passthrough);
  EXPECT_EQ(StagePoints(report, "voxel_grid"), counts.after_voxel);
  EXPECT_EQ(StagePoints(report, "fused_chain"), expected.size());
  EXPECT_EQ(StagePoints(report, "draco_encode"), expected.size());
  EXPECT_LT(StagePoints(report, "voxel_grid"), StagePoints(report, "passthrough"));
  EXPECT_LT(StagePoints(report, "passthrough"), counts.valid_points);
  EXPECT_EQ(report["fused_matches_stages"], true);
  EXPECT_EQ(report["input"]["frame"], 5);
  EXPECT_EQ(report["camera"]["fx"], 307.5);  // the scene's camera: 615 * 320 / 640
  EXPECT_EQ(report["camera"]["cx"], 160.0);
  EXPECT_EQ(report["passthrough"]["axis"], "z");
  EXPECT_FLOAT_EQ(report["voxel_grid"]["leaf"].get<float>(), 0.03f);
  // The .drc written is the encode that was measured.
  ASSERT_TRUE(report["draco_bytes"].is_number_unsigned());
  EXPECT_GT(report["draco_bytes"].get<std::uint64_t>(), 0u);
  EXPECT_EQ(report["draco_bytes"].get<std::uint64_t>(), fs::file_size(Path("c.drc")));
  EXPECT_EQ(report["output"]["bytes"].get<std::uint64_t>(), fs::file_size(Path("c.drc")));
}

TEST_F(CliTest, PcdHoldsTheFusedCloudForPclAndOpen3d) {
  const std::string out = Path("cloud.pcd");
  const Json report = RunOk({"--synthetic", "320x240", "--frame", "3", "--out", out});
  const PointCloud expected = ExpectedSynthetic(320, 240, 3);
  ASSERT_GT(expected.size(), 1000u);
  EXPECT_EQ(StagePoints(report, "voxel_grid"), expected.size());

  // The header other tools rely on.
  const std::string text = ReadText(out);
  EXPECT_NE(text.find("FIELDS x y z rgb\n"), std::string::npos) << text.substr(0, 300);
  EXPECT_NE(text.find("DATA binary\n"), std::string::npos);

  pcl::PointCloud<pcl::PointXYZRGB> pcl_cloud;
  ASSERT_EQ(pcl::io::loadPCDFile(out, pcl_cloud), 0);
  EXPECT_EQ(pcl_cloud.size(), StagePoints(report, "voxel_grid"));
  EXPECT_TRUE(SamePoints(expected, FromPclCloud(pcl_cloud)));

  open3d::geometry::PointCloud o3d;
  ASSERT_TRUE(open3d::io::ReadPointCloud(out, o3d));
  ASSERT_TRUE(o3d.HasColors());
  EXPECT_TRUE(SamePoints(expected, FromOpen3d(o3d), /*compare_alpha=*/false));

  PointCloud ours;
  ASSERT_TRUE(LoadCloud(out, &ours).ok());
  EXPECT_TRUE(SamePoints(expected, ours));
}

TEST_F(CliTest, PlyHoldsTheFusedCloudForPclAndOpen3d) {
  const std::string out = Path("cloud.ply");
  const Json report = RunOk({"--synthetic", "320x240", "--frame", "3", "--out", out});
  const PointCloud expected = ExpectedSynthetic(320, 240, 3);
  EXPECT_EQ(StagePoints(report, "voxel_grid"), expected.size());

  const std::string text = ReadText(out);
  const std::string header = text.substr(0, text.find("end_header"));
  EXPECT_NE(header.find("format binary_little_endian 1.0"), std::string::npos) << header;
  EXPECT_NE(header.find("element vertex " + std::to_string(expected.size())), std::string::npos)
      << header;
  EXPECT_NE(header.find("property uchar red\nproperty uchar green\nproperty uchar blue"),
            std::string::npos)
      << header;
  EXPECT_EQ(header.find("element camera"), std::string::npos) << header;

  pcl::PointCloud<pcl::PointXYZRGB> pcl_cloud;
  ASSERT_EQ(pcl::io::loadPLYFile(out, pcl_cloud), 0);
  EXPECT_TRUE(SamePoints(expected, FromPclCloud(pcl_cloud), /*compare_alpha=*/false));

  open3d::geometry::PointCloud o3d;
  ASSERT_TRUE(open3d::io::ReadPointCloud(out, o3d));
  EXPECT_TRUE(SamePoints(expected, FromOpen3d(o3d), /*compare_alpha=*/false));

  PointCloud ours;
  ASSERT_TRUE(LoadCloud(out, &ours).ok());
  EXPECT_TRUE(SamePoints(expected, ours, /*compare_alpha=*/false));
}

TEST_F(CliTest, DrcDecodesToTheFusedCloud) {
  const std::string out = Path("cloud.drc");
  const Json report = RunOk({"--synthetic", "320x240", "--frame", "3", "--out", out});
  const PointCloud expected = ExpectedSynthetic(320, 240, 3);
  const Json encode = Stage(report, "draco_encode");
  const double bound = encode.value("position_error_bound", 1.0);
  EXPECT_GT(bound, 0.0);
  EXPECT_LE(bound, 0.03 / 4 + 1e-6) << "max_position_error must be leaf / 4";
  const CloudTolerance tolerance = CloudTolerance::DracoBound(bound);

  PointCloud ours;
  ASSERT_TRUE(LoadCloud(out, &ours).ok());
  EXPECT_EQ(ours.size(), StagePoints(report, "voxel_grid"));
  EXPECT_TRUE(CloudsMatch(expected, ours, tolerance));

  // The stock tool, when installed, reads the same file.
  if (std::system("command -v draco_decoder >/dev/null 2>&1") != 0) {
    GTEST_SKIP() << "draco_decoder not installed (Debian package 'draco'); skipped that part";
  }
  const std::string ply = Path("decoded.ply");
  const std::string command = "draco_decoder -i " + ShellQuote(out) + " -o " + ShellQuote(ply) +
                              " >" + ShellQuote(Path("draco.log")) + " 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0) << ReadText(Path("draco.log"));
  PointCloud decoded;
  ASSERT_TRUE(LoadCloud(ply, &decoded).ok());
  EXPECT_TRUE(CloudsMatch(expected, decoded, tolerance));
}

TEST_F(CliTest, RepeatReportsMediansAndQuietPrintsNothing) {
  RunResult r;
  const Json report =
      RunOk({"--synthetic", "160x120", "--repeat", "3", "--quiet", "--out", Path("q.pcd")}, &r);
  EXPECT_EQ(report["repeat"], 3);
  EXPECT_TRUE(r.out.empty()) << r;
  EXPECT_TRUE(r.err.empty()) << r;
  EXPECT_TRUE(fs::exists(Path("q.pcd")));

  const RunResult loud = Run({"--synthetic", "160x120", "--repeat", "3"});
  ASSERT_EQ(loud.code, 0) << loud;
  EXPECT_NE(loud.out.find("median of 3 runs"), std::string::npos) << loud;
}

TEST_F(CliTest, StageFlagsReachThePipeline) {
  PipelineOptions options;
  options.passthrough.axis = Axis::kY;
  options.passthrough.min = -0.5f;
  options.passthrough.max = 1.5f;
  options.passthrough.negative = true;
  options.voxel.SetLeaf(0.05f);
  options.voxel.min_points_per_voxel = 3;
  const PointCloud expected = ExpectedSynthetic(320, 240, 2, options);
  const Json report = RunOk({"--synthetic", "320x240", "--frame", "2", "--axis", "y", "--min",
                             "-0.5", "--max", "1.5", "--negative", "--leaf", "0.05",
                             "--min-points-per-voxel", "3", "--out", Path("s.pcd")});
  PointCloud ours;
  ASSERT_TRUE(LoadCloud(Path("s.pcd"), &ours).ok());
  EXPECT_TRUE(SamePoints(expected, ours));
  EXPECT_EQ(report["passthrough"]["negative"], true);
  EXPECT_EQ(report["fused_matches_stages"], true);

  // The passthrough and its negative split the valid points between them.
  const Json positive = RunOk(
      {"--synthetic", "320x240", "--frame", "2", "--axis", "y", "--min", "-0.5", "--max", "1.5"});
  EXPECT_EQ(StagePoints(positive, "passthrough") + StagePoints(report, "passthrough"),
            Stage(report, "convert")["valid_points"].get<std::uint64_t>());
}

TEST_F(CliTest, StagesSwitchOff) {
  const Json report = RunOk({"--synthetic", "160x120", "--no-passthrough", "--leaf", "0", "--min",
                             "9", "--max", "1"});  // limits unused when off
  const std::uint64_t valid = Stage(report, "convert")["valid_points"];
  EXPECT_EQ(StagePoints(report, "passthrough"), valid);
  EXPECT_EQ(StagePoints(report, "voxel_grid"), valid);
  EXPECT_EQ(StagePoints(report, "fused_chain"), valid);
  EXPECT_EQ(report["voxel_grid"]["enabled"], false);
  EXPECT_EQ(report["passthrough"]["enabled"], false);
  EXPECT_EQ(report["draco"]["max_position_error"], 0.0);
}

TEST_F(CliTest, EmptyResultIsWrittenInEveryFormat) {
  for (const char* name : {"none.pcd", "none.ply", "none.drc"}) {
    SCOPED_TRACE(name);
    const Json report =
        RunOk({"--synthetic", "160x120", "--min", "500", "--max", "600", "--out", Path(name)});
    EXPECT_EQ(StagePoints(report, "passthrough"), 0u);
    EXPECT_EQ(StagePoints(report, "fused_chain"), 0u);
    PointCloud back;
    back.points.resize(2);
    const absl::Status s = LoadCloud(Path(name), &back);
    ASSERT_TRUE(s.ok()) << s;
    EXPECT_TRUE(back.empty());
  }
  // PCL and Open3D refuse to read files without points ("No points to read", "number of
  // vertex <= 0"); only LoadCloud is checked here.
}

TEST_F(CliTest, CameraFlagsReachTheCamera) {
  const Json report = RunOk({"--synthetic",
                             "320x240",
                             "--focal",
                             "400",
                             "--fy",
                             "380",
                             "--cx",
                             "150.5",
                             "--cy",
                             "100",
                             "--baseline",
                             "0.5",
                             "--disparity-scale",
                             "2",
                             "--disparity-offset",
                             "0.25",
                             "--min",
                             "0",
                             "--max",
                             "100",
                             "--out",
                             Path("cam.pcd")});
  const Json& camera = report["camera"];
  EXPECT_EQ(camera["fx"], 400.0);
  EXPECT_EQ(camera["fy"], 380.0);
  EXPECT_EQ(camera["cx"], 150.5);
  EXPECT_EQ(camera["cy"], 100.0);
  EXPECT_EQ(camera["baseline"], 0.5);
  EXPECT_EQ(camera["disparity_scale"], 2.0);
  EXPECT_EQ(camera["disparity_offset"], 0.25);

  const SyntheticFrame f = Render(320, 240);
  PipelineOptions options;
  options.camera = f.camera;
  options.camera.fx = 400;
  options.camera.fy = 380;
  options.camera.cx = 150.5;
  options.camera.cy = 100;
  options.camera.baseline = 0.5;
  options.camera.disparity_scale = 2;
  options.camera.disparity_offset = 0.25;
  options.passthrough.min = 0;
  options.passthrough.max = 100;
  const PointCloud expected = RunPipeline(f.disparity_view(), f.colour_view(), options);
  PointCloud ours;
  ASSERT_TRUE(LoadCloud(Path("cam.pcd"), &ours).ok());
  EXPECT_GT(ours.size(), 100u);
  EXPECT_TRUE(SamePoints(expected, ours));

  // --focal alone sets fy too.
  const Json focal_only = RunOk({"--synthetic", "320x240", "--focal", "500"});
  EXPECT_EQ(focal_only["camera"]["fy"], 500.0);
}

// ---------------------------------------------------------------------------------------------
// Image files: 8-bit, 16-bit (with --disparity-scale) and float disparity give the same cloud,
// and it is the cloud stock PCL makes from the 8-bit frame.

TEST_F(CliTest, EveryDisparityDepthGivesTheSameCloudAsStockPcl) {
  const SyntheticFrame f = Render(640, 480, 4, DisparityEncoding::kU8);
  const std::uint32_t w = f.width, h = f.height;
  const std::vector<std::uint8_t> d8 = f.disparity;
  std::vector<std::uint16_t> d16;
  std::vector<float> d32;
  for (std::uint8_t d : d8) {
    d16.push_back(static_cast<std::uint16_t>(d * 16));
    d32.push_back(static_cast<float>(d));
  }
  WriteFile(Path("d8.png"), Png(w, h, 8, 0, Bytes(d8)));
  WriteFile(Path("d16.png"), Png(w, h, 16, 0, Be16(d16)));
  WriteFile(Path("d32.tif"), FloatTiff(w, h, d32));
  // RGBA with alpha down to 0, as New Tsukuba's colour PNGs: alpha must not touch the colour.
  WriteFile(Path("colour.png"), Png(w, h, 8, 6, RgbaRowsFromBgr(f.colour)));

  const std::vector<std::string> common = {"--colour", Path("colour.png"), "--focal", "615"};
  auto run = [&](const std::string& disparity, const std::string& out,
                 std::vector<std::string> extra) {
    std::vector<std::string> args = common;
    args.insert(args.end(), {"--disparity", Path(disparity), "--out", Path(out)});
    args.insert(args.end(), extra.begin(), extra.end());
    const Json report = RunOk(args);
    PointCloud cloud;
    const absl::Status s = LoadCloud(Path(out), &cloud);
    EXPECT_TRUE(s.ok()) << s;
    return std::make_pair(report, cloud);
  };
  const auto [r8, c8] = run("d8.png", "c8.pcd", {});
  const auto [r16, c16] = run("d16.png", "c16.pcd", {"--disparity-scale", "0.0625"});
  const auto [r32, c32] = run("d32.tif", "c32.pcd", {});
  EXPECT_EQ(r8["input"]["disparity_encoding"], "u8");
  EXPECT_EQ(r16["input"]["disparity_encoding"], "u16");
  EXPECT_EQ(r32["input"]["disparity_encoding"], "f32");
  EXPECT_EQ(r8["input"]["colour_encoding"], "bgr8");
  ASSERT_GT(c8.size(), 1000u);
  EXPECT_TRUE(SamePoints(c8, c16));
  EXPECT_TRUE(SamePoints(c8, c32));

  // Stock PCL 1.13 on the same 8-bit frame: OrganizedConversion, PassThrough, VoxelGrid.
  reference::PclFrame pf = reference::MakePclFrame(f.disparity_view(), f.colour_view());
  auto organized = std::make_shared<reference::PclCloud>();
  reference::PclConvert(pf, 615.0f, 0.0f, 1.0f, *organized);
  auto passed = std::make_shared<reference::PclCloud>();
  reference::PclPassThrough(organized, PassThroughParams{}, *passed);
  reference::PclCloud voxels;
  reference::PclVoxelGrid(passed, VoxelGridParams{}, voxels);
  EXPECT_EQ(StagePoints(r8, "passthrough"), passed->size());
  EXPECT_TRUE(CloudsMatch(reference::FromPcl(voxels), c8, CloudTolerance::Equivalence()));
}

// ---------------------------------------------------------------------------------------------
// A real New Tsukuba frame, the paper's parameters: the counts stock PCL gives (PLATFORM.md).

TEST_F(CliTest, TsukubaFrameMatchesStockPcl) {
  CLOUDCAST_REQUIRE_TSUKUBA();
  const std::string colour = testing::TsukubaColourPath("00001");
  const std::string disparity = testing::TsukubaDisparityPath("00001");
  const std::string out = Path("tsukuba.pcd");
  RunResult r;
  const Json report = RunOk({"--colour", colour, "--disparity", disparity, "--focal", "615",
                             "--min", "3", "--max", "12", "--leaf", "0.03", "--out", out},
                            &r);
  EXPECT_EQ(report["input"]["kind"], "files");
  EXPECT_EQ(report["input"]["disparity_encoding"], "u8");
  EXPECT_EQ(report["input"]["colour_encoding"], "bgr8");  // RGBA PNG, alpha dropped
  EXPECT_EQ(report["camera"]["cx"], 320.0);
  EXPECT_EQ(report["camera"]["cy"], 240.0);
  EXPECT_EQ(StagePoints(report, "load"), 307200u);
  EXPECT_EQ(StagePoints(report, "convert"), 307200u);
  EXPECT_EQ(Stage(report, "convert")["valid_points"], 307200u);
  EXPECT_EQ(StagePoints(report, "passthrough"), 52300u);
  EXPECT_EQ(StagePoints(report, "voxel_grid"), 16186u);
  EXPECT_EQ(StagePoints(report, "fused_chain"), 16186u);
  EXPECT_NE(r.out.find("tsukuba_disparity_L_00001.png (640x480 u8)"), std::string::npos) << r;

  // Stock PCL's chain on the same images, compared point by point with the file.
  auto d = LoadDisparity(disparity);
  auto c = LoadColor(colour);
  ASSERT_TRUE(d.ok() && c.ok());
  reference::PclFrame pf = reference::MakePclFrame(d->view(), c->view());
  auto organized = std::make_shared<reference::PclCloud>();
  reference::PclConvert(pf, 615.0f, 0.0f, 1.0f, *organized);
  auto passed = std::make_shared<reference::PclCloud>();
  reference::PclPassThrough(organized, PassThroughParams{}, *passed);
  reference::PclCloud voxels;
  reference::PclVoxelGrid(passed, VoxelGridParams{}, voxels);
  ASSERT_EQ(voxels.size(), 16186u);

  pcl::PointCloud<pcl::PointXYZRGB> pcl_cloud;
  ASSERT_EQ(pcl::io::loadPCDFile(out, pcl_cloud), 0);
  EXPECT_TRUE(CloudsMatch(reference::FromPcl(voxels), FromPclCloud(pcl_cloud),
                          CloudTolerance::Equivalence()));
  open3d::geometry::PointCloud o3d;
  ASSERT_TRUE(open3d::io::ReadPointCloud(out, o3d));
  EXPECT_TRUE(
      CloudsMatch(reference::FromPcl(voxels), FromOpen3d(o3d), CloudTolerance::Equivalence()));
}

// ---------------------------------------------------------------------------------------------
// Bad input: a clear message naming the problem, exit 2 for usage and 1 for processing errors,
// never a crash, and no output file.

struct BadCase {
  std::string name;
  std::vector<std::string> args;  // "@" prefixes a file in the test folder
  int code;
  std::vector<std::string> mentions;
};

void PrintTo(const BadCase& c, std::ostream* os) { *os << c.name; }

class BadInputTest : public CliTest, public ::testing::WithParamInterface<BadCase> {};

TEST_P(BadInputTest, FailsCleanly) {
  // Fixtures: a good frame, a smaller colour image, an undecodable and an empty file.
  const SyntheticFrame f = Render(64, 48, 0, DisparityEncoding::kU8);
  WriteFile(Path("d.png"), Png(f.width, f.height, 8, 0, Bytes(f.disparity)));
  WriteFile(Path("c.png"), Png(f.width, f.height, 8, 6, RgbaRowsFromBgr(f.colour)));
  WriteFile(Path("small.png"), Png(32, 48, 8, 2, std::string(std::size_t{32} * 48 * 3, '\x80')));
  WriteFile(Path("garbage.png"), "this is not a PNG");
  WriteFile(Path("truncated.png"), Png(f.width, f.height, 8, 0, Bytes(f.disparity)).substr(0, 60));
  WriteFile(Path("empty.png"), "");

  std::vector<std::string> args;
  for (const std::string& a : GetParam().args) args.push_back(a[0] == '@' ? Path(a.substr(1)) : a);
  const bool has_out = std::find(args.begin(), args.end(), "--out") != args.end();
  if (!has_out) args.insert(args.end(), {"--out", Path("never.pcd")});
  const RunResult r = Run(args);
  EXPECT_FALSE(r.crashed()) << r;
  EXPECT_EQ(r.code, GetParam().code) << r;
  for (const std::string& m : GetParam().mentions) {
    const std::string mention = m[0] == '@' ? Path(m.substr(1)) : m;
    EXPECT_NE(r.err.find(mention), std::string::npos) << "stderr must mention '" << mention << "'\n"
                                                      << r;
  }
  EXPECT_FALSE(fs::exists(Path("never.pcd")));
}

const std::vector<BadCase>& BadCases() {
  static const std::vector<BadCase> cases = {
      {"MissingDisparity",
       {"--colour", "@c.png", "--disparity", "@nope.png"},
       1,
       {"@nope.png", "no such file"}},
      {"MissingColour",
       {"--colour", "@nope.png", "--disparity", "@d.png"},
       1,
       {"@nope.png", "no such file"}},
      {"Undecodable",
       {"--colour", "@c.png", "--disparity", "@garbage.png"},
       1,
       {"@garbage.png", "decoded"}},
      {"Truncated", {"--colour", "@c.png", "--disparity", "@truncated.png"}, 1, {"@truncated.png"}},
      {"EmptyFile", {"--colour", "@empty.png", "--disparity", "@d.png"}, 1, {"@empty.png"}},
      {"ColourAsDisparity",
       {"--colour", "@c.png", "--disparity", "@c.png"},
       1,
       {"disparity file", "4 channels"}},
      {"FolderAsColour", {"--colour", "@", "--disparity", "@d.png"}, 1, {"directory"}},
      {"MismatchedSizes",
       {"--colour", "@small.png", "--disparity", "@d.png"},
       1,
       {"32x48", "64x48", "must be the same size"}},
      {"ColourWithoutDisparity", {"--colour", "@c.png"}, 2, {"--disparity"}},
      {"DisparityWithoutColour", {"--disparity", "@d.png"}, 2, {"--colour"}},
      {"FilesAndSynthetic",
       {"--colour", "@c.png", "--disparity", "@d.png", "--synthetic", "8x8"},
       2,
       {"--synthetic"}},
      {"FrameWithFiles",
       {"--colour", "@c.png", "--disparity", "@d.png", "--frame", "2"},
       2,
       {"--frame"}},
      {"NegativeLeaf", {"--synthetic", "64x48", "--leaf", "-0.1"}, 2, {"--leaf", ">= 0"}},
      {"NanLeaf", {"--synthetic", "64x48", "--leaf", "nan"}, 2, {"--leaf"}},
      {"LeafTooFine", {"--synthetic", "64x48", "--leaf", "1e-7"}, 1, {"voxel", "leaf"}},
      {"UnknownExtension",
       {"--synthetic", "64x48", "--out", "@cloud.xyz"},
       2,
       {"--out", "'.xyz'", ".pcd, .ply, .drc"}},
      {"NoExtension", {"--synthetic", "64x48", "--out", "@cloud"}, 2, {"--out", "extension"}},
      {"MissingOutFolder",
       {"--synthetic", "64x48", "--out", "@no/such/dir/cloud.pcd"},
       1,
       {"@no/such/dir", "does not exist"}},
      {"MissingJsonFolder",
       {"--synthetic", "64x48", "--json", "@no/such/dir/r.json"},
       1,
       {"--json", "@no/such/dir", "does not exist"}},
      {"FocalZero", {"--synthetic", "64x48", "--focal", "0"}, 2, {"--focal", "> 0"}},
      {"FocalNan", {"--synthetic", "64x48", "--focal", "nan"}, 2, {"--focal", "nan"}},
      {"FocalInf", {"--synthetic", "64x48", "--focal", "inf"}, 2, {"--focal"}},
      {"FocalText", {"--synthetic", "64x48", "--focal", "wide"}, 2, {"--focal"}},
      {"FocalZeroForFiles",
       {"--colour", "@c.png", "--disparity", "@d.png", "--focal", "0"},
       2,
       {"--focal"}},
      {"NegativeFy", {"--synthetic", "64x48", "--fy", "-1"}, 2, {"--fy"}},
      {"NanCx", {"--synthetic", "64x48", "--cx", "nan"}, 2, {"--cx"}},
      {"ZeroBaseline", {"--synthetic", "64x48", "--baseline", "0"}, 2, {"--baseline"}},
      {"ZeroScale", {"--synthetic", "64x48", "--disparity-scale", "0"}, 2, {"--disparity-scale"}},
      {"InfOffset",
       {"--synthetic", "64x48", "--disparity-offset", "inf"},
       2,
       {"--disparity-offset"}},
      {"SyntheticZero", {"--synthetic", "0x48"}, 2, {"--synthetic"}},
      {"SyntheticText", {"--synthetic", "big"}, 2, {"--synthetic", "WIDTHxHEIGHT"}},
      {"SyntheticHuge", {"--synthetic", "100000x100000"}, 2, {"--synthetic", "limits"}},
      {"MinAboveMax", {"--synthetic", "64x48", "--min", "5", "--max", "3"}, 2, {"--min", "--max"}},
      {"NanMin", {"--synthetic", "64x48", "--min", "nan"}, 2, {"--min"}},
      {"BadAxis", {"--synthetic", "64x48", "--axis", "w"}, 2, {"--axis"}},
      {"RepeatZero", {"--synthetic", "64x48", "--repeat", "0"}, 2, {"--repeat"}},
      {"NegativeMinPoints",
       {"--synthetic", "64x48", "--min-points-per-voxel", "-1"},
       2,
       {"--min-points-per-voxel"}},
      {"DracoBits", {"--synthetic", "64x48", "--draco-bits", "31"}, 2, {"--draco-bits"}},
      {"DracoSpeed", {"--synthetic", "64x48", "--draco-speed", "11"}, 2, {"--draco-speed"}},
      {"UnknownFlag", {"--synthetic", "64x48", "--voxel", "3"}, 2, {"--voxel"}},
      {"StrayArgument", {"frame.png"}, 2, {"frame.png"}},
  };
  return cases;
}

INSTANTIATE_TEST_SUITE_P(Cases, BadInputTest, ::testing::ValuesIn(BadCases()),
                         [](const ::testing::TestParamInfo<BadCase>& info) {
                           return info.param.name;
                         });

}  // namespace
}  // namespace cloudcast
