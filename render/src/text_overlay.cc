#include "text_overlay.h"

#include <algorithm>
#include <cstdint>
#include <vector>

#include "font8x8.h"
#include "gl_util.h"

namespace cloudcast::render::internal {
namespace {

constexpr int kAtlasColumns = 16;  // glyphs per atlas row
constexpr int kAtlasRows = (kGlyphCount + kAtlasColumns - 1) / kAtlasColumns;
constexpr int kAtlasWidth = kAtlasColumns * kGlyphSize;
constexpr int kAtlasHeight = kAtlasRows * kGlyphSize;

// Vertices arrive in window pixels with y down, so the CPU never needs the framebuffer size.
constexpr char kVertexShader[] = R"(#version 330 core
layout(location = 0) in vec2 pixel;
layout(location = 1) in vec2 texel;
uniform vec2 viewport;
out vec2 atlas_texel;
void main() {
  gl_Position = vec4(pixel.x / viewport.x * 2.0 - 1.0, 1.0 - pixel.y / viewport.y * 2.0, 0.0, 1.0);
  atlas_texel = texel;
}
)";

// texelFetch with the interpolated texel position: at an integer scale every screen pixel maps
// to exactly one font pixel, with no filtering blur at glyph edges.
constexpr char kFragmentShader[] = R"(#version 330 core
in vec2 atlas_texel;
uniform sampler2D atlas;
out vec4 colour;
void main() {
  if (atlas_texel.x < 0.0) {
    colour = vec4(0.0, 0.0, 0.0, 0.65);
    return;
  }
  if (texelFetch(atlas, ivec2(atlas_texel), 0).r < 0.5) discard;
  colour = vec4(0.95, 0.95, 0.95, 1.0);
}
)";

void PushQuad(std::vector<float>& v, float x0, float y0, float x1, float y1, float u0, float v0,
              float u1, float v1) {
  const float quad[6][4] = {{x0, y0, u0, v0}, {x1, y0, u1, v0}, {x1, y1, u1, v1},
                            {x0, y0, u0, v0}, {x1, y1, u1, v1}, {x0, y1, u0, v1}};
  for (const auto& vertex : quad) v.insert(v.end(), vertex, vertex + 4);
}

}  // namespace

absl::Status TextOverlay::Init() {
  absl::StatusOr<GLuint> program = BuildProgram("overlay", kVertexShader, kFragmentShader);
  if (!program.ok()) return program.status();
  program_ = *program;
  viewport_location_ = glGetUniformLocation(program_, "viewport");
  glUseProgram(program_);
  glUniform1i(glGetUniformLocation(program_, "atlas"), 0);

  // Atlas row y holds font row y (top first): texelFetch addresses rows directly, so GL's
  // bottom-up texture convention never comes into play.
  std::vector<std::uint8_t> atlas(std::size_t{kAtlasWidth} * kAtlasHeight, 0);
  for (int g = 0; g < kGlyphCount; ++g) {
    const int gx = (g % kAtlasColumns) * kGlyphSize, gy = (g / kAtlasColumns) * kGlyphSize;
    for (int row = 0; row < kGlyphSize; ++row) {
      for (int col = 0; col < kGlyphSize; ++col) {
        if (kFont8x8[g][row] & (1u << col)) atlas[(gy + row) * kAtlasWidth + gx + col] = 255;
      }
    }
  }
  glGenTextures(1, &atlas_);
  glBindTexture(GL_TEXTURE_2D, atlas_);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glTexImage2D(GL_TEXTURE_2D, 0, GL_R8, kAtlasWidth, kAtlasHeight, 0, GL_RED, GL_UNSIGNED_BYTE,
               atlas.data());
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAX_LEVEL, 0);

  glGenVertexArrays(1, &vao_);
  glGenBuffers(1, &vbo_);
  glBindVertexArray(vao_);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 2, GL_FLOAT, GL_FALSE, 4 * sizeof(float), nullptr);
  glEnableVertexAttribArray(1);
  glVertexAttribPointer(1, 2, GL_FLOAT, GL_FALSE, 4 * sizeof(float),
                        reinterpret_cast<const void*>(2 * sizeof(float)));
  glBindVertexArray(0);
  return absl::OkStatus();
}

