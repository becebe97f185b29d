// cloudcast-render-bench: frame time of cloudcast's OpenGL renderer against stock PCLVisualizer
// (VTK), with a new cloud every frame, on realistic clouds: New Tsukuba frame 00001 as an
// organized cloud (307,200 points, NaN holes included) and as the fused pipeline's output
// (paper parameters, about 16k points). Needs an X display; without one, run it as
//   xvfb-run -a -s "-screen 0 1280x1024x24 -noreset" build/bin/cloudcast-render-bench
// (-noreset: an X server otherwise resets, refusing connections, whenever its last client goes.)
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cloudcast/core/camera.h"
#include "cloudcast/core/filters.h"
#include "cloudcast/core/pipeline.h"
#include "cloudcast/datasets/synthetic.h"
#include "cloudcast/datasets/tsukuba.h"
#include "cloudcast/io/image_io.h"
#include "cloudcast/render/renderer.h"
#include "pclvis_bench.h"

namespace cloudcast::bench {
namespace {

using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

struct Samples {
  std::vector<double> ms;
  void Add(double v) { ms.push_back(v); }
  double Quantile(double q) const {
    if (ms.empty()) return 0;
    std::vector<double> s = ms;
    std::sort(s.begin(), s.end());
    return s[static_cast<std::size_t>(q * (s.size() - 1) + 0.5)];
  }
  double Min() const { return Quantile(0); }
  double Median() const { return Quantile(0.5); }
  double Max() const { return Quantile(1); }
  nlohmann::json Json() const {
    return {{"median_ms", Median()},
            {"min_ms", Min()},
            {"max_ms", Max()},
            {"frames", ms.size()},
            {"samples_ms", ms}};
  }
};

void Check(const absl::Status& s, const std::string& what) {
  if (!s.ok()) {
    std::cerr << what << " failed: " << s << "\n";
    std::exit(1);
  }
}

// One benchmarked cloud size: a few variants, so every frame uploads different data.
struct Workload {
  std::string name;
  std::vector<PointCloud> variants;
  std::size_t finite = 0;
  Samples ours, ours_upload, ours_draw;
  Samples pcl;              // stock: updatePointCloud + spinOnce(1, true)
  Samples pcl_render_only;  // updatePointCloud + Render(), no event loop
};

// Variant k moves every point by k millimetres and flips the low colour bit: the same picture,
// but never the same bytes two frames in a row (nothing can be cached between frames).
std::vector<PointCloud> Variants(const PointCloud& base, int count) {
  std::vector<PointCloud> out;
  for (int k = 0; k < count; ++k) {
    PointCloud c = base;
    const float d = 0.001f * static_cast<float>(k);
    for (Point& p : c.points) {
      p.x += d;
      p.y += d;
      p.rgba ^= static_cast<std::uint32_t>(k & 1);
    }
    out.push_back(std::move(c));
  }
  return out;
}

std::size_t CountFinite(const PointCloud& c) {
  return static_cast<std::size_t>(
      std::count_if(c.points.begin(), c.points.end(), [](const Point& p) {
        return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
      }));
}

int Main(int argc, char** argv) {
  CLI::App app{
      "cloudcast-render-bench: cloudcast's OpenGL renderer against stock PCLVisualizer (VTK),\n"
      "new cloud every frame. Frame = upload + draw + swap, until glFinish (cloudcast);\n"
      "updatePointCloud + spinOnce(1, true) until VTK's WaitForCompletion (PCLVisualizer, the\n"
      "stock path); and updatePointCloud + Render() without the event loop (VTK render only).\n"
      "Needs an X display: xvfb-run -a -s \"-screen 0 1280x1024x24 -noreset\" "
      "cloudcast-render-bench"};
  std::string data_dir = tsukuba::DefaultDir();
  bool synthetic = false, skip_pcl = false, hidden = false;
  int frames = 61, pcl_frames = 11, warmup = 3, width = 1280, height = 720, variants = 4;
  float point_size = 2.0f;
  std::string json_path;
  app.add_option("--data", data_dir,
                 "New Tsukuba folder (holds groundtruth/ and illumination/); the synthetic scene "
                 "at 640x480 is used when it is absent")
      ->capture_default_str();
  app.add_flag("--synthetic", synthetic, "use the synthetic scene even if --data exists");
  app.add_option("--frames", frames, "timed cloudcast frames per cloud size")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  app.add_option("--pcl-frames", pcl_frames, "timed PCLVisualizer frames per cloud size")
      ->check(CLI::Range(1, 10000))
      ->capture_default_str();
  app.add_option("--warmup", warmup, "untimed frames first, for each renderer")
      ->check(CLI::Range(0, 1000))
      ->capture_default_str();
  app.add_option("--width", width, "window width, both renderers")
      ->check(CLI::Range(16, 8192))
      ->capture_default_str();
  app.add_option("--height", height, "window height, both renderers")
      ->check(CLI::Range(16, 8192))
      ->capture_default_str();
  app.add_option("--point-size", point_size, "point size in pixels, both renderers")
      ->check(CLI::Range(1.0f, 64.0f))
      ->capture_default_str();
  app.add_option("--variants", variants, "different clouds cycled per size")
      ->check(CLI::Range(2, 64))
      ->capture_default_str();
  app.add_flag("--hidden", hidden, "cloudcast renders into a hidden window (no swap to screen)");
  app.add_flag("--skip-pcl", skip_pcl, "measure cloudcast only");
  app.add_option("--json", json_path, "also write the results as JSON to this file");
  CLI11_PARSE(app, argc, argv);

  // --- the clouds
  std::string input;
  OwnedDisparity disparity;
  OwnedColor colour;
  CameraModel camera;
  if (!synthetic && tsukuba::Present(data_dir)) {
    auto frame = tsukuba::Load(data_dir, "00001");
    Check(frame.status(), "loading New Tsukuba frame 00001");
    disparity = std::move(frame->disparity);
    colour = std::move(frame->colour);
    camera = CameraModel::PclCompatible(disparity.width, disparity.height);
    input = "New Tsukuba frame 00001 (" + data_dir + ")";
  } else {
    if (!synthetic) std::cout << "note: no New Tsukuba data at " << data_dir << "\n";
    SyntheticOptions o;
    o.disparity_encoding = DisparityEncoding::kU8;
    auto r = SyntheticScene::Default().Render(o);
    Check(r.status(), "synthetic render");
    camera = r->camera;
    disparity.width = colour.width = r->width;
    disparity.height = colour.height = r->height;
    disparity.encoding = DisparityEncoding::kU8;
    disparity.pixels = std::move(r->disparity);
    colour.encoding = ColorEncoding::kBGR8;
    colour.pixels = std::move(r->colour);
    input = "synthetic scene 640x480, frame 0 (8-bit disparity)";
  }
  PointCloud organized, fused;
  Check(ConvertToOrganized(camera, disparity.view(), colour.view(), &organized),
        "ConvertToOrganized");
  PipelineOptions paper;  // passthrough z in [3, 12], leaf 0.03
  paper.camera = camera;
  Pipeline pipeline;
  Check(pipeline.Run(paper, disparity.view(), colour.view(), &fused), "fused pipeline");

  std::vector<Workload> work(2);
  work[0].name = "organized";
  work[0].variants = Variants(organized, variants);
  work[0].finite = CountFinite(organized);
  work[1].name = "fused pipeline";
  work[1].variants = Variants(fused, variants);
  work[1].finite = CountFinite(fused);

  std::cout << "input: " << input << "\n"
            << "window: " << width << "x" << height << ", point size " << point_size
            << ", camera at the origin looking along +z (60-degree vertical FOV)\n"
            << "frames: cloudcast " << frames << ", PCLVisualizer " << pcl_frames << " (+" << warmup
            << " warm-up each), " << variants << " different clouds cycled\n\n";

  // --- cloudcast. The renderer stays open until the end: closing the process's last X
  // connection would let a server without -noreset reset under PCLVisualizer's connect.
  std::unique_ptr<render::Renderer> renderer_holder;
  {
    render::RendererOptions o;
    o.width = width;
    o.height = height;
    o.point_size = point_size;
    o.visible = !hidden;
    o.title = "cloudcast-render-bench";
    auto r = render::Renderer::Create(o);
    Check(r.status(), "creating the renderer");
    renderer_holder = *std::move(r);
    render::Renderer& renderer = *renderer_holder;
    for (Workload& w : work) {
      for (int f = -warmup; f < frames; ++f) {
        const PointCloud& c = w.variants[static_cast<std::size_t>(f + warmup) % w.variants.size()];
        const auto t0 = Clock::now();
        renderer.Upload(c.points.data(), c.size());
        const double upload = MsSince(t0);
        const auto t1 = Clock::now();
        renderer.Draw();
        renderer.Swap();
        renderer.Finish();
        const double draw = MsSince(t1);
        const double total = MsSince(t0);
        if (f < 0) continue;
        w.ours.Add(total);
        w.ours_upload.Add(upload);
        w.ours_draw.Add(draw);
      }
    }
  }

  // --- PCLVisualizer
  if (!skip_pcl) {
    PclVisualizerBench vis(width, height, point_size);
    for (Workload& w : work) {
      std::vector<const PointCloud*> clouds;
      for (const PointCloud& c : w.variants) clouds.push_back(&c);
      vis.Prepare(clouds);
      for (int f = -warmup; f < pcl_frames; ++f) {
        const double ms = vis.FrameRenderOnly(static_cast<std::size_t>(f + warmup));
        if (f >= 0) w.pcl_render_only.Add(ms);
      }
      for (int f = -warmup; f < pcl_frames; ++f) {
        const double ms = vis.Frame(static_cast<std::size_t>(f + warmup));
        if (f >= 0) w.pcl.Add(ms);
      }
    }
  }

  // --- report
  auto range = [](const Samples& x, const char* format) {
    char b[64] = "-";
    if (!x.ms.empty()) std::snprintf(b, sizeof(b), format, x.Median(), x.Min(), x.Max());
    return std::string(b);
  };
  auto ratio = [](const Samples& theirs, const Samples& ours) {
    char b[32] = "-";
    if (!theirs.ms.empty()) std::snprintf(b, sizeof(b), "%.1fx", theirs.Median() / ours.Median());
    return std::string(b);
  };
  std::printf("%-16s %7s %7s | %-21s %6s %6s | %-24s %6s | %-21s %6s\n", "cloud", "points",
              "finite", "cloudcast ms/frame", "upload", "draw", "PCLVisualizer stock", "ratio",
              "PCLVis render only", "ratio");
  std::printf("%-16s %7s %7s | %-21s %6s %6s | %-24s %6s | %-21s %6s\n", "", "", "",
              "median (min..max)", "median", "median", "spinOnce, median (min..max)", "",
              "median (min..max)", "");
  nlohmann::json rows = nlohmann::json::array();
  for (const Workload& w : work) {
    std::printf("%-16s %7zu %7zu | %-21s %6.2f %6.2f | %-24s %6s | %-21s %6s\n", w.name.c_str(),
                w.variants[0].size(), w.finite, range(w.ours, "%.1f (%.1f..%.1f)").c_str(),
                w.ours_upload.Median(), w.ours_draw.Median(),
                range(w.pcl, "%.0f (%.0f..%.0f)").c_str(), ratio(w.pcl, w.ours).c_str(),
                range(w.pcl_render_only, "%.0f (%.0f..%.0f)").c_str(),
                ratio(w.pcl_render_only, w.ours).c_str());
    nlohmann::json row = {{"cloud", w.name},
                          {"points", w.variants[0].size()},
                          {"finite_points", w.finite},
                          {"cloudcast", w.ours.Json()},
                          {"cloudcast_upload", w.ours_upload.Json()},
                          {"cloudcast_draw_swap_finish", w.ours_draw.Json()}};
    if (!w.pcl.ms.empty()) {
      row["pclvisualizer_spinonce"] = w.pcl.Json();
      row["ratio_spinonce"] = w.pcl.Median() / w.ours.Median();
      row["pclvisualizer_render_only"] = w.pcl_render_only.Json();
      row["ratio_render_only"] = w.pcl_render_only.Median() / w.ours.Median();
    }
    rows.push_back(row);
  }
  std::printf(
      "\nratio = PCLVisualizer median / cloudcast median; target >= 20x (stock path) at 307,200.\n"
      "upload = Upload() (orphan + glBufferSubData); draw = Draw + Swap + glFinish.\n"
      "PCLVisualizer stock includes VTK 9.1's X event wait in spinOnce (idles ~1 s under Xvfb);\n"
      "render only = updatePointCloud + Render + WaitForCompletion.\n");

  if (!json_path.empty()) {
    nlohmann::json report = {{"input", input},
                             {"window", {{"width", width}, {"height", height}}},
                             {"point_size", point_size},
                             {"hidden", hidden},
                             {"variants", variants},
                             {"warmup", warmup},
                             {"rows", rows}};
    std::ofstream out(json_path);
    out << report.dump(2) << "\n";
    if (!out) {
      std::cerr << "cannot write " << json_path << "\n";
      return 1;
    }
  }
  return 0;
}

}  // namespace
}  // namespace cloudcast::bench

int main(int argc, char** argv) { return cloudcast::bench::Main(argc, argv); }
