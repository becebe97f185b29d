// The live point cloud renderer: one window, one OpenGL 3.3 core context, our 16-byte points
// uploaded to the GPU as they are and coloured by a shader that unpacks PCL's 0xAARRGGBB word
// with integer operations. It replaces PCLVisualizer (VTK) on the client, as the paper's section
// B did, and knows nothing of the network: tests and benchmarks drive it with plain arrays.
//
// Threading: GLFW requires window creation and event polling on the main thread, so create,
// use and destroy a Renderer on the main thread. Several Renderers may exist at once; each call
// makes its own context current.
//
// A frame is:   Upload(points, n) (only when a new cloud arrived)  ->  SetOverlayText(...)  ->
//               Draw()  ->  Swap()   (Swap also polls mouse and keyboard events)
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cloudcast/core/point.h"

namespace cloudcast::render {

struct RendererOptions {
  // Window size in screen coordinates (equal to framebuffer pixels without HiDPI scaling).
  int width = 1280, height = 720;
  // false: the window is never shown; rendering still goes to its (offscreen) default
  // framebuffer, which ReadPixelsRgb / SaveScreenshot read. For tests, benchmarks, batch jobs.
  bool visible = true;
  std::string title = "cloudcast";
  // Side of the square drawn for each point, in framebuffer pixels ('+' / '-' change it).
  float point_size = 2.0f;
  // Clear colour, linear RGB in [0, 1].
  std::array<float, 3> background = {0.08f, 0.08f, 0.10f};
  // true: Swap waits for the display's vertical blank (caps the frame rate at the refresh rate).
  bool vsync = false;
};

// An axis-aligned box in point coordinates (the camera frame: x right, y down, z forward).
struct Bounds3 {
  float min[3], max[3];
};

class Renderer {
 public:
  // Opens the window and compiles the shaders. Errors: FailedPrecondition when no display can be
  // opened (e.g. $DISPLAY unset: run under Xvfb / xvfb-run), Unavailable when no OpenGL 3.3 core
  // context can be created, Internal when a shader fails to compile (with the driver's log).
  static absl::StatusOr<std::unique_ptr<Renderer>> Create(const RendererOptions& options);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // Replaces the drawn cloud with `count` points (copied; `points` may be freed afterwards).
  // The GPU buffer is reused: it grows only when `count` exceeds its capacity, otherwise it is
  // orphaned and refilled, so there is no GL object allocation per frame. Points with a NaN or
  // infinite coordinate are not drawn (the vertex shader moves them outside the clip volume), so
  // organized clouds upload as they are. Alpha is ignored: points are opaque.
  void Upload(const cloudcast::Point* points, std::size_t count);
  // Number of points of the last Upload (NaN points included).
  std::size_t point_count() const;
  // Bytes of GPU storage behind the point buffer: at least 16 * the largest upload so far; it
  // never shrinks, so smaller clouds reuse it.
  std::size_t gpu_buffer_bytes() const;

  // Text drawn on top, top-left, in a built-in 8x8 font at 2x scale on a dark box (fps, latency,
  // points, bytes). '\n' starts a new line; characters outside ASCII 32..126 show as '?'.
  // Empty: no overlay.
  void SetOverlayText(const std::string& line);

  // Clears to the background, draws the points (depth tested) and the overlay into the back
  // buffer. Does not swap.
  void Draw();
  // Shows the back buffer and polls window events (mouse, keys, close). Call once per frame,
  // after Draw; also keep calling it while paused so the window stays responsive.
  void Swap();

  // Blocks until the GPU has finished all submitted work (glFinish). Only for measuring: a
  // benchmark calls it before stopping its clock, since GL calls return before the work is done.
  void Finish();

  // True once the window's close button, Esc or 'q' was pressed.
  bool ShouldClose() const;
  // Toggled by the space key. The renderer only keeps the flag: the caller decides what pausing
  // means (typically: keep drawing the last cloud, stop uploading new ones).
  bool paused() const;
  void SetPaused(bool paused);

  // Points the camera at the centre of `bounds`, looking along +z with y down (as the stereo
  // camera sees it), from the distance at which the whole box fits the 60-degree vertical field
  // of view (and the horizontal one). Remembered: the 'r' key returns to it.
  void ResetView(const Bounds3& bounds);
  // ResetView on the bounds of the finite points (NaN points ignored). No finite point: the
  // default view (from the origin along +z), also remembered for 'r'.
  void ResetViewToCloud(const cloudcast::Point* points, std::size_t count);

  // Mouse actions, also callable directly (the window's callbacks call these). Deltas are in
  // window pixels, positive right / down. Left drag: orbit (yaw, pitch) around the target.
  void Orbit(double dx, double dy);
  // Right or middle drag: moves the target in the view plane so the scene follows the mouse.
  void Pan(double dx, double dy);
  // Scroll: scales the distance to the target by 0.9^steps (positive steps zoom in).
  void Zoom(double steps);

  // The keyboard map, callable directly (the window's character and key callbacks call it):
  // '+' / '-' (keypad too; '=' counts as '+', its unshifted key on US layouts) point size by one
  // pixel, ' ' pause, 'r' reset view, 's' screenshot, 'q' close (Esc closes as well). Returns
  // false for characters without a binding.
  bool HandleCharacter(unsigned int codepoint);

  // Keys without a character (arrows, page up / down, function keys) for the program on top:
  // called with GLFW's key code (e.g. GLFW_KEY_RIGHT), action (GLFW_PRESS / GLFW_REPEAT /
  // GLFW_RELEASE) and modifier bits for every key event, after the renderer's own handling (Esc),
  // on the main thread inside Swap. Characters still go through HandleCharacter. Empty: none.
  void SetKeyHandler(std::function<void(int key, int action, int mods)> handler);

  // Point size in pixels, clamped to [1, the driver's maximum] (255 on llvmpipe).
  void SetPointSize(float pixels);
  float point_size() const;

  // Writes the current frame (points and overlay) as a PNG with OpenCV, top row first, at
  // framebuffer size. Re-draws first if the back buffer was swapped since the last Draw.
  absl::Status SaveScreenshot(const std::string& png_path);
  // The current frame as tightly packed RGB bytes, top row first; sets *width and *height (either
  // may be null). Re-draws first if the back buffer was swapped since the last Draw.
  absl::StatusOr<std::vector<std::uint8_t>> ReadPixelsRgb(int* width, int* height);
  // Where the 's' key saves: the first "%d" is replaced by a counter starting at 0 (default
  // "cloudcast-%d.png"; without "%d" every screenshot overwrites the same file).
  void SetScreenshotPath(const std::string& pattern);
  // Path written by the last successful 's' screenshot, and the status of the last attempt, so
  // a program can report it (the renderer itself prints nothing).
  const std::string& last_screenshot_path() const;
  const absl::Status& last_screenshot_status() const;

  int framebuffer_width() const;
  int framebuffer_height() const;

  // The camera for tests: projection * view, column-major (OpenGL's layout: element [c * 4 + r]
  // is row r, column c). Maps a point (x, y, z, 1) in point coordinates to clip space; window
  // pixel x = (ndc.x + 1) / 2 * framebuffer_width, and y from the bottom likewise.
  std::array<float, 16> ViewProjection() const;

 private:
  struct Impl;
  explicit Renderer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace cloudcast::render
