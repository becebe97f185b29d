#include "app/viewer.h"

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <thread>
#include <utility>

#include "absl/strings/str_cat.h"
#include "cloudcast/io/cloud_io.h"

namespace cloudcast::client::app {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

// When no new cloud comes, the window is still redrawn at about this rate so that it stays
// responsive to the mouse, without spinning a core that the server and decoder need.
constexpr milliseconds kIdleFrame{16};
// Without new clouds the overlay is refreshed this often (the rate falls, "paused" shows).
constexpr milliseconds kOverlayPeriod{250};

// "frame tsukuba_01800", or "sequence 9" for a frame without a name.
std::string FrameName(const CloudMeta& meta) {
  return meta.frame_id.empty() ? fmt::format("sequence {}", meta.sequence)
                               : fmt::format("frame {}", meta.frame_id);
}

absl::Status WriteSnapshot(render::Renderer& renderer, const std::string& path) {
  absl::Status s = renderer.SaveScreenshot(path);
  if (!s.ok()) return absl::Status(s.code(), absl::StrCat("--snapshot ", path, ": ", s.message()));
  spdlog::info("snapshot written to {} ({}x{})", path, renderer.framebuffer_width(),
               renderer.framebuffer_height());
  return absl::OkStatus();
}

// Displayed clouds per second over the last second: the intervals between the displays in it.
// It reads right from the second cloud on, and falls to 0 within a second when clouds stop.
class RateMeter {
 public:
  void Tick(Clock::time_point now) {
    times_.push_back(now);
    Trim(now);
  }
  double Rate(Clock::time_point now) {
    Trim(now);
    if (times_.size() < 2) return 0;
    const double span = std::chrono::duration<double>(times_.back() - times_.front()).count();
    return span > 0 ? (times_.size() - 1) / span : 0;
  }

 private:
  void Trim(Clock::time_point now) {
    while (!times_.empty() && now - times_.front() > std::chrono::seconds(1)) times_.pop_front();
  }
  std::deque<Clock::time_point> times_;
};

}  // namespace

// ---------------------------------------------------------------------------------------------

void CloudMailbox::Put(Result& result) {
  if (!result.ok()) return;
  {
    std::unique_lock<std::mutex> lock(mu_);
    if (wait_for_viewer_ && full_ && !closed_) {
      ++puts_held_;
      held_cv_.notify_all();
      taken_cv_.wait(lock, [this] { return !full_ || closed_; });
    }
    if (closed_) return;
    if (full_) ++skipped_;
    std::swap(slot_, result.cloud);
    meta_.sequence = result.sequence;
    meta_.frame_id = result.frame_id;
    meta_.draco_bytes = result.draco_bytes();
    meta_.latency_ms = std::chrono::duration<double, std::milli>(result.latency()).count();
    meta_.frames_dropped = result.frames_dropped;
    full_ = true;
  }
  put_cv_.notify_one();
}

bool CloudMailbox::Take(PointCloud* cloud, CloudMeta* meta, milliseconds timeout) {
  {
    std::unique_lock<std::mutex> lock(mu_);
    if (!put_cv_.wait_for(lock, timeout, [this] { return full_; })) return false;
    std::swap(*cloud, slot_);
    *meta = meta_;
    full_ = false;
  }
  taken_cv_.notify_one();
  return true;
}

void CloudMailbox::Close() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    closed_ = true;
  }
  taken_cv_.notify_all();
}

bool CloudMailbox::has_new() const {
  std::lock_guard<std::mutex> lock(mu_);
  return full_;
}

std::uint64_t CloudMailbox::skipped() const {
  std::lock_guard<std::mutex> lock(mu_);
  return skipped_;
}

bool CloudMailbox::WaitForPutsHeld(std::uint64_t count, milliseconds timeout) const {
  std::unique_lock<std::mutex> lock(mu_);
  return held_cv_.wait_for(lock, timeout, [&] { return puts_held_ >= count; });
}

std::string OverlayLine(double fps, double latency_ms, std::size_t points, std::size_t bytes,
                        std::uint64_t dropped, bool paused, bool ended) {
  std::string line = fmt::format("{:.1f} fps | {:.1f} ms | {} points | {:.1f} KB | dropped {}", fps,
                                 latency_ms, points, bytes / 1024.0, dropped);
  if (paused) line += " | paused (space)";
  if (ended) line += " | stream ended";
  return line;
}

