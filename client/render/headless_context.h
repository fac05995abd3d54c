// An OpenGL 3.3 core context with no window and no X server, rendering into an offscreen
// framebuffer. On Debian this runs on Mesa (llvmpipe without a GPU); EGL and GL types stay in
// client/render/opengl/, so callers see only this class.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "client/render/image.h"
#include "shared/status.h"

namespace isostream::render {

enum class EglPlatform {
  kAuto,         // Mesa's surfaceless platform, then the first usable EGL device
  kSurfaceless,  // EGL_MESA_platform_surfaceless only
  kDevice,       // EGL_EXT_platform_device only (GPU drivers without Mesa)
};

inline constexpr int64_t kMaxSamplesInAll = int64_t{1} << 28;  // 1 GiB of RGBA8 samples

struct HeadlessContextOptions {
  int width = 512;  // framebuffer size in pixels, 1..16384 (and at most the GL's limit)
  int height = 512;
  // The renderer relies on draw order, not depth, so a depth buffer is only for callers that
  // draw opaque geometry of their own.
  bool depth_buffer = false;
  // Multisample anti-aliasing: samples per pixel (1: none). Fewer where the GL offers fewer, and
  // halved until all the samples (depth's too) fit kMaxSamplesInAll (a 16384^2 picture at 4
  // would take 4 GiB: it gets 1).
  int samples = 1;
  EglPlatform platform = EglPlatform::kAuto;
  int device_index = -1;  // kDevice / kAuto: which EGL device; -1 tries each in turn
};

// Owns the EGL display connection's context and the framebuffer object every draw goes to.
// After Create the context is current on the calling thread and the framebuffer is bound with
// the viewport covering it. GL state is per thread: use the object from one thread, or call
// MakeCurrent first. GL objects made by others (a MeshRenderer) must be destroyed before it.
class HeadlessContext {
 public:
  // Unavailable, with a message naming each platform tried and why it failed, when no EGL
  // display or device gives a GL 3.3 core context; InvalidArgument for a bad size.
  static absl::StatusOr<std::unique_ptr<HeadlessContext>> Create(
      const HeadlessContextOptions& options);
  ~HeadlessContext();
  HeadlessContext(const HeadlessContext&) = delete;
  HeadlessContext& operator=(const HeadlessContext&) = delete;

  int width() const;
  int height() const;
  // "Mesa/X.org llvmpipe (LLVM 15.0.6, 256 bits)" and the like: what is actually drawing.
  const std::string& renderer_name() const;
  // "surfaceless" or "device N": which EGL platform the context came from.
  const std::string& platform_name() const;

  // Makes the context current on this thread and binds the framebuffer and viewport.
  absl::Status MakeCurrent();
  // Replaces the framebuffer's storage; contents become undefined.
  absl::Status Resize(int width, int height);
  // Blocks until every command issued so far has finished (for timing).
  absl::Status Finish();
  // The framebuffer's colour, top row first. Waits for pending draws.
  absl::StatusOr<Image> ReadPixels();

  struct Impl;

 private:
  explicit HeadlessContext(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace isostream::render
