#include "cloudcast/render/renderer.h"

// epoxy must come before GLFW so GLFW does not pull in the system's <GL/gl.h>.
#include <epoxy/gl.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <mutex>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <utility>

#include "absl/strings/str_cat.h"
#include "gl_util.h"
#include "orbit_camera.h"
#include "text_overlay.h"

namespace cloudcast::render {
namespace {

using internal::OrbitCamera;
using internal::TextOverlay;

// The point pass. Attribute 1 is the colour word as an integer attribute (glVertexAttribIPointer),
// so the shader unpacks PCL's 0xAARRGGBB with shifts and masks; the paper's 2013 shaders lacked
// integer operations and had to smuggle the colour through a float.
constexpr char kPointVertexShader[] = R"(#version 330 core
layout(location = 0) in vec3 position;
layout(location = 1) in uint rgba;
uniform mat4 view_projection;
uniform float point_size;
flat out vec3 point_colour;
void main() {
  gl_PointSize = point_size;
  point_colour = vec3(float((rgba >> 16) & 0xFFu), float((rgba >> 8) & 0xFFu),
                      float(rgba & 0xFFu)) / 255.0;
  // Organized clouds mark holes with NaN. A NaN gl_Position is undefined behaviour, so such
  // points go beyond the far plane, where every implementation discards a point whole.
  if (any(isnan(position)) || any(isinf(position))) {
    gl_Position = vec4(0.0, 0.0, 2.0, 1.0);
    return;
  }
  gl_Position = view_projection * vec4(position, 1.0);
}
)";

constexpr char kPointFragmentShader[] = R"(#version 330 core
flat in vec3 point_colour;
out vec4 colour;
void main() { colour = vec4(point_colour, 1.0); }
)";

constexpr float kPointSizeStep = 1.0f;
constexpr char kDefaultScreenshotPattern[] = "cloudcast-%d.png";

// GLFW is process-wide: initialised by the first Renderer, terminated with the last. Its error
// callback has no user pointer, so the last message is kept here for the Status of Create.
std::mutex glfw_mutex;
int glfw_users = 0;
std::string glfw_last_error;

void OnGlfwError(int code, const char* description) {
  glfw_last_error = absl::StrCat(description, " (GLFW error 0x", absl::Hex(code), ")");
}

std::string TakeGlfwError() {
  std::string e = std::move(glfw_last_error);
  glfw_last_error.clear();
  return e.empty() ? std::string("no details from GLFW") : e;
}

absl::Status AcquireGlfw() {
  std::lock_guard<std::mutex> lock(glfw_mutex);
  if (glfw_users == 0) {
    glfwSetErrorCallback(OnGlfwError);
    if (glfwInit() != GLFW_TRUE) {
      const char* display = std::getenv("DISPLAY");
      return absl::FailedPreconditionError(absl::StrCat(
          "cannot open a display (DISPLAY=", display != nullptr ? display : "<unset>",
          "): ", TakeGlfwError(), "; without a screen run under Xvfb, e.g. xvfb-run -a"));
    }
  }
  ++glfw_users;
  return absl::OkStatus();
}

void ReleaseGlfw() {
  std::lock_guard<std::mutex> lock(glfw_mutex);
  if (--glfw_users == 0) glfwTerminate();
}

}  // namespace

struct Renderer::Impl {
  RendererOptions options;
  GLFWwindow* window = nullptr;
  bool glfw_acquired = false;

  GLuint point_program = 0, point_vao = 0, point_vbo = 0;
  GLint view_projection_location = -1, point_size_location = -1;
  GLsizeiptr vbo_capacity = 0;  // bytes of the buffer's storage
  std::size_t point_count = 0;  // points of the last Upload
  float point_size = 2.0f;
  float max_point_size = 64.0f;

  TextOverlay overlay;
  OrbitCamera camera;
  // What 'r' returns to: the last ResetView's box, or the default view.
  bool have_bounds = false;
  Bounds3 last_bounds{};

  bool paused = false;
  // False after Swap: the back buffer's content is then undefined, so a read-back re-draws.
  bool drawn_since_swap = false;

