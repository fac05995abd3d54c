// HeadlessContext on EGL. Display choice follows what works on Debian's Mesa without X: the
// surfaceless platform first, then EGL devices (which is also how NVIDIA's headless EGL is
// reached). eglGetDisplay(EGL_DEFAULT_DISPLAY) is never used: it probes X11 and fails there.
#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <absl/strings/str_cat.h>
#include <absl/strings/str_split.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <vector>

#include "client/render/headless_context.h"
#include "client/render/opengl/egl_names.h"
#include "client/render/opengl/gl_api.h"

namespace isostream::render {
namespace egl {

std::string EglErrorName(int code) {
  switch (code) {
    case EGL_SUCCESS:
      return "EGL_SUCCESS";
    case EGL_NOT_INITIALIZED:
      return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ACCESS:
      return "EGL_BAD_ACCESS";
    case EGL_BAD_ALLOC:
      return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE:
      return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONFIG:
      return "EGL_BAD_CONFIG";
    case EGL_BAD_CONTEXT:
      return "EGL_BAD_CONTEXT";
    case EGL_BAD_CURRENT_SURFACE:
      return "EGL_BAD_CURRENT_SURFACE";
    case EGL_BAD_DISPLAY:
      return "EGL_BAD_DISPLAY";
    case EGL_BAD_MATCH:
      return "EGL_BAD_MATCH";
    case EGL_BAD_NATIVE_PIXMAP:
      return "EGL_BAD_NATIVE_PIXMAP";
    case EGL_BAD_NATIVE_WINDOW:
      return "EGL_BAD_NATIVE_WINDOW";
    case EGL_BAD_PARAMETER:
      return "EGL_BAD_PARAMETER";
    case EGL_BAD_SURFACE:
      return "EGL_BAD_SURFACE";
    case EGL_CONTEXT_LOST:
      return "EGL_CONTEXT_LOST";
  }
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "EGL error 0x%04x", unsigned(code));
  return buffer;
}

}  // namespace egl

namespace {

constexpr int kMaxFramebufferSide = 16384;

std::string LastEglError() { return egl::EglErrorName(eglGetError()); }

bool HasExtension(const char* list, const char* name) {
  if (list == nullptr) return false;
  for (absl::string_view token : absl::StrSplit(list, ' ', absl::SkipEmpty())) {
    if (token == name) return true;
  }
  return false;
}

absl::Status CheckSize(int width, int height) {
  if (width < 1 || height < 1 || width > kMaxFramebufferSide || height > kMaxFramebufferSide) {
    return absl::InvalidArgumentError(absl::StrCat("framebuffer size ", width, "x", height,
                                                   " is outside 1..", kMaxFramebufferSide));
  }
  return absl::OkStatus();
}

// A display that initialised and gave a current GL 3.3 core context.
struct Opened {
  EGLDisplay display = EGL_NO_DISPLAY;
  EGLContext context = EGL_NO_CONTEXT;
};

absl::StatusOr<Opened> OpenContextOn(EGLDisplay display) {
  if (display == EGL_NO_DISPLAY) {
    return absl::UnavailableError(absl::StrCat("eglGetPlatformDisplay: ", LastEglError()));
  }
  EGLint major = 0, minor = 0;
  if (!eglInitialize(display, &major, &minor)) {
    return absl::UnavailableError(absl::StrCat("eglInitialize: ", LastEglError()));
  }
  if (!eglBindAPI(EGL_OPENGL_API)) {
    return absl::UnavailableError(absl::StrCat("eglBindAPI(EGL_OPENGL_API): ", LastEglError()));
  }
  // The config only matters for EGL's bookkeeping: drawing goes to our framebuffer object. A
  // pbuffer-capable RGBA8 config is what Mesa offers on every platform; any GL config will do
  // if it does not.
  const EGLint wanted[] = {EGL_SURFACE_TYPE,
                           EGL_PBUFFER_BIT,
                           EGL_RENDERABLE_TYPE,
                           EGL_OPENGL_BIT,
                           EGL_RED_SIZE,
                           8,
                           EGL_GREEN_SIZE,
                           8,
                           EGL_BLUE_SIZE,
                           8,
                           EGL_NONE};
  const EGLint any_gl[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_NONE};
  EGLConfig config = nullptr;
  EGLint count = 0;
  if (!eglChooseConfig(display, wanted, &config, 1, &count) || count < 1) {
    if (!eglChooseConfig(display, any_gl, &config, 1, &count) || count < 1) {
      return absl::UnavailableError(
          absl::StrCat("no EGL config renders OpenGL (", LastEglError(), ")"));
    }
  }
  const EGLint context_attributes[] = {EGL_CONTEXT_MAJOR_VERSION,
                                       3,
                                       EGL_CONTEXT_MINOR_VERSION,
                                       3,
                                       EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                       EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                                       EGL_NONE};
  EGLContext context = eglCreateContext(display, config, EGL_NO_CONTEXT, context_attributes);
  if (context == EGL_NO_CONTEXT) {
    return absl::UnavailableError(
        absl::StrCat("eglCreateContext (OpenGL 3.3 core): ", LastEglError()));
  }
  if (!eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, context)) {
    const std::string error = LastEglError();
    eglDestroyContext(display, context);
    return absl::UnavailableError(absl::StrCat(
        "eglMakeCurrent without a surface (needs EGL_KHR_surfaceless_context): ", error));
  }
  GLint gl_major = 0, gl_minor = 0;
  glGetIntegerv(GL_MAJOR_VERSION, &gl_major);
  glGetIntegerv(GL_MINOR_VERSION, &gl_minor);
  if (gl_major * 10 + gl_minor < 33) {
    eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    eglDestroyContext(display, context);
    return absl::UnavailableError(
        absl::StrCat("context reports OpenGL ", gl_major, ".", gl_minor, ", need 3.3"));
  }
  return Opened{display, context};
}

