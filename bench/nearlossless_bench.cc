// cloudcast-nearlossless-bench: what near-lossless disparity and depth (core/near_lossless.h)
// save on the uplink. For each geometry input of the New Tsukuba frames and each point error
// bound (0 = today's lossless row deltas + zstd): KB per frame after row deltas + zstd at the
// default level, the client's encode time (quantize + compress, this thread's CPU), the share of
// valid pixels whose value changed, and the largest point error measured through the server's
// own conversion (a check, not a promise: it must stay under the bound). Medians over the frames
// (each frame's time the median of --rounds). The camera: f = 615 px and New Tsukuba's real 10 cm
// baseline (--baseline; 1 is the paper's z = 615 / d). Inputs:
//   u8 disparity (truth)     the 8-bit ground truth: whole pixels move points by centimetres
//   u16 disparity (matcher)  our matcher's output on the grey pairs (1/16 px, sgm defaults)
//   u16 depth mm (matcher)   that disparity as a stereo depth camera gives it (16UC1, mm)
//   f32 depth m (matcher)    the same in float metres (32FC1)
//   u16 / f32 depth (truth)  the ground truth's depth (piecewise constant: few distinct values)
#include <time.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cloudcast/core/filters.h"
#include "cloudcast/core/frame_codec.h"
#include "cloudcast/core/near_lossless.h"
#include "cloudcast/core/settings.h"
#include "cloudcast/datasets/tsukuba.h"
#include "cloudcast/stereo/grey.h"
#include "cloudcast/stereo/matcher.h"
#include "stats.h"

