// Small OpenGL helpers shared by the point and overlay passes. Need a current GL context.
#pragma once

#include <epoxy/gl.h>

#include <string>

#include "absl/status/statusor.h"

namespace cloudcast::render::internal {

// Compiles and links a vertex + fragment shader pair. Errors carry the driver's info log, which
// names the failing line, so a broken shader is diagnosable from the Status alone.
absl::StatusOr<GLuint> BuildProgram(const char* name, const char* vertex_source,
                                    const char* fragment_source);

// "GL_INVALID_OPERATION" etc., for error messages.
std::string GlErrorName(GLenum error);

}  // namespace cloudcast::render::internal