absl::StatusOr<Opened> OpenSurfaceless(const char* client_extensions) {
  if (!HasExtension(client_extensions, "EGL_MESA_platform_surfaceless")) {
    return absl::UnavailableError("EGL_MESA_platform_surfaceless not offered");
  }
  return OpenContextOn(
      eglGetPlatformDisplay(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr));
}

absl::StatusOr<Opened> OpenDevice(const char* client_extensions, int device_index,
                                  std::string* platform_name) {
  if (!HasExtension(client_extensions, "EGL_EXT_platform_device")) {
    return absl::UnavailableError("EGL_EXT_platform_device not offered");
  }
  auto query_devices =
      reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
  if (query_devices == nullptr) {
    return absl::UnavailableError("eglQueryDevicesEXT missing");
  }
  EGLint count = 0;
  if (!query_devices(0, nullptr, &count)) {
    return absl::UnavailableError(absl::StrCat("eglQueryDevicesEXT: ", LastEglError()));
  }
  std::vector<EGLDeviceEXT> devices(size_t(std::max(count, 0)));
  if (count > 0 && !query_devices(count, devices.data(), &count)) {
    return absl::UnavailableError(absl::StrCat("eglQueryDevicesEXT: ", LastEglError()));
  }
  devices.resize(size_t(std::max(count, 0)));
  if (devices.empty()) return absl::UnavailableError("no EGL devices");
  if (device_index >= int(devices.size())) {
    return absl::UnavailableError(absl::StrCat("EGL device ", device_index, " requested but only ",
                                               devices.size(), " found (0..", devices.size() - 1,
                                               ")"));
  }
  std::string reasons;
  for (int i = 0; i < int(devices.size()); ++i) {
    if (device_index >= 0 && i != device_index) continue;
    absl::StatusOr<Opened> opened =
        OpenContextOn(eglGetPlatformDisplay(EGL_PLATFORM_DEVICE_EXT, devices[size_t(i)], nullptr));
    if (opened.ok()) {
      *platform_name = absl::StrCat("device ", i);
      return opened;
    }
    absl::StrAppend(&reasons, reasons.empty() ? "" : "; ", "device ", i, ": ",
                    opened.status().message());
  }
  return absl::UnavailableError(reasons);
}

}  // namespace

struct HeadlessContext::Impl {
  EGLDisplay display = EGL_NO_DISPLAY;
  EGLContext context = EGL_NO_CONTEXT;
  gl::Framebuffer framebuffer;  // what every draw goes to: multisampled when samples > 1
  gl::Renderbuffer color;
  gl::Renderbuffer depth;
  gl::Framebuffer resolved;  // samples > 1: the picture the samples resolve into, to be read
  gl::Renderbuffer resolved_color;
  int width = 0;
  int height = 0;
  bool with_depth = false;
  int asked_samples = 1;
  int samples = 1;  // in use for the current size
  std::string renderer_name;
  std::string platform_name;

