#include "client/render/opengl/gl_api.h"

#include <absl/strings/str_cat.h>

#include <algorithm>
#include <cstdio>
#include <string>

namespace isostream::render::gl {
namespace {

// Compiled shader objects are only needed until the program links.
struct ShaderTraits {
  static void Delete(GLuint id) { glDeleteShader(id); }
};
using Shader = Object<ShaderTraits>;

absl::StatusOr<Shader> Compile(absl::string_view name, GLenum stage, absl::string_view source) {
  Shader shader(glCreateShader(stage));
  if (!shader) return absl::InternalError(absl::StrCat(name, ": glCreateShader failed"));
  const GLchar* text = source.data();
  const GLint length = GLint(source.size());
  glShaderSource(shader.get(), 1, &text, &length);
  glCompileShader(shader.get());
  GLint ok = GL_FALSE;
  glGetShaderiv(shader.get(), GL_COMPILE_STATUS, &ok);
  if (ok != GL_TRUE) {
    GLint log_length = 0;
    glGetShaderiv(shader.get(), GL_INFO_LOG_LENGTH, &log_length);
    std::string log(size_t(std::max(log_length, 1)), '\0');
    glGetShaderInfoLog(shader.get(), GLsizei(log.size()), nullptr, log.data());
    return absl::InvalidArgumentError(
        absl::StrCat(name, (stage == GL_VERTEX_SHADER ? " vertex" : " fragment"),
                     " shader does not compile: ", log.c_str()));
  }
  return shader;
}

}  // namespace

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
    case GL_STACK_UNDERFLOW:
      return "GL_STACK_UNDERFLOW";
    case GL_STACK_OVERFLOW:
      return "GL_STACK_OVERFLOW";
  }
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "GL error 0x%04x", unsigned(error));
  return buffer;
}

absl::Status CheckGl(absl::string_view where) {
  std::string errors;
  // A lost context or a broken driver may report errors indefinitely; the bound keeps an
  // error check from hanging the caller.
  for (int i = 0; i < 16; ++i) {
    const GLenum error = glGetError();
    if (error == GL_NO_ERROR) break;
    absl::StrAppend(&errors, errors.empty() ? "" : ", ", GlErrorName(error));
  }
  if (errors.empty()) return absl::OkStatus();
  return absl::InternalError(absl::StrCat(where, ": OpenGL reported ", errors));
}

absl::StatusOr<Program> BuildProgram(absl::string_view name, absl::string_view vertex_source,
                                     absl::string_view fragment_source) {
  ISOSTREAM_ASSIGN_OR_RETURN(Shader vertex, Compile(name, GL_VERTEX_SHADER, vertex_source));
  ISOSTREAM_ASSIGN_OR_RETURN(Shader fragment, Compile(name, GL_FRAGMENT_SHADER, fragment_source));
  Program program = Program::Make();
  if (!program) return absl::InternalError(absl::StrCat(name, ": glCreateProgram failed"));
  glAttachShader(program.get(), vertex.get());
  glAttachShader(program.get(), fragment.get());
  glLinkProgram(program.get());
  GLint ok = GL_FALSE;
  glGetProgramiv(program.get(), GL_LINK_STATUS, &ok);
  if (ok != GL_TRUE) {
    GLint log_length = 0;
    glGetProgramiv(program.get(), GL_INFO_LOG_LENGTH, &log_length);
    std::string log(size_t(std::max(log_length, 1)), '\0');
    glGetProgramInfoLog(program.get(), GLsizei(log.size()), nullptr, log.data());
    return absl::InvalidArgumentError(absl::StrCat(name, " program does not link: ", log.c_str()));
  }
  glDetachShader(program.get(), vertex.get());
  glDetachShader(program.get(), fragment.get());
  ISOSTREAM_RETURN_IF_ERROR(CheckGl(name));
  return program;
}

}  // namespace isostream::render::gl
