// cloudcast-stereo-bench: our semi-global matcher against OpenCV 4.6's StereoSGBM (three modes)
// and StereoBM, at the same settings, on the New Tsukuba pairs (or the Middlebury Aloe pair), in
// one run:
//   accuracy    bad-1.0 and bad-2.0 against the truth and the truth + 1 px (New Tsukuba's truth
//               reads about 1 px low: docs/stereo.md), density, the median error;
//   speed       median thread-CPU ms per frame on one thread (cv::setNumThreads(1)), interleaved
//               over rounds x frames after a warm-up round, and the ratio to StereoSGBM's;
//   throughput  frames/s with N threads (default 2, one per core, as the server runs), each
//               matching its own frames with its own matcher;
//   simd        (--simd-levels) our matcher's time per instruction set;
//   ranges      (--ranges) accuracy and time for other disparity ranges.
#include <time.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_split.h"
#include "cloudcast/datasets/middlebury.h"
#include "cloudcast/datasets/tsukuba.h"
#include "cloudcast/io/image_io.h"
#include "cloudcast/stereo/evaluation.h"
#include "cloudcast/stereo/grey.h"
#include "cloudcast/stereo/matcher.h"
#include "stats.h"

namespace cloudcast::bench {
namespace {

using stereo::DisparityMap16;
using stereo::DisparityScore;
using stereo::GreyImage;

struct Pair {
  std::string id;
  GreyImage left, right;
  OwnedDisparity truth;
};

double ThreadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

// A row of the tables: a matcher and what it measured.
struct Mode {
  std::string label;
  StereoParams params;
  stereo::SimdLevel simd = stereo::SimdLevel::kAuto;  // ours: which code
  std::unique_ptr<stereo::Matcher> matcher;
  std::vector<double> ms;  // per frame and round
  DisparityScore score;
  double fps = 0, thread_ms = 0;
};

std::vector<Pair> LoadTsukuba(const std::string& dir, int max_frames) {
  auto frames = tsukuba::LoadAllStereo(dir);
  if (!frames.ok()) {
    std::fprintf(stderr, "cloudcast-stereo-bench: %s\n",
                 std::string(frames.status().message()).c_str());
    std::exit(2);
  }
  std::vector<Pair> pairs;
  for (StereoFrame& f : *frames) {
    if (max_frames > 0 && static_cast<int>(pairs.size()) >= max_frames) break;
    Pair p;
    p.id = f.id;
    p.left = *stereo::ToGrey(f.left.view(), "left");
    p.right = *stereo::ToGrey(f.right.view(), "right");
    p.truth = std::move(f.truth);
    pairs.push_back(std::move(p));
  }
  return pairs;
}

// Middlebury's Aloe as Debian's opencv-doc ships it, at half size (middlebury.h), so that 128
// disparities cover it.
std::vector<Pair> LoadAloe(const std::string& dir) {
  auto f = middlebury::LoadAloe(dir, /*half=*/true);
  if (!f.ok()) {
    std::fprintf(stderr, "cloudcast-stereo-bench: %s (apt-get install opencv-doc)\n",
                 std::string(f.status().message()).c_str());
    std::exit(2);
  }
  Pair p;
  p.id = f->id;
  p.left = *stereo::ToGrey(f->left.view(), "left");
  p.right = *stereo::ToGrey(f->right.view(), "right");
  p.truth = std::move(f->truth);
  return {std::move(p)};
}

void Match(Mode& m, const Pair& p, DisparityMap16* out) {
  if (absl::Status s = m.matcher->Compute(p.left.view(), p.right.view(), out); !s.ok()) {
    std::fprintf(stderr, "%s: %s\n", m.label.c_str(), std::string(s.message()).c_str());
    std::exit(1);
  }
}

// Accuracy once, then `rounds` timed rounds, modes interleaved within each frame.
void RunTimed(std::vector<Mode>& modes, const std::vector<Pair>& pairs, int rounds) {
  DisparityMap16 out;
  for (const Pair& p : pairs) {
    for (Mode& m : modes) {
      Match(m, p, &out);  // warm-up and accuracy
      (void)m.score.Add(out, p.truth.view());
    }
  }
  for (int r = 0; r < rounds; ++r) {
    for (const Pair& p : pairs) {
      for (Mode& m : modes) {
        const double t0 = ThreadCpuMs();
        Match(m, p, &out);
        m.ms.push_back(ThreadCpuMs() - t0);
      }
    }
  }
}

// `threads` threads, each with its own matcher, each matching `per_thread` frames (thread i
// starts at frame i); frames/s over the wall time of all of them.
void RunThroughput(Mode& m, const std::vector<Pair>& pairs, int threads, int per_thread) {
  std::vector<std::unique_ptr<stereo::Matcher>> matchers;
  for (int i = 0; i < threads; ++i) matchers.push_back(*stereo::MakeMatcher(m.params, m.simd));
  std::vector<double> cpu(threads, 0);
  std::atomic<int> ready{0};
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::thread> pool;
  for (int i = 0; i < threads; ++i) {
    pool.emplace_back([&, i] {
      DisparityMap16 out;
      ready.fetch_add(1);
      const double t0 = ThreadCpuMs();
      for (int f = 0; f < per_thread; ++f) {
        const Pair& p = pairs[(i + f) % pairs.size()];
        (void)matchers[i]->Compute(p.left.view(), p.right.view(), &out);
      }
      cpu[i] = ThreadCpuMs() - t0;
    });
  }
  for (std::thread& t : pool) t.join();
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  m.fps = threads * per_thread / wall;
  double sum = 0;
  for (double c : cpu) sum += c;
  m.thread_ms = sum / (threads * per_thread);
}

// The table: `reference` names the row the speed ratio is taken to (StereoSGBM, or the scalar code
// in the table of instruction sets).
nlohmann::json PrintAccuracyAndSpeed(const char* title, std::vector<Mode>& modes, bool throughput,
                                     int threads, const char* reference = "SGBM") {
  // The reference row's median for each row: StereoSGBM's, or the scalar code's with as many paths.
  auto reference_ms = [&](const Mode& row) {
    for (const Mode& m : modes) {
      const bool is_reference =
          std::string(reference) == "SGBM"
              ? m.params.matcher == StereoMatcher::kOpenCvSgbm
              : m.simd == stereo::SimdLevel::kScalar && m.params.paths == row.params.paths;
      if (is_reference) return Median(m.ms);
    }
    return 0.0;
  };
  std::printf("\n%s\n", title);
  std::printf("%-20s %8s %8s %8s %8s %9s %8s %7s %9s %8s", "mode", "bad-1.0", "bad-1.0", "bad-2.0",
              "bad-2.0", "bad-2.0", "density", "median", "ms/frame",
              (std::string("x ") + reference).c_str());
  if (throughput) std::printf(" %9s %9s %9s", "frames/s", "thread ms", "frames/s");
  std::printf("\n%-20s %8s %8s %8s %8s %9s %8s %7s %9s %8s", "", "GT", "GT+1", "GT", "GT+1",
              "GT+1 all", "", "d - GT", "1 thread", "speed");
  if (throughput) {
    const std::string t = std::to_string(threads);
    std::printf(" %9s %9s %9s", (t + " thr").c_str(), "", (t + "x1/ms").c_str());
  }
  std::printf("\n");
  nlohmann::json rows = nlohmann::json::array();
  for (Mode& m : modes) {
    const double ms = Median(m.ms), sgbm_ms = reference_ms(m);
    const DisparityScore& s = m.score;
    std::printf("%-20s %7.2f%% %7.2f%% %7.2f%% %7.2f%% %8.2f%% %7.2f%% %+7.2f %9.2f %7.2fx",
                m.label.c_str(), s.Bad(1, 0), s.Bad(1, 1), s.Bad(2, 0), s.Bad(2, 1),
                s.BadCountingMisses(2, 1), 100 * s.Density(), s.MedianError(), ms,
                ms > 0 && sgbm_ms > 0 ? sgbm_ms / ms : 0.0);
    // Wall frames/s on this (shared) machine, and what the threads' own CPU time would give on
    // otherwise idle cores.
    if (throughput) {
      std::printf(" %9.1f %9.2f %9.1f", m.fps, m.thread_ms, threads * 1000.0 / m.thread_ms);
    }
    std::printf("\n");
    nlohmann::json j = {
        {"mode", m.label},
        {"kind", std::string(Name(m.params.matcher))},
        {"paths", m.params.paths},
        {"min_disparity", m.params.min_disparity},
        {"num_disparities", m.params.num_disparities},
        {"block_size", m.params.block_size},
        {"p1", m.params.EffectiveP1()},
        {"p2", m.params.EffectiveP2()},
        {"bad_1_gt", s.Bad(1, 0)},
        {"bad_1_gt_plus_1", s.Bad(1, 1)},
        {"bad_2_gt", s.Bad(2, 0)},
        {"bad_2_gt_plus_1", s.Bad(2, 1)},
        {"bad_2_gt_plus_1_counting_misses", s.BadCountingMisses(2, 1)},
        {"density", s.Density()},
        {"median_error_px", s.MedianError()},
        {"median_ms", ms},
        {std::string("speed_vs_") + reference, ms > 0 && sgbm_ms > 0 ? sgbm_ms / ms : 0.0},
        {"ms_per_frame", m.ms}};
    if (throughput) {
      j["frames_per_second"] = m.fps;
      j["threads"] = threads;
      j["thread_ms_per_frame"] = m.thread_ms;
      j["frames_per_second_of_thread_cpu"] = threads * 1000.0 / m.thread_ms;
    }
    rows.push_back(std::move(j));
  }
  return rows;
}

Mode MakeMode(const std::string& name, const StereoParams& base) {
  Mode m;
  m.params = base;
  std::string kind = name;
  std::string simd;
  if (auto at = name.find('@'); at != std::string::npos) {
    kind = name.substr(0, at);
    simd = name.substr(at + 1);
  }
  if (kind == "sgm4" || kind == "sgm8") {
    m.params.matcher = StereoMatcher::kSgm;
    m.params.paths = kind == "sgm4" ? 4 : 8;
    m.label = kind == "sgm4" ? "ours 4 paths" : "ours 8 paths";
  } else if (!ParseStereoMatcher(kind, &m.params.matcher) || kind == "sgm") {
    std::fprintf(stderr, "--modes: unknown mode '%s' (sgm4, sgm8, sgbm, sgbm-3way, hh, bm)\n",
                 kind.c_str());
    std::exit(2);
  } else {
    m.label = "OpenCV " + kind;
  }
  if (!simd.empty()) {
    if (!stereo::ParseSimdLevel(simd, &m.simd)) {
      std::fprintf(stderr, "--modes: unknown SIMD level '%s' (scalar, avx2, avx512)\n",
                   simd.c_str());
      std::exit(2);
    }
    m.label += " " + simd;
  }
  auto matcher = stereo::MakeMatcher(m.params, m.simd);
  if (!matcher.ok()) {
    std::fprintf(stderr, "%s: %s\n", name.c_str(), std::string(matcher.status().message()).c_str());
    std::exit(2);
  }
  m.matcher = *std::move(matcher);
  return m;
}

std::vector<std::string> SplitList(const std::string& s) {
  return absl::StrSplit(s, ',', absl::SkipEmpty());
}

int Main(int argc, char** argv) {
  CLI::App app{
      "cloudcast-stereo-bench: our semi-global matcher against OpenCV's StereoSGBM (sgbm,\n"
      "sgbm-3way, hh) and StereoBM (bm) at the same settings, on the New Tsukuba pairs: bad-1.0 /\n"
      "bad-2.0 against the truth and the truth + 1 px, density, median thread-CPU ms per frame on\n"
      "one thread and the ratio to StereoSGBM, and frames/s with several threads."};
  std::string data_dir = tsukuba::DefaultDir(), json_path, aloe_dir;
  std::string modes_list = "sgm4,sgm8,sgbm,sgbm-3way,hh,bm", simd_levels, ranges;
  int rounds = 3, frames = 0, threads = 2, per_thread = 20;
  bool no_throughput = false;
  StereoParams base;
  app.add_option("--data", data_dir,
                 "New Tsukuba folder (default: $CLOUDCAST_DATA or the build's)");
  app.add_option("--aloe", aloe_dir,
                 "match Middlebury's Aloe pair (half size) from this folder instead, e.g. " +
                     middlebury::AloeDir() + " (Debian's opencv-doc)");
  app.add_option("--modes", modes_list,
                 "comma-separated: sgm4, sgm8 (ours; name@scalar|avx2|avx512 forces the code), "
                 "sgbm, sgbm-3way, hh, bm")
      ->capture_default_str();
  app.add_option("--rounds", rounds, "timed rounds over the frames")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  app.add_option("--frames", frames, "use only the first N pairs (0: all)")
      ->check(CLI::Range(0, 1000));
  app.add_option("--threads", threads, "threads of the throughput row")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  app.add_option("--per-thread", per_thread, "frames each throughput thread matches")
      ->check(CLI::Range(1, 10000))
      ->capture_default_str();
  app.add_flag("--no-throughput", no_throughput, "skip the throughput columns");
  app.add_option("--min-disparity", base.min_disparity, "the settings every mode gets")
      ->capture_default_str();
  app.add_option("--num-disparities", base.num_disparities)->capture_default_str();
  app.add_option("--block-size", base.block_size, "ours: 3, 5 or 7 (its census window)")
      ->capture_default_str();
  app.add_option("--p1", base.p1, "0: each matcher's default")->capture_default_str();
  app.add_option("--p2", base.p2, "0: each matcher's default")->capture_default_str();
  app.add_option("--uniqueness", base.uniqueness_ratio)->capture_default_str();
  app.add_option("--speckle-window", base.speckle_window_size)->capture_default_str();
  app.add_option("--speckle-range", base.speckle_range)->capture_default_str();
  app.add_option("--disp12-max-diff", base.disp12_max_diff)->capture_default_str();
  app.add_option(
      "--simd-levels", simd_levels,
      "also a table of ours (4 and 8 paths) per instruction set, e.g. scalar,avx2,avx512 "
      "(the ratio column is then to the first, scalar)");
  app.add_option(
      "--ranges", ranges,
      "also a table per disparity range MIN:NUM (e.g. 0:128,0:160,16:128) for the modes");
  app.add_option("--json", json_path, "write the tables as JSON");
  CLI11_PARSE(app, argc, argv);

  if (absl::Status s = base.Validate("settings"); !s.ok()) {
    std::fprintf(stderr, "%s\n", std::string(s.message()).c_str());
    return 2;
  }
  cv::setNumThreads(1);     // OpenCV's matchers on one thread, as ours
  std::vector<Mode> modes;  // made first: a wrong --modes fails before the data is read
  for (const std::string& name : SplitList(modes_list)) modes.push_back(MakeMode(name, base));
  const std::vector<Pair> pairs =
      aloe_dir.empty() ? LoadTsukuba(data_dir, frames) : LoadAloe(aloe_dir);
  std::string load;
  if (std::ifstream in("/proc/loadavg"); in) std::getline(in, load);
  std::printf(
      "%zu pairs of %ux%u (%s), disparities [%d, %d), block %d, uniqueness %d, speckle %d/%d, "
      "disp12 %d; %d rounds, CPU %s, load average %s\n",
      pairs.size(), pairs[0].left.width, pairs[0].left.height,
      aloe_dir.empty() ? "New Tsukuba" : "Aloe", base.min_disparity,
      base.min_disparity + base.num_disparities, base.block_size, base.uniqueness_ratio,
      base.speckle_window_size, base.speckle_range, base.disp12_max_diff, rounds,
      std::string(stereo::Name(stereo::BestSimdLevel())).c_str(), load.c_str());
  nlohmann::json out;
  out["load_average"] = load;

  RunTimed(modes, pairs, rounds);
  if (!no_throughput) {
    for (Mode& m : modes) RunThroughput(m, pairs, threads, per_thread);
  }
  out["modes"] = PrintAccuracyAndSpeed(
      "accuracy (matched pixels; \"all\": a pixel without a match counts as bad) and speed "
      "(thread CPU ms, median over rounds x frames)",
      modes, !no_throughput, threads);

  if (!simd_levels.empty()) {
    std::vector<Mode> simd;
    for (const char* paths : {"sgm4", "sgm8"}) {
      for (const std::string& level : SplitList(simd_levels)) {
        simd.push_back(MakeMode(std::string(paths) + "@" + level, base));
      }
    }
    RunTimed(simd, pairs, rounds);
    out["simd"] = PrintAccuracyAndSpeed("ours per instruction set (the same output)", simd, false,
                                        0, "scalar");
  }

  if (!ranges.empty()) {
    nlohmann::json tables = nlohmann::json::array();
    for (const std::string& range : SplitList(ranges)) {
      StereoParams p = base;
      if (std::sscanf(range.c_str(), "%d:%d", &p.min_disparity, &p.num_disparities) != 2) {
        std::fprintf(stderr, "--ranges: '%s' is not MIN:NUM\n", range.c_str());
        return 2;
      }
      if (absl::Status s = p.Validate("--ranges"); !s.ok()) {
        std::fprintf(stderr, "%s\n", std::string(s.message()).c_str());
        return 2;
      }
      std::vector<Mode> rm;
      for (const std::string& name : SplitList(modes_list)) rm.push_back(MakeMode(name, p));
      RunTimed(rm, pairs, 1);
      const std::string title = "disparities [" + std::to_string(p.min_disparity) + ", " +
                                std::to_string(p.min_disparity + p.num_disparities) + ")";
      tables.push_back({{"min_disparity", p.min_disparity},
                        {"num_disparities", p.num_disparities},
                        {"modes", PrintAccuracyAndSpeed(title.c_str(), rm, false, 0)}});
    }
    out["ranges"] = tables;
  }
  if (!json_path.empty()) std::ofstream(json_path) << out.dump(2) << "\n";
  return 0;
}

}  // namespace
}  // namespace cloudcast::bench

int main(int argc, char** argv) { return cloudcast::bench::Main(argc, argv); }