  ~Impl() {
    if (context == EGL_NO_CONTEXT) return;
    // GL names belong to this context: delete them while it is current, then let go of it.
    // The display is not terminated: EGL displays are per process, and terminating would pull
    // the display from under any other HeadlessContext still alive.
    eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, context);
    framebuffer.reset();
    color.reset();
    depth.reset();
    resolved.reset();
    resolved_color.reset();
    eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    eglDestroyContext(display, context);
  }

  void Bind() {
    glBindFramebuffer(GL_FRAMEBUFFER, framebuffer.get());
    glViewport(0, 0, width, height);
  }

  absl::Status AllocateStorage(int w, int h) {
    GLint max_renderbuffer = 0;
    glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &max_renderbuffer);
    if (w > max_renderbuffer || h > max_renderbuffer) {
      return absl::InvalidArgumentError(absl::StrCat(
          "framebuffer size ", w, "x", h, " exceeds this GL's limit of ", max_renderbuffer));
    }
    GLint max_samples = 1;
    glGetIntegerv(GL_MAX_SAMPLES, &max_samples);
    // The most samples, up to those asked, that the GL offers and kMaxSamplesInAll holds (the
    // depth buffer's too): halving them until they fit.
    const int64_t buffers = with_depth ? 2 : 1;
    samples = std::max(1, std::min(asked_samples, int(max_samples)));
    while (samples > 1 && int64_t{w} * h * samples * buffers > kMaxSamplesInAll) samples /= 2;
    // Storage of `format` for `buffer`, multisampled when samples > 1.
    auto store = [&](const gl::Renderbuffer& buffer, GLenum format, int count) {
      glBindRenderbuffer(GL_RENDERBUFFER, buffer.get());
      if (count > 1)
        glRenderbufferStorageMultisample(GL_RENDERBUFFER, count, format, w, h);
      else
        glRenderbufferStorage(GL_RENDERBUFFER, format, w, h);
    };
    auto complete = [](const char* which) {
      const GLenum status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
      if (status == GL_FRAMEBUFFER_COMPLETE) return absl::OkStatus();
      return absl::InternalError(absl::StrCat(
          "offscreen ", which, " framebuffer incomplete (status 0x", absl::Hex(status), ")"));
    };
    if (!framebuffer) framebuffer = gl::Framebuffer::Make();
    if (!color) color = gl::Renderbuffer::Make();
    glBindFramebuffer(GL_FRAMEBUFFER, framebuffer.get());
    store(color, GL_RGBA8, samples);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, color.get());
    if (with_depth) {
      if (!depth) depth = gl::Renderbuffer::Make();
      store(depth, GL_DEPTH_COMPONENT24, samples);
      glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth.get());
    }
    ISOSTREAM_RETURN_IF_ERROR(complete("drawing"));
    if (samples == 1) {  // a resize past the cap: the resolving buffers are not needed now
      resolved.reset();
      resolved_color.reset();
    } else {
      if (!resolved) resolved = gl::Framebuffer::Make();
      if (!resolved_color) resolved_color = gl::Renderbuffer::Make();
      glBindFramebuffer(GL_FRAMEBUFFER, resolved.get());
      store(resolved_color, GL_RGBA8, 1);
      glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER,
                                resolved_color.get());
      ISOSTREAM_RETURN_IF_ERROR(complete("resolving"));
    }
    glBindRenderbuffer(GL_RENDERBUFFER, 0);
    width = w;
    height = h;
    Bind();
    return gl::CheckGl("HeadlessContext framebuffer");
  }
};

