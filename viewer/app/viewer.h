// cloudcast-client's window: the live view of a stream, and the viewer of local cloud files.
// Everything here runs on the main thread (GLFW's rule); clouds reach it through a CloudMailbox
// filled on the receiving thread.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "app/session.h"
#include "app/stats.h"
#include "cloudcast/client/result.h"
#include "cloudcast/core/point.h"
#include "cloudcast/render/renderer.h"

namespace cloudcast::client::app {

// What the overlay shows about a cloud, beside its points.
struct CloudMeta {
  std::uint64_t sequence = 0;
  std::string frame_id;  // the source's name of the frame, e.g. "tsukuba_01800"
  std::size_t draco_bytes = 0;
  double latency_ms = 0;
  std::uint64_t frames_dropped = 0;
};

// The hand-over of clouds from the receiving thread to the viewer, one cloud deep. Buffers are
// swapped, never copied, so steady streaming allocates nothing.
//
// Two policies:
//   replace (a paced camera, --fps N): a cloud that arrives before the previous one was drawn
//     replaces it (counted in skipped()), so the view never lags behind the stream;
//   wait (--fps 0): Put waits until the previous cloud was taken. The receiver then stops
//     reading, the sender's in-flight window stays full, and frames are sent only as fast as
//     they are displayed: on 2 cores, the server and the decoder then spend no time on clouds
//     nobody sees, which leaves it to the renderer.
class CloudMailbox {
 public:
  explicit CloudMailbox(bool wait_for_viewer = false) : wait_for_viewer_(wait_for_viewer) {}

  // Receiving thread: takes `result`'s cloud (leaving it a spare buffer to reuse). Returns at
  // once after Close().
  void Put(Result& result);
  // Viewer: waits up to `timeout` for a cloud not yet taken; swaps it into `cloud`.
  bool Take(PointCloud* cloud, CloudMeta* meta, std::chrono::milliseconds timeout);
  // No viewer any more: Put stops waiting and drops clouds.
  void Close();
  bool has_new() const;
  std::uint64_t skipped() const;
  // For tests, which must see the wait policy hold a Put instead of guessing with a sleep: waits
  // until `count` Put calls in all have had to wait for the viewer, or `timeout` passes (false).
  bool WaitForPutsHeld(std::uint64_t count, std::chrono::milliseconds timeout) const;

 private:
  const bool wait_for_viewer_;
  mutable std::mutex mu_;
  std::condition_variable taken_cv_, put_cv_;
  mutable std::condition_variable held_cv_;
  std::uint64_t puts_held_ = 0;
  PointCloud slot_;
  CloudMeta meta_;
  bool full_ = false;
  bool closed_ = false;
  std::uint64_t skipped_ = 0;
};

struct ViewerOptions {
  render::RendererOptions window;
  // Empty: no snapshot. Otherwise a PNG written once `snapshot_after` clouds were displayed and
  // the one shown has points (or when the stream ends first: then of the last cloud with points,
  // the log and the overlay saying so), after which the viewer returns.
  std::string snapshot_path;
  std::uint64_t snapshot_after = 10;
  // Return when the stream has ended (otherwise the window stays open on the last cloud).
  bool exit_at_end = false;
  // Where the 's' key saves screenshots.
  std::string screenshot_pattern = "cloudcast-%d.png";
};

// Opens the window. Errors say how to get a display (Xvfb) or to use --no-window.
absl::StatusOr<std::unique_ptr<render::Renderer>> OpenWindow(const ViewerOptions& options);

// Shows the clouds of a running session until the window is closed, `interrupted` is set, the
// snapshot is written, or (with exit_at_end) the stream ends. Stops the session when it returns
// early. Errors: the snapshot could not be written, or no cloud ever arrived for it.
absl::Status RunLiveViewer(render::Renderer& renderer, Session& session, CloudMailbox& mailbox,
                           StreamStats& stats, const ViewerOptions& options,
                           const std::atomic<bool>& interrupted);

// Reads local cloud files (.pcd, .ply, .drc), all of them up front so that a bad one is reported
// before a window opens. Errors name the file.
absl::StatusOr<std::vector<PointCloud>> LoadCloudFiles(const std::vector<std::string>& files);

// Shows `clouds` (read from `files`): the first, and the next / previous with the arrow keys
// (right / left, also down / up).
absl::Status RunFileViewer(render::Renderer& renderer, const std::vector<std::string>& files,
                           const std::vector<PointCloud>& clouds, const ViewerOptions& options,
                           const std::atomic<bool>& interrupted);

// The overlay's line, e.g. "58.3 fps | 12.4 ms | 16186 points | 45.2 KB | dropped 3".
std::string OverlayLine(double fps, double latency_ms, std::size_t points, std::size_t bytes,
                        std::uint64_t dropped, bool paused, bool ended);

}  // namespace cloudcast::client::app
