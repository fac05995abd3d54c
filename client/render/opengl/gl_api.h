// The one place that includes the OpenGL headers. Entry points are linked directly from GLVND's
// libOpenGL, which dispatches to whichever vendor owns the current EGL context, so there is no
// loader to initialise and no function pointer that can be left null.
#pragma once

#ifndef GL_GLEXT_PROTOTYPES
#define GL_GLEXT_PROTOTYPES 1
#endif
#include <GL/glcorearb.h>
#include <absl/strings/string_view.h>

#include <string>
#include <utility>

#include "shared/status.h"

namespace isostream::render::gl {

// "GL_INVALID_OPERATION" etc., or "GL error 0x...." for codes this file does not know.
std::string GlErrorName(GLenum error);

// Drains glGetError. OK when there was none; otherwise Internal naming every pending error and
// `where` (the public entry point that was running), so a failure is attributed to a call.
absl::Status CheckGl(absl::string_view where);

// Owner of one GL object name. Deleting needs the owning context current, which the public
// classes guarantee by their destruction order (see HeadlessContext).
template <typename Traits>
class Object {
 public:
  Object() = default;
  explicit Object(GLuint id) : id_(id) {}
  ~Object() { reset(); }
  Object(Object&& other) noexcept : id_(std::exchange(other.id_, 0)) {}
  Object& operator=(Object&& other) noexcept {
    if (this != &other) {
      reset();
      id_ = std::exchange(other.id_, 0);
    }
    return *this;
  }
  Object(const Object&) = delete;
  Object& operator=(const Object&) = delete;

  GLuint get() const { return id_; }
  explicit operator bool() const { return id_ != 0; }
  void reset() {
    if (id_ != 0) Traits::Delete(id_);
    id_ = 0;
  }

  static Object Make() { return Object(Traits::Create()); }

 private:
  GLuint id_ = 0;
};

struct BufferTraits {
  static GLuint Create() {
    GLuint id = 0;
    glGenBuffers(1, &id);
    return id;
  }
  static void Delete(GLuint id) { glDeleteBuffers(1, &id); }
};
struct VertexArrayTraits {
  static GLuint Create() {
    GLuint id = 0;
    glGenVertexArrays(1, &id);
    return id;
  }
  static void Delete(GLuint id) { glDeleteVertexArrays(1, &id); }
};
struct TextureTraits {
  static GLuint Create() {
    GLuint id = 0;
    glGenTextures(1, &id);
    return id;
  }
  static void Delete(GLuint id) { glDeleteTextures(1, &id); }
};
struct FramebufferTraits {
  static GLuint Create() {
    GLuint id = 0;
    glGenFramebuffers(1, &id);
    return id;
  }
  static void Delete(GLuint id) { glDeleteFramebuffers(1, &id); }
};
struct RenderbufferTraits {
  static GLuint Create() {
    GLuint id = 0;
    glGenRenderbuffers(1, &id);
    return id;
  }
  static void Delete(GLuint id) { glDeleteRenderbuffers(1, &id); }
};
struct ProgramTraits {
  static GLuint Create() { return glCreateProgram(); }
  static void Delete(GLuint id) { glDeleteProgram(id); }
};

using Buffer = Object<BufferTraits>;
using VertexArray = Object<VertexArrayTraits>;
using Texture = Object<TextureTraits>;
using Framebuffer = Object<FramebufferTraits>;
using Renderbuffer = Object<RenderbufferTraits>;
using Program = Object<ProgramTraits>;

// Compiles and links a vertex and a fragment shader. InvalidArgument with the driver's log
// (prefixed with `name`) when either fails to compile or the program fails to link.
absl::StatusOr<Program> BuildProgram(absl::string_view name, absl::string_view vertex_source,
                                     absl::string_view fragment_source);

}  // namespace isostream::render::gl