HeadlessContext::HeadlessContext(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
HeadlessContext::~HeadlessContext() = default;

absl::StatusOr<std::unique_ptr<HeadlessContext>> HeadlessContext::Create(
    const HeadlessContextOptions& options) {
  ISOSTREAM_RETURN_IF_ERROR(CheckSize(options.width, options.height));
  const char* client_extensions = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
  auto impl = std::make_unique<Impl>();
  impl->with_depth = options.depth_buffer;
  impl->asked_samples = options.samples;

  std::string reasons;
  absl::StatusOr<Opened> opened = absl::UnavailableError("no platform tried");
  if (options.platform != EglPlatform::kDevice && options.device_index < 0) {
    opened = OpenSurfaceless(client_extensions);
    if (opened.ok()) impl->platform_name = "surfaceless";
    if (!opened.ok()) absl::StrAppend(&reasons, "surfaceless: ", opened.status().message());
  }
  if (!opened.ok() && options.platform != EglPlatform::kSurfaceless) {
    opened = OpenDevice(client_extensions, options.device_index, &impl->platform_name);
    if (!opened.ok()) {
      absl::StrAppend(&reasons, reasons.empty() ? "" : "; ",
                      "device platform: ", opened.status().message());
    }
  }
  if (!opened.ok()) {
    return absl::UnavailableError(absl::StrCat(
        "no headless OpenGL 3.3 core context (", reasons,
        "). With Mesa, install libegl-mesa0 and libgl1-mesa-dri; with a GPU, its EGL driver."));
  }
  impl->display = opened->display;
  impl->context = opened->context;
  const GLubyte* renderer = glGetString(GL_RENDERER);
  impl->renderer_name = renderer ? reinterpret_cast<const char*>(renderer) : "unknown";
  ISOSTREAM_RETURN_IF_ERROR(impl->AllocateStorage(options.width, options.height));
  return std::unique_ptr<HeadlessContext>(new HeadlessContext(std::move(impl)));
}

int HeadlessContext::width() const { return impl_->width; }
int HeadlessContext::height() const { return impl_->height; }
const std::string& HeadlessContext::renderer_name() const { return impl_->renderer_name; }
const std::string& HeadlessContext::platform_name() const { return impl_->platform_name; }

absl::Status HeadlessContext::MakeCurrent() {
  if (!eglMakeCurrent(impl_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, impl_->context)) {
    return absl::InternalError(absl::StrCat("eglMakeCurrent: ", LastEglError()));
  }
  impl_->Bind();
  return gl::CheckGl("HeadlessContext::MakeCurrent");
}

absl::Status HeadlessContext::Resize(int width, int height) {
  ISOSTREAM_RETURN_IF_ERROR(CheckSize(width, height));
  return impl_->AllocateStorage(width, height);
}

absl::Status HeadlessContext::Finish() {
  glFinish();
  return gl::CheckGl("HeadlessContext::Finish");
}

absl::StatusOr<Image> HeadlessContext::ReadPixels() {
  Image image;
  image.width = impl_->width;
  image.height = impl_->height;
  image.rgba.resize(4 * size_t(image.width) * size_t(image.height));
  if (impl_->samples > 1) {  // each pixel's samples averaged into the picture read below
    glBindFramebuffer(GL_READ_FRAMEBUFFER, impl_->framebuffer.get());
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, impl_->resolved.get());
    glBlitFramebuffer(0, 0, image.width, image.height, 0, 0, image.width, image.height,
                      GL_COLOR_BUFFER_BIT, GL_NEAREST);
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, impl_->framebuffer.get());
    glBindFramebuffer(GL_READ_FRAMEBUFFER, impl_->resolved.get());
  } else {
    glBindFramebuffer(GL_READ_FRAMEBUFFER, impl_->framebuffer.get());
  }
  glReadBuffer(GL_COLOR_ATTACHMENT0);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, image.width, image.height, GL_RGBA, GL_UNSIGNED_BYTE, image.rgba.data());
  impl_->Bind();  // reads and draws go to the drawing framebuffer again, as after Create
  ISOSTREAM_RETURN_IF_ERROR(gl::CheckGl("HeadlessContext::ReadPixels"));
  // GL's rows start at the bottom; images start at the top.
  const size_t row = 4 * size_t(image.width);
  std::vector<uint8_t> swap(row);
  for (int y = 0; y < image.height / 2; ++y) {
    uint8_t* a = image.rgba.data() + row * size_t(y);
    uint8_t* b = image.rgba.data() + row * size_t(image.height - 1 - y);
    std::memcpy(swap.data(), a, row);
    std::memcpy(a, b, row);
    std::memcpy(b, swap.data(), row);
  }
  return image;
}

}  // namespace isostream::render