  // Framebuffer pixels, kept current by GLFW's resize callback: querying GLFW costs an X round
  // trip, and Draw needs the size twice per frame (viewport, aspect).
  int framebuffer_width = 1, framebuffer_height = 1;

  // Mouse drag state.
  bool have_cursor = false;
  double cursor_x = 0, cursor_y = 0;

  std::function<void(int, int, int)> key_handler;

  std::string screenshot_pattern = kDefaultScreenshotPattern;
  int screenshot_counter = 0;
  std::string last_screenshot_path;
  absl::Status last_screenshot_status;

  ~Impl() {
    if (window != nullptr) {
      glfwMakeContextCurrent(window);
      overlay.Destroy();
      if (point_program != 0) glDeleteProgram(point_program);
      if (point_vbo != 0) glDeleteBuffers(1, &point_vbo);
      if (point_vao != 0) glDeleteVertexArrays(1, &point_vao);
      glfwMakeContextCurrent(nullptr);
      glfwDestroyWindow(window);
    }
    if (glfw_acquired) ReleaseGlfw();
  }

  // glfwMakeContextCurrent costs a glXMakeCurrent round trip; skip it when already current.
  void MakeCurrent() const {
    if (glfwGetCurrentContext() != window) glfwMakeContextCurrent(window);
  }

  void FramebufferSize(int* w, int* h) const {
    *w = framebuffer_width;
    *h = framebuffer_height;
  }
  void SetFramebufferSize(int w, int h) {
    framebuffer_width = std::max(w, 1);  // minimised windows report 0
    framebuffer_height = std::max(h, 1);
  }

  float Aspect() const {
    int w, h;
    FramebufferSize(&w, &h);
    return static_cast<float>(w) / static_cast<float>(h);
  }
};

Renderer::Renderer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Renderer::~Renderer() = default;

