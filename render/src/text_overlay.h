// The status overlay: lines of ASCII text in the built-in 8x8 font, drawn at 2x scale in the
// top-left corner on a translucent dark box. Glyphs come from one GL_R8 atlas texture; the
// quads are rebuilt only when the text changes, into a buffer that only grows.
#pragma once

#include <epoxy/gl.h>

#include <string>
#include <vector>

#include "absl/status/status.h"

namespace cloudcast::render::internal {

class TextOverlay {
 public:
  static constexpr int kScale = 2;    // screen pixels per font pixel
  static constexpr int kMargin = 6;   // from the window's corner to the box, pixels
  static constexpr int kPadding = 4;  // from the box's edge to the text, pixels

  // Needs a current GL 3.3 context; Destroy must run with the same context current.
  absl::Status Init();
  void Destroy();

  void SetText(const std::string& text);
  // Draws over whatever is in the framebuffer (blending on, depth test off for the call).
  void Draw(int framebuffer_width, int framebuffer_height);

  // The box the overlay covers, in window pixels from the top-left; all zero without text.
  struct Box {
    int x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // [x0, x1) x [y0, y1)
  };
  const Box& box() const { return box_; }

 private:
  std::string text_;
  std::vector<float> vertices_;  // x, y (pixels, y down), u, v (atlas texels; u < 0: box)
  Box box_;
  bool dirty_ = false;
  GLuint program_ = 0, vao_ = 0, vbo_ = 0, atlas_ = 0;
  GLsizeiptr vbo_capacity_ = 0;
  GLint viewport_location_ = -1;
};

}  // namespace cloudcast::render::internal