void TextOverlay::Destroy() {
  if (program_ != 0) glDeleteProgram(program_);
  if (vbo_ != 0) glDeleteBuffers(1, &vbo_);
  if (vao_ != 0) glDeleteVertexArrays(1, &vao_);
  if (atlas_ != 0) glDeleteTextures(1, &atlas_);
  program_ = vbo_ = vao_ = atlas_ = 0;
  vbo_capacity_ = 0;
}

void TextOverlay::SetText(const std::string& text) {
  if (text == text_) return;  // the overlay is set every frame, but changes far less often
  text_ = text;
  vertices_.clear();
  box_ = Box{};
  if (text_.empty()) {
    dirty_ = true;
    return;
  }
  constexpr int kCell = kGlyphSize * kScale;
  const int x_text = kMargin + kPadding, y_text = kMargin + kPadding;
  int line = 0, column = 0, widest = 0;
  std::vector<float> glyphs;
  for (const char ch : text_) {
    if (ch == '\n') {
      ++line;
      column = 0;
      continue;
    }
    const int code = static_cast<unsigned char>(ch);
    const int glyph = (code >= kFirstGlyph && code <= kLastGlyph ? code : '?') - kFirstGlyph;
    if (glyph != 0) {  // a space has no ink: no quad
      const float x0 = static_cast<float>(x_text + column * kCell);
      const float y0 = static_cast<float>(y_text + line * kCell);
      const int atlas_x = (glyph % kAtlasColumns) * kGlyphSize;
      const int atlas_y = (glyph / kAtlasColumns) * kGlyphSize;  // whole atlas rows
      const auto u0 = static_cast<float>(atlas_x), v0 = static_cast<float>(atlas_y);
      PushQuad(glyphs, x0, y0, x0 + kCell, y0 + kCell, u0, v0, u0 + kGlyphSize, v0 + kGlyphSize);
    }
    ++column;
    widest = std::max(widest, column);
  }
  box_ = Box{kMargin, kMargin, x_text + widest * kCell + kPadding,
             y_text + (line + 1) * kCell + kPadding};
  // The box first, so the glyphs blend over it.
  PushQuad(vertices_, static_cast<float>(box_.x0), static_cast<float>(box_.y0),
           static_cast<float>(box_.x1), static_cast<float>(box_.y1), -1, -1, -1, -1);
  vertices_.insert(vertices_.end(), glyphs.begin(), glyphs.end());
  dirty_ = true;
}

void TextOverlay::Draw(int framebuffer_width, int framebuffer_height) {
  if (dirty_) {
    const auto bytes = static_cast<GLsizeiptr>(vertices_.size() * sizeof(float));
    glBindBuffer(GL_ARRAY_BUFFER, vbo_);
    if (bytes > vbo_capacity_) {
      vbo_capacity_ = std::max(bytes, vbo_capacity_ * 2);
      glBufferData(GL_ARRAY_BUFFER, vbo_capacity_, nullptr, GL_DYNAMIC_DRAW);
    }
    if (bytes > 0) glBufferSubData(GL_ARRAY_BUFFER, 0, bytes, vertices_.data());
    dirty_ = false;
  }
  if (vertices_.empty()) return;
  glDisable(GL_DEPTH_TEST);
  glEnable(GL_BLEND);
  glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
  glUseProgram(program_);
  glUniform2f(viewport_location_, static_cast<float>(framebuffer_width),
              static_cast<float>(framebuffer_height));
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, atlas_);
  glBindVertexArray(vao_);
  glDrawArrays(GL_TRIANGLES, 0, static_cast<GLsizei>(vertices_.size() / 4));
  glBindVertexArray(0);
  glDisable(GL_BLEND);
  glEnable(GL_DEPTH_TEST);
}

}  // namespace cloudcast::render::internal