absl::StatusOr<std::unique_ptr<Renderer>> Renderer::Create(const RendererOptions& options) {
  if (options.width <= 0 || options.height <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("window size must be positive, got ", options.width, "x", options.height));
  }
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  if (absl::Status s = AcquireGlfw(); !s.ok()) return s;
  impl->glfw_acquired = true;

  glfwDefaultWindowHints();
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  glfwWindowHint(GLFW_VISIBLE, options.visible ? GLFW_TRUE : GLFW_FALSE);
  // Exact colours: no multisampling, no sRGB conversion (and no dithering, below), so a point's
  // packed colour is the pixel's colour bit for bit.
  glfwWindowHint(GLFW_SAMPLES, 0);
  glfwWindowHint(GLFW_SRGB_CAPABLE, GLFW_FALSE);
  glfwWindowHint(GLFW_DEPTH_BITS, 24);
  glfwWindowHint(GLFW_DOUBLEBUFFER, GLFW_TRUE);
  impl->window =
      glfwCreateWindow(options.width, options.height, options.title.c_str(), nullptr, nullptr);
  if (impl->window == nullptr) {
    return absl::UnavailableError(
        absl::StrCat("cannot create an OpenGL 3.3 core profile context: ", TakeGlfwError()));
  }
  glfwMakeContextCurrent(impl->window);
  {
    int w = 1, h = 1;
    glfwGetFramebufferSize(impl->window, &w, &h);
    impl->SetFramebufferSize(w, h);
  }
  if (epoxy_gl_version() < 33) {
    return absl::UnavailableError(absl::StrCat("OpenGL 3.3 needed, the context has ",
                                               epoxy_gl_version() / 10, ".",
                                               epoxy_gl_version() % 10));
  }
  glfwSwapInterval(options.vsync ? 1 : 0);

  absl::StatusOr<GLuint> program =
      internal::BuildProgram("point", kPointVertexShader, kPointFragmentShader);
  if (!program.ok()) return program.status();
  impl->point_program = *program;
  impl->view_projection_location = glGetUniformLocation(impl->point_program, "view_projection");
  impl->point_size_location = glGetUniformLocation(impl->point_program, "point_size");

  // One VBO of our 16-byte points as they are: xyz floats at offset 0, the colour word at 12.
  glGenVertexArrays(1, &impl->point_vao);
  glGenBuffers(1, &impl->point_vbo);
  glBindVertexArray(impl->point_vao);
  glBindBuffer(GL_ARRAY_BUFFER, impl->point_vbo);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(Point), nullptr);
  glEnableVertexAttribArray(1);
  glVertexAttribIPointer(1, 1, GL_UNSIGNED_INT, sizeof(Point),
                         reinterpret_cast<const void*>(offsetof(Point, rgba)));
  glBindVertexArray(0);

  if (absl::Status s = impl->overlay.Init(); !s.ok()) return s;

  GLfloat range[2] = {1.0f, 64.0f};
  glGetFloatv(GL_POINT_SIZE_RANGE, range);
  impl->max_point_size = std::max(range[1], 1.0f);
  glEnable(GL_PROGRAM_POINT_SIZE);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDisable(GL_DITHER);
  glDisable(GL_MULTISAMPLE);

  if (const GLenum e = glGetError(); e != GL_NO_ERROR) {
    return absl::InternalError(absl::StrCat("OpenGL setup failed: ", internal::GlErrorName(e)));
  }

  auto renderer = std::unique_ptr<Renderer>(new Renderer(std::move(impl)));
  renderer->SetPointSize(options.point_size);
  GLFWwindow* window = renderer->impl_->window;
  glfwSetWindowUserPointer(window, renderer.get());
  glfwSetCharCallback(window, [](GLFWwindow* w, unsigned int codepoint) {
    static_cast<Renderer*>(glfwGetWindowUserPointer(w))->HandleCharacter(codepoint);
  });
  glfwSetKeyCallback(window, [](GLFWwindow* w, int key, int, int action, int mods) {
    // Esc has no character; everything else goes through the character callback, which also
    // receives the keypad's '+' and '-' and respects the keyboard layout.
    if (key == GLFW_KEY_ESCAPE && action == GLFW_PRESS) glfwSetWindowShouldClose(w, GLFW_TRUE);
    auto* self = static_cast<Renderer*>(glfwGetWindowUserPointer(w));
    if (self->impl_->key_handler) self->impl_->key_handler(key, action, mods);
  });
  glfwSetCursorPosCallback(window, [](GLFWwindow* w, double x, double y) {
    auto* self = static_cast<Renderer*>(glfwGetWindowUserPointer(w));
    Impl& impl = *self->impl_;
    const double dx = x - impl.cursor_x, dy = y - impl.cursor_y;
    const bool had_cursor = impl.have_cursor;
    impl.cursor_x = x;
    impl.cursor_y = y;
    impl.have_cursor = true;
    if (!had_cursor) return;
    if (glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS) {
      self->Orbit(dx, dy);
    } else if (glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS ||
               glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_MIDDLE) == GLFW_PRESS) {
      self->Pan(dx, dy);
    }
  });
  glfwSetFramebufferSizeCallback(window, [](GLFWwindow* w, int width, int height) {
    static_cast<Renderer*>(glfwGetWindowUserPointer(w))->impl_->SetFramebufferSize(width, height);
  });
  glfwSetScrollCallback(window, [](GLFWwindow* w, double, double y_offset) {
    static_cast<Renderer*>(glfwGetWindowUserPointer(w))->Zoom(y_offset);
  });
  return renderer;
}

void Renderer::Upload(const cloudcast::Point* points, std::size_t count) {
  impl_->MakeCurrent();
  const auto bytes = static_cast<GLsizeiptr>(count * sizeof(Point));
  glBindBuffer(GL_ARRAY_BUFFER, impl_->point_vbo);
  if (bytes > impl_->vbo_capacity) {
    // Grow with headroom so a cloud that creeps up in size does not reallocate every frame.
    impl_->vbo_capacity = std::max(bytes, impl_->vbo_capacity + impl_->vbo_capacity / 2);
    glBufferData(GL_ARRAY_BUFFER, impl_->vbo_capacity, nullptr, GL_STREAM_DRAW);
  } else if (bytes > 0) {
    // Orphan: fresh storage of the same size, so the copy below never waits for the GPU to
    // finish drawing the previous cloud from the old storage.
    glBufferData(GL_ARRAY_BUFFER, impl_->vbo_capacity, nullptr, GL_STREAM_DRAW);
  }
  if (bytes > 0) glBufferSubData(GL_ARRAY_BUFFER, 0, bytes, points);
  impl_->point_count = count;
}