absl::StatusOr<std::unique_ptr<render::Renderer>> OpenWindow(const ViewerOptions& options) {
  auto renderer = render::Renderer::Create(options.window);
  if (!renderer.ok()) {
    return absl::Status(
        renderer.status().code(),
        absl::StrCat("cannot open the viewer window: ", renderer.status().message(),
                     ". Without a display, run under Xvfb (xvfb-run -a cloudcast-client ...) "
                     "or use --no-window"));
  }
  (*renderer)->SetScreenshotPath(options.screenshot_pattern);
  return renderer;
}

absl::Status RunLiveViewer(render::Renderer& renderer, Session& session, CloudMailbox& mailbox,
                           StreamStats& stats, const ViewerOptions& options,
                           const std::atomic<bool>& interrupted) {
  // `cloud` is on screen; `incoming` receives from the mailbox. For the snapshot, the last cloud
  // with points before the one shown is kept too (buffers rotate, nothing is copied).
  PointCloud cloud, incoming, last_with_points;
  CloudMeta meta, incoming_meta, last_with_points_meta;
  std::uint64_t displayed = 0;
  bool view_set = false;
  bool ended = false;
  Smoothed latency(0.2);
  RateMeter rate;
  bool ended_shown = false;
  Clock::time_point overlay_at{};
  std::string last_screenshot;
  renderer.SetOverlayText("waiting for the first cloud...");

  while (!renderer.ShouldClose() && !interrupted.load()) {
    // Paused, clouds are still taken (into a spare buffer) and counted, so that the stream keeps
    // moving: a stalled stream would hit the server's idle timeout.
    const bool paused = renderer.paused();
    const bool fresh = mailbox.Take(&incoming, &incoming_meta, kIdleFrame) && !paused;
    if (fresh) {
      if (!cloud.empty()) {
        std::swap(last_with_points, cloud);
        std::swap(last_with_points_meta, meta);
      }
      std::swap(cloud, incoming);
      std::swap(meta, incoming_meta);
      renderer.Upload(cloud.points.data(), cloud.size());
      // The first cloud with points frames the view; later ones keep the user's camera.
      if (!view_set && !cloud.empty()) {
        renderer.ResetViewToCloud(cloud.points.data(), cloud.size());
        view_set = true;
      }
      ++displayed;
      stats.RecordDisplayed();
      rate.Tick(Clock::now());
      latency.Add(meta.latency_ms);
    }
    if (!ended && session.done() && !mailbox.has_new()) ended = true;

    // Each new cloud shows its own figures; otherwise a few refreshes a second let the rate fall
    // when clouds stop coming.
    const Clock::time_point now = Clock::now();
    if (fresh || ended != ended_shown || now - overlay_at >= kOverlayPeriod) {
      ended_shown = ended;
      overlay_at = now;
      if (displayed > 0 || ended) {
        renderer.SetOverlayText(OverlayLine(rate.Rate(now), latency.value(), cloud.size(),
                                            meta.draco_bytes, meta.frames_dropped, paused, ended));
      }
    }
    renderer.Draw();

    // An empty view makes a useless picture (two of New Tsukuba's ten frames lie wholly outside
    // the paper's passthrough, the last one among them), so the snapshot waits for a cloud with
    // points, and when the stream ends on an empty one it shows the last cloud that had points.
    const bool snapshot_due = !options.snapshot_path.empty() &&
                              ((displayed >= options.snapshot_after && !cloud.empty()) || ended);
    if (snapshot_due) {
      if (displayed == 0) {
        return absl::UnavailableError(
            absl::StrCat("--snapshot ", options.snapshot_path,
                         ": the stream ended without a single cloud to show"));
      }
      if (displayed < options.snapshot_after) {
        spdlog::warn("the stream ended after {} clouds, before --snapshot-after {}", displayed,
                     options.snapshot_after);
      }
      if (cloud.empty() && !last_with_points.empty()) {
        spdlog::warn("the last cloud ({}) was empty: the snapshot shows {} ({} points)",
                     FrameName(meta), FrameName(last_with_points_meta), last_with_points.size());
        renderer.Upload(last_with_points.points.data(), last_with_points.size());
        // One short line, the news first: a second line would reach into the picture.
        const CloudMeta& shown = last_with_points_meta;
        renderer.SetOverlayText(fmt::format(
            "last cloud empty, showing {} | {} points",
            shown.frame_id.empty() ? fmt::format("sequence {}", shown.sequence) : shown.frame_id,
            last_with_points.size()));
        renderer.Draw();
      } else if (cloud.empty()) {
        spdlog::warn("every cloud of the stream was empty: the snapshot shows no points");
      }
      absl::Status s = WriteSnapshot(renderer, options.snapshot_path);
      session.Stop();
      return s;
    }
    renderer.Swap();
    if (renderer.last_screenshot_path() != last_screenshot) {
      last_screenshot = renderer.last_screenshot_path();
      spdlog::info("screenshot saved to {}", last_screenshot);
    }
    if (ended && options.exit_at_end) break;
  }
  session.Stop();
  return absl::OkStatus();
}