namespace cloudcast::bench {
namespace {

double ThreadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

template <typename T>
T Check(absl::StatusOr<T> v, const char* what) {
  if (!v.ok()) {
    std::fprintf(stderr, "cloudcast-nearlossless-bench: %s: %s\n", what,
                 std::string(v.status().message()).c_str());
    std::exit(2);
  }
  return *std::move(v);
}

// One plane of one frame, packed, with the camera that reads it.
struct Plane {
  std::vector<std::uint8_t> bytes;
  std::uint32_t width = 0, height = 0;
  bool depth = false;
  DisparityEncoding disparity_encoding{};
  DepthEncoding depth_encoding{};
  CameraModel camera;
  DisparityView disparity() const {
    return {bytes.data(), bytes.size(), width, height,
            std::size_t{width} * BytesPerPixel(disparity_encoding), disparity_encoding};
  }
  DepthView depth_view() const {
    return {bytes.data(), bytes.size(), width, height,
            std::size_t{width} * BytesPerPixel(depth_encoding), depth_encoding};
  }
};

template <typename T>
Plane Packed(std::uint32_t w, std::uint32_t h, const std::vector<T>& v) {
  Plane p;
  p.width = w;
  p.height = h;
  p.bytes.resize(v.size() * sizeof(T));
  std::memcpy(p.bytes.data(), v.data(), p.bytes.size());
  return p;
}

struct Input {
  std::string name;
  std::vector<Plane> frames;
};

// Depth planes (float metres, 16-bit millimetres) of disparities `d` read by `camera`.
template <typename T>
void AddDepths(const std::vector<T>& d, std::uint32_t w, std::uint32_t h, const CameraModel& camera,
               Input* f32, Input* u16) {
  std::vector<float> zf(d.size());
  std::vector<std::uint16_t> z16(d.size());
  for (std::size_t i = 0; i < d.size(); ++i) {
    const double den = d[i] * camera.disparity_scale + camera.disparity_offset;
    const double z = d[i] == 0 || !(den > 0) ? 0.0 : camera.fx * camera.baseline / den;
    zf[i] = static_cast<float>(z);
    z16[i] = static_cast<std::uint16_t>(std::lround(std::min(z * 1000, 65535.0)));
  }
  CameraModel depth_camera = camera;
  depth_camera.depth_scale.reset();  // REP 118's units
  Plane df = Packed(w, h, zf);
  df.depth = true;
  df.depth_encoding = DepthEncoding::kF32;
  df.camera = depth_camera;
  f32->frames.push_back(std::move(df));
  Plane d16 = Packed(w, h, z16);
  d16.depth = true;
  d16.depth_encoding = DepthEncoding::kU16;
  d16.camera = depth_camera;
  u16->frames.push_back(std::move(d16));
}

std::vector<Input> LoadInputs(const std::string& dir, int max_frames, double baseline) {
  FrameSettings settings;
  if (!ApplyPreset("new_tsukuba", &settings, "preset", false).ok()) std::exit(2);
  CameraModel camera = settings.PipelineFor(640, 480).camera;
  camera.baseline = baseline;
  auto pairs = Check(tsukuba::LoadAllStereo(dir), "New Tsukuba");
  auto matcher = Check(stereo::MakeMatcher(StereoParams{}), "matcher");
  std::vector<Input> inputs = {{"u8 disparity (truth)", {}},     {"u16 disparity (matcher)", {}},
                               {"u16 depth mm (matcher)", {}},   {"f32 depth m (matcher)", {}},
                               {"u16 depth mm (truth)", {}},     {"f32 depth m (truth)", {}}};
  for (const StereoFrame& f : pairs) {
    if (max_frames > 0 && static_cast<int>(inputs[0].frames.size()) >= max_frames) break;
    const std::uint32_t w = f.truth.width, h = f.truth.height;
    Plane u8 = Packed(w, h, f.truth.pixels);
    u8.disparity_encoding = DisparityEncoding::kU8;
    u8.camera = camera;
    inputs[0].frames.push_back(std::move(u8));

    const stereo::GreyImage left = Check(stereo::ToGrey(f.left.view(), "left"), "grey");
    const stereo::GreyImage right = Check(stereo::ToGrey(f.right.view(), "right"), "grey");
    stereo::DisparityMap16 map;
    if (absl::Status s = matcher->Compute(left.view(), right.view(), &map); !s.ok()) {
      std::fprintf(stderr, "matcher: %s\n", std::string(s.message()).c_str());
      std::exit(2);
    }
    Plane u16 = Packed(w, h, map.values);
    u16.disparity_encoding = DisparityEncoding::kU16;
    u16.camera = stereo::ForMatcherOutput(camera);
    inputs[1].frames.push_back(std::move(u16));
    AddDepths(map.values, w, h, stereo::ForMatcherOutput(camera), &inputs[3], &inputs[2]);
    AddDepths(f.truth.pixels, w, h, camera, &inputs[5], &inputs[4]);
  }
  return inputs;
}

// The largest distance between the points of `a` and `b` (both organized), NaN pixels skipped;
// -1 when their validity differs anywhere.
double WorstError(const PointCloud& a, const PointCloud& b) {
  double worst = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const Point& p = a.points[i];
    const Point& q = b.points[i];
    if (std::isfinite(p.z) != std::isfinite(q.z)) return -1;
    if (!std::isfinite(p.z)) continue;
    const double dx = double{p.x} - q.x, dy = double{p.y} - q.y, dz = double{p.z} - q.z;
    worst = std::max(worst, std::sqrt(dx * dx + dy * dy + dz * dz));
  }
  return worst;
}

struct Row {
  std::string input;
  double bound_m = 0;
  double kb = 0, encode_ms = 0, changed_pct = 0, worst_mm = 0, ratio = 0;
};

Row Measure(const Input& input, double bound, int rounds, double lossless_kb) {
  PointErrorQuantizer quantizer;
  PlaneCompressor compressor;
  std::string out;
  std::vector<double> kb, ms, changed;
  double worst = 0;
  for (const Plane& p : input.frames) {
    std::vector<double> times;
    const void* data = nullptr;
    std::size_t stride = 0;
    PlaneLayout layout;
    for (int r = 0; r < rounds; ++r) {
      const double t0 = ThreadCpuMs();
      absl::Status s;
      if (bound == 0) {
        // Today's lossless path: straight into the compressor.
        data = p.bytes.data();
        stride = p.depth ? p.depth_view().stride_bytes : p.disparity().stride_bytes;
        layout = p.depth ? LayoutOf(p.depth_view()) : LayoutOf(p.disparity());
      } else if (p.depth) {
        DepthView q;
        s = quantizer.Quantize(p.depth_view(), p.camera, bound, "depth", &q);
        data = q.data;
        stride = q.stride_bytes;
        layout = LayoutOf(q);
      } else {
        DisparityView q;
        s = quantizer.Quantize(p.disparity(), p.camera, bound, "disparity", &q);
        data = q.data;
        stride = q.stride_bytes;
        layout = LayoutOf(q);
      }
      if (s.ok()) {
        s = compressor.Compress(data, stride, layout, Predictor::kUp, kDefaultCompressionLevel,
                                &out);
      }
      times.push_back(ThreadCpuMs() - t0);
      if (!s.ok()) {
        std::fprintf(stderr, "%s: %s\n", input.name.c_str(), std::string(s.message()).c_str());
        std::exit(2);
      }
    }
    ms.push_back(Median(times));
    kb.push_back(out.size() / 1000.0);
    const QuantizeStats& st = quantizer.stats();
    changed.push_back(bound == 0 || st.valid == 0 ? 0.0 : 100.0 * st.changed / st.valid);
    if (bound > 0) {
      // The check: the server's conversion of both planes (the quantized one is still in the
      // quantizer's buffer).
      std::vector<std::uint8_t> grey(std::size_t{p.width} * p.height, 0);
      const ColorView colour{grey.data(), grey.size(), p.width, p.height, p.width,
                             ColorEncoding::kMono8};
      PointCloud a, b;
      if (p.depth) {
        DepthView q{data, layout.bytes(), p.width, p.height, stride, p.depth_encoding};
        ConvertToOrganized(p.camera, p.depth_view(), colour, &a).IgnoreError();
        ConvertToOrganized(p.camera, q, colour, &b).IgnoreError();
      } else {
        DisparityView q{data, layout.bytes(), p.width, p.height, stride, p.disparity_encoding};
        ConvertToOrganized(p.camera, p.disparity(), colour, &a).IgnoreError();
        ConvertToOrganized(p.camera, q, colour, &b).IgnoreError();
      }
      const double e = WorstError(a, b);
      worst = e < 0 || worst < 0 ? -1 : std::max(worst, e);
    }
  }
  Row row;
  row.input = input.name;
  row.bound_m = bound;
  row.kb = Median(kb);
  row.encode_ms = Median(ms);
  row.changed_pct = Median(changed);
  row.worst_mm = worst < 0 ? -1 : worst * 1000;
  row.ratio = lossless_kb > 0 ? lossless_kb / row.kb : 1;
  return row;
}

int Main(int argc, char** argv) {
  CLI::App app{
      "cloudcast-nearlossless-bench: near-lossless disparity and depth on New Tsukuba: KB per "
      "frame and client encode ms (quantize + row deltas + zstd) per point error bound, "
      "medians over the frames; the worst point error measured through the server's conversion"};
  std::string data_dir = tsukuba::DefaultDir(), json_path, bounds_list = "1,5,10,20";
  int rounds = 5, frames = 0;
  double baseline = 0.1;
  app.add_option("--data", data_dir, "New Tsukuba folder (default: $CLOUDCAST_DATA or the build's)");
  app.add_option("--bounds-mm", bounds_list, "comma-separated point error bounds, millimetres")
      ->capture_default_str();
  app.add_option("--rounds", rounds, "timed encodings per frame (the median is kept)")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  app.add_option("--frames", frames, "at most this many frames (0: all)")->capture_default_str();
  app.add_option("--baseline", baseline,
                 "stereo baseline, metres: New Tsukuba's real 0.1 (z = 61.5 / d m, 0.3 to 6 m); "
                 "1 is the paper's and PCL's z = 615 / d")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--json", json_path, "also write the rows as JSON here");
  CLI11_PARSE(app, argc, argv);

  std::vector<double> bounds = {0};
  for (std::size_t start = 0; start <= bounds_list.size();) {
    const std::size_t comma = std::min(bounds_list.find(',', start), bounds_list.size());
    const std::string item = bounds_list.substr(start, comma - start);
    char* end = nullptr;
    const double mm = std::strtod(item.c_str(), &end);
    if (item.empty() || end != item.c_str() + item.size() || !(mm > 0) || !std::isfinite(mm)) {
      std::fprintf(stderr, "--bounds-mm: \"%s\" is not a positive number of millimetres\n",
                   item.c_str());
      return 2;
    }
    bounds.push_back(mm / 1000);
    start = comma + 1;
  }

  const std::vector<Input> inputs = LoadInputs(data_dir, frames, baseline);
  std::vector<Row> rows;
  for (const Input& input : inputs) {
    double lossless_kb = 0;
    for (double bound : bounds) {
      rows.push_back(Measure(input, bound, rounds, lossless_kb));
      if (bound == 0) lossless_kb = rows.back().kb;
    }
  }

  std::printf("New Tsukuba, %zu frames 640x480, f = 615 px, baseline %g m; row deltas + zstd "
              "level %d; medians over the frames (encode: quantize + compress, this thread's CPU, "
              "median of %d)\n\n",
              inputs[0].frames.size(), baseline, kDefaultCompressionLevel, rounds);
  std::printf("| input | bound mm | KB a frame | vs lossless | encode ms | values changed | "
              "worst point error mm |\n| --- | --- | --- | --- | --- | --- | --- |\n");
  nlohmann::json json = nlohmann::json::array();
  for (const Row& r : rows) {
    std::printf("| %s | %s | %.1f | %.2fx | %.2f | %.1f%% | %s |\n", r.input.c_str(),
                r.bound_m == 0 ? "0 (lossless)" : std::to_string(std::lround(r.bound_m * 1000)).c_str(),
                r.kb, r.ratio, r.encode_ms, r.changed_pct,
                r.bound_m == 0 ? "0" : (r.worst_mm < 0 ? "VALIDITY CHANGED"
                                                       : std::to_string(r.worst_mm).substr(0, 5))
                                           .c_str());
    json.push_back({{"input", r.input},
                    {"bound_m", r.bound_m},
                    {"kb_per_frame", r.kb},
                    {"ratio_to_lossless", r.ratio},
                    {"encode_ms", r.encode_ms},
                    {"changed_percent", r.changed_pct},
                    {"worst_point_error_m", r.worst_mm < 0 ? -1.0 : r.worst_mm / 1000}});
  }
  if (!json_path.empty()) {
    std::ofstream(json_path) << nlohmann::json{{"frames", inputs[0].frames.size()},
                                               {"baseline_m", baseline},
                                               {"rows", json}}
                                    .dump(2)
                             << "\n";
  }
  return 0;
}

}  // namespace
}  // namespace cloudcast::bench

int main(int argc, char** argv) { return cloudcast::bench::Main(argc, argv); }