std::size_t Renderer::point_count() const { return impl_->point_count; }
std::size_t Renderer::gpu_buffer_bytes() const {
  return static_cast<std::size_t>(impl_->vbo_capacity);
}

void Renderer::SetOverlayText(const std::string& line) { impl_->overlay.SetText(line); }

void Renderer::Draw() {
  Impl& impl = *impl_;
  impl.MakeCurrent();
  int w, h;
  impl.FramebufferSize(&w, &h);
  glViewport(0, 0, w, h);
  const auto& bg = impl.options.background;
  glClearColor(bg[0], bg[1], bg[2], 1.0f);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  if (impl.point_count > 0) {
    const std::array<float, 16> vp = ViewProjection();
    glUseProgram(impl.point_program);
    glUniformMatrix4fv(impl.view_projection_location, 1, GL_FALSE, vp.data());
    glUniform1f(impl.point_size_location, impl.point_size);
    glBindVertexArray(impl.point_vao);
    glDrawArrays(GL_POINTS, 0, static_cast<GLsizei>(impl.point_count));
    glBindVertexArray(0);
  }
  impl.overlay.Draw(w, h);
  impl.drawn_since_swap = true;
}

void Renderer::Swap() {
  impl_->MakeCurrent();
  glfwSwapBuffers(impl_->window);
  impl_->drawn_since_swap = false;
  glfwPollEvents();
}

void Renderer::Finish() {
  impl_->MakeCurrent();
  glFinish();
}

bool Renderer::ShouldClose() const { return glfwWindowShouldClose(impl_->window) == GLFW_TRUE; }

bool Renderer::paused() const { return impl_->paused; }
void Renderer::SetPaused(bool paused) { impl_->paused = paused; }

void Renderer::ResetView(const Bounds3& bounds) {
  impl_->have_bounds = true;
  impl_->last_bounds = bounds;
  impl_->camera.Frame({bounds.min[0], bounds.min[1], bounds.min[2]},
                      {bounds.max[0], bounds.max[1], bounds.max[2]}, impl_->Aspect());
}

void Renderer::ResetViewToCloud(const cloudcast::Point* points, std::size_t count) {
  Bounds3 b;
  for (int i = 0; i < 3; ++i) {
    b.min[i] = std::numeric_limits<float>::infinity();
    b.max[i] = -std::numeric_limits<float>::infinity();
  }
  bool any = false;
  for (std::size_t k = 0; k < count; ++k) {
    const Point& p = points[k];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) continue;
    const float c[3] = {p.x, p.y, p.z};
    for (int i = 0; i < 3; ++i) {
      b.min[i] = std::min(b.min[i], c[i]);
      b.max[i] = std::max(b.max[i], c[i]);
    }
    any = true;
  }
  if (any) {
    ResetView(b);
  } else {
    impl_->have_bounds = false;
    impl_->camera.Reset();
  }
}

void Renderer::Orbit(double dx, double dy) {
  impl_->camera.Orbit(static_cast<float>(dx), static_cast<float>(dy));
}

void Renderer::Pan(double dx, double dy) {
  // Window pixels to framebuffer pixels (they differ on HiDPI screens).
  int fw, fh, ww, wh;
  impl_->FramebufferSize(&fw, &fh);
  glfwGetWindowSize(impl_->window, &ww, &wh);
  const double scale = wh > 0 ? static_cast<double>(fh) / wh : 1.0;
  impl_->camera.Pan(static_cast<float>(dx * scale), static_cast<float>(dy * scale),
                    static_cast<float>(fh));
}

void Renderer::Zoom(double steps) { impl_->camera.Zoom(static_cast<float>(steps)); }

