// Draws OrderedMesh frames the way the server sends them: as chunks whose triangles are already
// in back-to-front order, blended in arrival order with no depth test and no sorting here
// (Gerstner §3: the order comes from the extraction, the client only blends).
//
// Shading, per fragment, with everything in world space (the Embree reference in
// tests/render/ evaluates the same formula):
//   n  = normalize(interpolated vertex normal); a zero normal falls back to the facet normal
//   v  = unit vector to the eye (perspective) or -Camera::Forward() (orthographic)
//   n  = -n if dot(n, v) < 0                          (two-sided: face the viewer)
//   l  = normalize(light.direction_in_eye expressed in the camera's right/true-up/backward frame)
//   h  = normalize(l + v)
//   rgb = min(1, colour * (ambient + diffuse * max(dot(n, l), 0))
//             + specular * max(dot(n, h), 0)^shininess)
//   alpha = surface opacity
// composited as colour = alpha * rgb + (1 - alpha) * framebuffer.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>
#include <memory>

#include "client/render/camera.h"
#include "shared/ordered_mesh.h"
#include "shared/status.h"

namespace isostream::render {

struct SurfaceStyle {
  glm::vec3 color{1.0f};  // linear RGB in [0, 1]
  float opacity = 1.0f;   // in [0, 1]
};

using Palette = std::array<SurfaceStyle, kMaxSurfaces>;

// kDefaultSurfaceRgba (shared/surface_palette.h).
Palette DefaultPalette();

// A headlight: fixed to the camera so that the lit side is always the one being looked at.
struct Lighting {
  // In the eye frame: +x right, +y up, +z back towards the viewer. Non-zero; normalised when
  // used.
  glm::vec3 direction_in_eye{-0.3f, 0.4f, 1.0f};
  float ambient = 0.25f;
  float diffuse = 0.75f;
  float specular = 0.25f;
  float shininess = 32.0f;  // > 0
};

// The world-space unit light vector `l` of the shading formula for `camera`.
glm::vec3 LightDirectionInWorld(const Lighting& lighting, const Camera& camera);

// White by default: the surfaces are shaded only darker than their colour except for the
// highlight, so on white every transparent layer, however faint, shows as a tint, as in print.
inline constexpr glm::vec4 kDefaultBackground{1.0f, 1.0f, 1.0f, 1.0f};

// Owns the GL buffers of two frames: the current one (what Render draws) and the pending one
// being received. A frame is replaced whole: BeginFrame starts a pending frame, AddChunk appends
// to it, EndFrame makes it current and frees the old one, so a viewer keeps showing the last
// complete frame while the next arrives chunk by chunk.
//
// Every method needs the GL context the renderer was created in to be current and must run on
// that context's thread; destroy the renderer before the context.
class MeshRenderer {
 public:
  // Compiles the embedded shaders. InvalidArgument (with the driver's log) if they do not build.
  static absl::StatusOr<std::unique_ptr<MeshRenderer>> Create();
  ~MeshRenderer();
  MeshRenderer(const MeshRenderer&) = delete;
  MeshRenderer& operator=(const MeshRenderer&) = delete;

  // Starts a new pending frame, dropping any pending frame that was never ended.
  void BeginFrame();

  // Uploads a chunk to the pending frame; chunks are drawn in the order they were added and
  // triangles within a chunk in index order. The mesh is copied, the caller keeps it.
  // FailedPrecondition outside BeginFrame/EndFrame; InvalidArgument when the mesh fails
  // ValidateMeshSizes / ValidateTriangleRange (bad sizes, index out of range, surface >= 16) or
  // has more triangles than one draw call takes (~715 M); Internal for GL errors. A chunk with
  // no triangles is accepted and adds nothing. Vertices shared by triangles of different
  // surfaces are uploaded once per surface (the extractor never shares them).
  absl::Status AddChunk(const OrderedMesh& mesh);

  // As AddChunk(mesh) for triangles [first_triangle, first_triangle + triangle_count) only;
  // just the vertices those triangles use are uploaded. OutOfRange when the range does not lie
  // inside the mesh.
  absl::Status AddChunk(const OrderedMesh& mesh, size_t first_triangle, size_t triangle_count);

  // Makes the pending frame current. FailedPrecondition without BeginFrame.
  absl::Status EndFrame();

  // Clears the bound framebuffer's viewport to the background and draws the current frame.
  // InvalidArgument for a camera that fails IsValidCamera.
  absl::Status Render(const Camera& camera);

  void SetPalette(const Palette& palette);
  const Palette& palette() const;
  void SetLighting(const Lighting& lighting);
  const Lighting& lighting() const;
  void SetBackground(const glm::vec4& rgba);
  const glm::vec4& background() const;

  // Sizes of the current frame (empty chunks not counted).
  size_t chunk_count() const;
  size_t triangle_count() const;
  bool frame_pending() const;

  struct Impl;

 private:
  explicit MeshRenderer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace isostream::render