absl::StatusOr<std::vector<PointCloud>> LoadCloudFiles(const std::vector<std::string>& files) {
  std::vector<PointCloud> clouds(files.size());
  for (std::size_t i = 0; i < files.size(); ++i) {
    if (absl::Status s = CheckCloudPath(files[i]); !s.ok()) {
      return absl::Status(s.code(), absl::StrCat("--open: ", s.message()));
    }
    if (absl::Status s = LoadCloud(files[i], &clouds[i]); !s.ok()) {
      return absl::Status(s.code(), absl::StrCat("--open: ", s.message()));
    }
    spdlog::info("{}: {} points{}", files[i], clouds[i].size(),
                 clouds[i].organized()
                     ? fmt::format(" (organized {}x{})", clouds[i].width, clouds[i].height)
                     : "");
  }
  return clouds;
}

absl::Status RunFileViewer(render::Renderer& renderer, const std::vector<std::string>& files,
                           const std::vector<PointCloud>& clouds, const ViewerOptions& options,
                           const std::atomic<bool>& interrupted) {
  const std::size_t n = clouds.size();
  std::size_t shown = SIZE_MAX;
  std::size_t current = 0;
  std::uint64_t frames = 0;
  std::string last_screenshot;
  // Arrow keys are not characters, so they come through the renderer's key hook. It runs on
  // this thread inside Swap, where the counter is read: no lock needed.
  int arrow_steps = 0;  // +1 per right / down press, -1 per left / up
  renderer.SetKeyHandler([&arrow_steps](int key, int action, int /*mods*/) {
    if (action != GLFW_PRESS && action != GLFW_REPEAT) return;
    if (key == GLFW_KEY_RIGHT || key == GLFW_KEY_DOWN || key == GLFW_KEY_PAGE_DOWN) ++arrow_steps;
    if (key == GLFW_KEY_LEFT || key == GLFW_KEY_UP || key == GLFW_KEY_PAGE_UP) --arrow_steps;
  });
  struct Unhook {  // the handler refers to this frame's counter
    render::Renderer& r;
    ~Unhook() { r.SetKeyHandler(nullptr); }
  } unhook{renderer};

  while (!renderer.ShouldClose() && !interrupted.load()) {
    if (arrow_steps != 0) {
      const auto count = static_cast<std::int64_t>(n);
      const std::int64_t next = (static_cast<std::int64_t>(current) + arrow_steps % count + count);
      current = static_cast<std::size_t>(next % count);
      arrow_steps = 0;
    }
    if (current != shown) {
      const PointCloud& c = clouds[current];
      renderer.Upload(c.points.data(), c.size());
      renderer.ResetViewToCloud(c.points.data(), c.size());
      std::size_t finite = 0;
      for (const Point& p : c.points) finite += std::isfinite(p.x) ? 1 : 0;
      std::string text = fmt::format("{} ({}/{}) | {} points",
                                     std::filesystem::path(files[current]).filename().string(),
                                     current + 1, n, finite);
      if (n > 1) text += " | arrows: next / previous";
      renderer.SetOverlayText(text);
      shown = current;
    }
    renderer.Draw();
    ++frames;
    if (!options.snapshot_path.empty() &&
        frames >= std::max<std::uint64_t>(1, options.snapshot_after)) {
      return WriteSnapshot(renderer, options.snapshot_path);
    }
    renderer.Swap();
    if (renderer.last_screenshot_path() != last_screenshot) {
      last_screenshot = renderer.last_screenshot_path();
      spdlog::info("screenshot saved to {}", last_screenshot);
    }
    // Nothing changes between key presses: redraw at a modest rate.
    std::this_thread::sleep_for(kIdleFrame);
  }
  return absl::OkStatus();
}

}  // namespace cloudcast::client::app