bool Renderer::HandleCharacter(unsigned int codepoint) {
  switch (codepoint) {
    case '+':
    case '=':  // '+' without shift on US layouts
      SetPointSize(impl_->point_size + kPointSizeStep);
      return true;
    case '-':
      SetPointSize(impl_->point_size - kPointSizeStep);
      return true;
    case ' ':
      impl_->paused = !impl_->paused;
      return true;
    case 'r':
    case 'R':
      if (impl_->have_bounds) {
        ResetView(impl_->last_bounds);
      } else {
        impl_->camera.Reset();
      }
      return true;
    case 's':
    case 'S': {
      std::string path = impl_->screenshot_pattern;
      if (const auto at = path.find("%d"); at != std::string::npos) {
        path.replace(at, 2, std::to_string(impl_->screenshot_counter));
      }
      ++impl_->screenshot_counter;
      impl_->last_screenshot_status = SaveScreenshot(path);
      if (impl_->last_screenshot_status.ok()) impl_->last_screenshot_path = path;
      return true;
    }
    case 'q':
    case 'Q':
      glfwSetWindowShouldClose(impl_->window, GLFW_TRUE);
      return true;
    default:
      return false;
  }
}

void Renderer::SetKeyHandler(std::function<void(int key, int action, int mods)> handler) {
  impl_->key_handler = std::move(handler);
}

void Renderer::SetPointSize(float pixels) {
  if (!std::isfinite(pixels)) return;
  impl_->point_size = std::clamp(pixels, 1.0f, impl_->max_point_size);
}

float Renderer::point_size() const { return impl_->point_size; }

absl::StatusOr<std::vector<std::uint8_t>> Renderer::ReadPixelsRgb(int* width, int* height) {
  Impl& impl = *impl_;
  impl.MakeCurrent();
  if (!impl.drawn_since_swap) Draw();
  int w, h;
  impl.FramebufferSize(&w, &h);
  const std::size_t row = static_cast<std::size_t>(w) * 3;
  std::vector<std::uint8_t> bottom_up(row * h);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
  glReadBuffer(GL_BACK);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, w, h, GL_RGB, GL_UNSIGNED_BYTE, bottom_up.data());
  if (const GLenum e = glGetError(); e != GL_NO_ERROR) {
    return absl::InternalError(absl::StrCat("glReadPixels failed: ", internal::GlErrorName(e)));
  }
  // GL's row 0 is the bottom of the window; images start at the top.
  std::vector<std::uint8_t> pixels(bottom_up.size());
  for (int y = 0; y < h; ++y) {
    std::memcpy(pixels.data() + y * row, bottom_up.data() + (h - 1 - y) * row, row);
  }
  if (width != nullptr) *width = w;
  if (height != nullptr) *height = h;
  return pixels;
}

absl::Status Renderer::SaveScreenshot(const std::string& png_path) {
  int w = 0, h = 0;
  absl::StatusOr<std::vector<std::uint8_t>> rgb = ReadPixelsRgb(&w, &h);
  if (!rgb.ok()) return rgb.status();
  // OpenCV writes BGR.
  std::vector<std::uint8_t>& px = *rgb;
  for (std::size_t i = 0; i + 2 < px.size(); i += 3) std::swap(px[i], px[i + 2]);
  const cv::Mat image(h, w, CV_8UC3, px.data());
  try {
    if (!cv::imwrite(png_path, image)) {
      return absl::InternalError(absl::StrCat("cannot write screenshot ", png_path));
    }
  } catch (const cv::Exception& e) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot write screenshot ", png_path, ": ", e.what()));
  }
  return absl::OkStatus();
}

void Renderer::SetScreenshotPath(const std::string& pattern) {
  impl_->screenshot_pattern = pattern;
  impl_->screenshot_counter = 0;
}

const std::string& Renderer::last_screenshot_path() const { return impl_->last_screenshot_path; }
const absl::Status& Renderer::last_screenshot_status() const {
  return impl_->last_screenshot_status;
}

int Renderer::framebuffer_width() const {
  int w, h;
  impl_->FramebufferSize(&w, &h);
  return w;
}

int Renderer::framebuffer_height() const {
  int w, h;
  impl_->FramebufferSize(&w, &h);
  return h;
}

std::array<float, 16> Renderer::ViewProjection() const {
  return impl_->camera.ViewProjection(impl_->Aspect());
}

}  // namespace cloudcast::render
