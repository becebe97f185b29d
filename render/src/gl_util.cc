#include "gl_util.h"

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace cloudcast::render::internal {
namespace {

std::string ShaderLog(GLuint shader) {
  GLint length = 0;
  glGetShaderiv(shader, GL_INFO_LOG_LENGTH, &length);
  std::string log(static_cast<std::size_t>(length > 0 ? length : 1), '\0');
  glGetShaderInfoLog(shader, length, nullptr, log.data());
  return std::string(log.c_str());
}

std::string ProgramLog(GLuint program) {
  GLint length = 0;
  glGetProgramiv(program, GL_INFO_LOG_LENGTH, &length);
  std::string log(static_cast<std::size_t>(length > 0 ? length : 1), '\0');
  glGetProgramInfoLog(program, length, nullptr, log.data());
  return std::string(log.c_str());
}

absl::StatusOr<GLuint> Compile(const char* name, GLenum type, const char* source) {
  const GLuint shader = glCreateShader(type);
  glShaderSource(shader, 1, &source, nullptr);
  glCompileShader(shader);
  GLint ok = GL_FALSE;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (ok != GL_TRUE) {
    const std::string log = ShaderLog(shader);
    glDeleteShader(shader);
    return absl::InternalError(
        absl::StrCat(name, (type == GL_VERTEX_SHADER ? " vertex" : " fragment"), " shader: ", log));
  }
  return shader;
}

}  // namespace

absl::StatusOr<GLuint> BuildProgram(const char* name, const char* vertex_source,
                                    const char* fragment_source) {
  absl::StatusOr<GLuint> vs = Compile(name, GL_VERTEX_SHADER, vertex_source);
  if (!vs.ok()) return vs.status();
  absl::StatusOr<GLuint> fs = Compile(name, GL_FRAGMENT_SHADER, fragment_source);
  if (!fs.ok()) {
    glDeleteShader(*vs);
    return fs.status();
  }
  const GLuint program = glCreateProgram();
  glAttachShader(program, *vs);
  glAttachShader(program, *fs);
  glLinkProgram(program);
  // The program keeps what it needs; the shader objects are no longer used.
  glDetachShader(program, *vs);
  glDetachShader(program, *fs);
  glDeleteShader(*vs);
  glDeleteShader(*fs);
  GLint ok = GL_FALSE;
  glGetProgramiv(program, GL_LINK_STATUS, &ok);
  if (ok != GL_TRUE) {
    const std::string log = ProgramLog(program);
    glDeleteProgram(program);
    return absl::InternalError(absl::StrCat(name, " program link: ", log));
  }
  return program;
}

std::string GlErrorName(GLenum error) {
  switch (error) {
    case GL_NO_ERROR:
      return "GL_NO_ERROR";
    case GL_INVALID_ENUM:
      return "GL_INVALID_ENUM";
    case GL_INVALID_VALUE:
      return "GL_INVALID_VALUE";
    case GL_INVALID_OPERATION:
      return "GL_INVALID_OPERATION";
    case GL_INVALID_FRAMEBUFFER_OPERATION:
      return "GL_INVALID_FRAMEBUFFER_OPERATION";
    case GL_OUT_OF_MEMORY:
      return "GL_OUT_OF_MEMORY";
    default:
      return absl::StrCat("GL error 0x", absl::Hex(error));
  }
}

}  // namespace cloudcast::render::internal
