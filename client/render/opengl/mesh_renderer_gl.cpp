// MeshRenderer on OpenGL 3.3 core. Each chunk keeps its own vertex array and index buffer;
// drawing a frame is one glDrawElements per chunk, in arrival order, blended over what is
// already there.
//
// Surfaces are per triangle in OrderedMesh but reach the shaders as a flat per-vertex
// attribute. Reading gl_PrimitiveID in the fragment shader (with the per-triangle bytes in a
// buffer texture) would avoid touching vertices, but on llvmpipe it sends every primitive through
// Mesa's primitive assembler and cost ~45 ms per 10^6 triangles (125 ms vs 79 ms for a frame
// that covers few pixels). Extracted isosurfaces never share a vertex between surfaces, so the
// attribute is usually free; a vertex that is shared is split, one copy per surface.
#include <absl/container/flat_hash_map.h>
#include <absl/strings/str_cat.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <limits>
#include <vector>

#include "client/render/mesh_renderer.h"
#include "client/render/opengl/embedded_shaders.h"
#include "client/render/opengl/gl_api.h"
#include "shared/mesh_validate.h"
#include "shared/surface_palette.h"

namespace isostream::render {
namespace {

constexpr GLuint kPositionAttribute = 0;
constexpr GLuint kNormalAttribute = 1;
constexpr GLuint kSurfaceAttribute = 2;

struct Chunk {
  gl::VertexArray vertex_array;
  gl::Buffer positions;
  gl::Buffer normals;
  gl::Buffer surfaces;
  gl::Buffer indices;
  GLsizei index_count = 0;
  bool has_normals = false;
};

struct Uniforms {
  GLint view_projection = -1;
  GLint surface_style = -1;
  GLint eye = -1;
  GLint view_scale = -1;
  GLint forward = -1;
  GLint orthographic = -1;
  GLint light = -1;
  GLint light_terms = -1;
};

// Arrays for one chunk; views into the caller's mesh when the whole mesh is uploaded, into the
// renderer's scratch when a range is compacted or vertices are split.
struct ChunkArrays {
  const float* positions;
  const float* normals;  // null when the mesh has no normals
  size_t vertex_count;
  const uint32_t* triangles;
  const uint8_t* surface;  // per triangle
  size_t triangle_count;
};

// Largest chunk one glDrawElements call can draw: its index count is a GLsizei.
constexpr size_t kMaxChunkTriangles = size_t(std::numeric_limits<GLsizei>::max()) / 3;

}  // namespace

Palette DefaultPalette() {
  Palette p;
  for (size_t i = 0; i < p.size(); ++i) {
    const std::array<float, 4>& c = kDefaultSurfaceRgba[i];
    p[i] = {{c[0], c[1], c[2]}, c[3]};
  }
  return p;
}

glm::vec3 LightDirectionInWorld(const Lighting& lighting, const Camera& camera) {
  const glm::vec3 d = lighting.direction_in_eye;
  return glm::normalize(d.x * camera.Right() + d.y * camera.TrueUp() - d.z * camera.Forward());
}

struct MeshRenderer::Impl {
  gl::Program program;
  Uniforms uniforms;

  std::vector<Chunk> current;
  std::vector<Chunk> pending;
  size_t current_triangles = 0;
  size_t pending_triangles = 0;
  bool frame_open = false;

  Palette palette = DefaultPalette();
  Lighting lighting;
  glm::vec4 background = kDefaultBackground;

  // Scratch kept between calls so a stream of chunks does not allocate per chunk once the
  // largest has been seen. remap holds kUnused for every vertex between calls.
  static constexpr uint32_t kUnused = std::numeric_limits<uint32_t>::max();
  static constexpr uint8_t kNoSurface = 0xFF;
  std::vector<uint32_t> remap;
  std::vector<uint32_t> used_vertices;
  std::vector<float> scratch_positions;
  std::vector<float> scratch_normals;
  std::vector<uint32_t> scratch_triangles;
  std::vector<uint8_t> vertex_surface;
  std::vector<float> split_positions;
  std::vector<float> split_normals;
  std::vector<uint32_t> split_triangles;

  // Gives every vertex the surface of the triangles that use it, in vertex_surface. Returns
  // `a` itself when no vertex serves two surfaces; otherwise arrays (in the split_* scratch)
  // where each (vertex, surface) pair in use is its own vertex. Unused vertices get surface 0.
  ChunkArrays AssignVertexSurfaces(const ChunkArrays& a) {
    vertex_surface.assign(a.vertex_count, kNoSurface);
    bool shared = false;
    for (size_t t = 0; t < a.triangle_count && !shared; ++t) {
      for (int k = 0; k < 3; ++k) {
        uint8_t& s = vertex_surface[a.triangles[3 * t + k]];
        if (s == kNoSurface) s = a.surface[t];
        shared |= s != a.surface[t];
      }
    }
    if (!shared) {
      for (uint8_t& s : vertex_surface) s = s == kNoSurface ? 0 : s;
      return a;
    }
    // Rare: only meshes not made by the extractor get here, so a hash map is good enough.
    absl::flat_hash_map<uint64_t, uint32_t> copy_of;
    split_positions.clear();
    split_normals.clear();
    vertex_surface.clear();
    split_triangles.resize(3 * a.triangle_count);
    for (size_t t = 0; t < a.triangle_count; ++t) {
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = a.triangles[3 * t + k];
        const auto [it, inserted] =
            copy_of.try_emplace(uint64_t(v) << 8 | a.surface[t], uint32_t(vertex_surface.size()));
        if (inserted) {
          split_positions.insert(split_positions.end(), a.positions + 3 * v,
                                 a.positions + 3 * v + 3);
          if (a.normals != nullptr)
            split_normals.insert(split_normals.end(), a.normals + 3 * v, a.normals + 3 * v + 3);
          vertex_surface.push_back(a.surface[t]);
        }
        split_triangles[3 * t + k] = it->second;
      }
    }
    return {split_positions.data(),
            a.normals != nullptr ? split_normals.data() : nullptr,
            vertex_surface.size(),
            split_triangles.data(),
            a.surface,
            a.triangle_count};
  }

  absl::Status Upload(const ChunkArrays& input) {
    if (input.triangle_count > kMaxChunkTriangles) {
      return absl::InvalidArgumentError(absl::StrCat("chunk has ", input.triangle_count,
                                                     " triangles; one draw call takes at most ",
                                                     kMaxChunkTriangles, ", split it"));
    }
    if (input.triangle_count == 0) return absl::OkStatus();
    const ChunkArrays a = AssignVertexSurfaces(input);
    Chunk c;
    c.vertex_array = gl::VertexArray::Make();
    c.positions = gl::Buffer::Make();
    c.surfaces = gl::Buffer::Make();
    c.indices = gl::Buffer::Make();
    c.index_count = GLsizei(3 * a.triangle_count);
    c.has_normals = a.normals != nullptr;

    glBindVertexArray(c.vertex_array.get());
    glBindBuffer(GL_ARRAY_BUFFER, c.positions.get());
    glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(3 * sizeof(float) * a.vertex_count), a.positions,
                 GL_STATIC_DRAW);
    glEnableVertexAttribArray(kPositionAttribute);
    glVertexAttribPointer(kPositionAttribute, 3, GL_FLOAT, GL_FALSE, 0, nullptr);
    if (c.has_normals) {
      c.normals = gl::Buffer::Make();
      glBindBuffer(GL_ARRAY_BUFFER, c.normals.get());
      glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(3 * sizeof(float) * a.vertex_count), a.normals,
                   GL_STATIC_DRAW);
      glEnableVertexAttribArray(kNormalAttribute);
      glVertexAttribPointer(kNormalAttribute, 3, GL_FLOAT, GL_FALSE, 0, nullptr);
    } else {
      glDisableVertexAttribArray(kNormalAttribute);
    }
    glBindBuffer(GL_ARRAY_BUFFER, c.surfaces.get());
    glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(a.vertex_count), vertex_surface.data(),
                 GL_STATIC_DRAW);
    glEnableVertexAttribArray(kSurfaceAttribute);
    glVertexAttribIPointer(kSurfaceAttribute, 1, GL_UNSIGNED_BYTE, 0, nullptr);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, c.indices.get());
    glBufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(sizeof(uint32_t) * 3 * a.triangle_count),
                 a.triangles, GL_STATIC_DRAW);
    glBindVertexArray(0);
    glBindBuffer(GL_ARRAY_BUFFER, 0);

    ISOSTREAM_RETURN_IF_ERROR(gl::CheckGl("MeshRenderer::AddChunk"));
    pending.push_back(std::move(c));
    pending_triangles += a.triangle_count;
    return absl::OkStatus();
  }

  // Copies triangles [first, first + count) and just the vertices they use, renumbered in
  // order of first use, into the scratch arrays.
  ChunkArrays Compact(const OrderedMesh& mesh, size_t first, size_t count) {
    const bool has_normals = !mesh.normals.empty();
    if (remap.size() < mesh.vertex_count()) remap.resize(mesh.vertex_count(), kUnused);
    used_vertices.clear();
    scratch_triangles.resize(3 * count);
    const uint32_t* in = mesh.triangles.data() + 3 * first;
    for (size_t i = 0; i < 3 * count; ++i) {
      uint32_t& slot = remap[in[i]];
      if (slot == kUnused) {
        slot = uint32_t(used_vertices.size());
        used_vertices.push_back(in[i]);
      }
      scratch_triangles[i] = slot;
    }
    scratch_positions.resize(3 * used_vertices.size());
    scratch_normals.resize(has_normals ? 3 * used_vertices.size() : 0);
    for (size_t j = 0; j < used_vertices.size(); ++j) {
      const size_t v = used_vertices[j];
      std::copy_n(mesh.positions.data() + 3 * v, 3, scratch_positions.data() + 3 * j);
      if (has_normals) std::copy_n(mesh.normals.data() + 3 * v, 3, scratch_normals.data() + 3 * j);
      remap[v] = kUnused;
    }
    return {scratch_positions.data(),    has_normals ? scratch_normals.data() : nullptr,
            used_vertices.size(),        scratch_triangles.data(),
            mesh.surface.data() + first, count};
  }
};

MeshRenderer::MeshRenderer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
MeshRenderer::~MeshRenderer() = default;

absl::StatusOr<std::unique_ptr<MeshRenderer>> MeshRenderer::Create() {
  const std::string_view vertex = shaders::EmbeddedShader("mesh.vert.glsl");
  const std::string_view fragment = shaders::EmbeddedShader("mesh.frag.glsl");
  if (vertex.empty() || fragment.empty()) {
    return absl::InternalError("mesh shaders were not embedded at build time");
  }
  auto impl = std::make_unique<Impl>();
  ISOSTREAM_ASSIGN_OR_RETURN(
      impl->program, gl::BuildProgram("mesh", absl::string_view(vertex.data(), vertex.size()),
                                      absl::string_view(fragment.data(), fragment.size())));
  const GLuint p = impl->program.get();
  Uniforms& u = impl->uniforms;
  u.view_projection = glGetUniformLocation(p, "u_view_projection");
  u.surface_style = glGetUniformLocation(p, "u_surface_style");
  u.eye = glGetUniformLocation(p, "u_eye");
  u.view_scale = glGetUniformLocation(p, "u_view_scale");
  u.forward = glGetUniformLocation(p, "u_forward");
  u.orthographic = glGetUniformLocation(p, "u_orthographic");
  u.light = glGetUniformLocation(p, "u_light");
  u.light_terms = glGetUniformLocation(p, "u_light_terms");
  // Every uniform is used by the shaders; a -1 here means the sources and this file disagree.
  for (GLint location : {u.view_projection, u.surface_style, u.eye, u.view_scale, u.forward,
                         u.orthographic, u.light, u.light_terms}) {
    if (location < 0) return absl::InternalError("mesh shader lacks a uniform the renderer sets");
  }
  ISOSTREAM_RETURN_IF_ERROR(gl::CheckGl("MeshRenderer::Create"));
  return std::unique_ptr<MeshRenderer>(new MeshRenderer(std::move(impl)));
}

void MeshRenderer::BeginFrame() {
  impl_->pending.clear();
  impl_->pending_triangles = 0;
  impl_->frame_open = true;
}

absl::Status MeshRenderer::AddChunk(const OrderedMesh& mesh) {
  if (!impl_->frame_open) return absl::FailedPreconditionError("AddChunk outside a frame");
  ISOSTREAM_RETURN_IF_ERROR(ValidateMeshSizes(mesh));
  ISOSTREAM_RETURN_IF_ERROR(ValidateTriangleRange(mesh, 0, mesh.triangle_count()));
  return impl_->Upload({mesh.positions.data(), mesh.normals.empty() ? nullptr : mesh.normals.data(),
                        mesh.vertex_count(), mesh.triangles.data(), mesh.surface.data(),
                        mesh.triangle_count()});
}

absl::Status MeshRenderer::AddChunk(const OrderedMesh& mesh, size_t first_triangle,
                                    size_t triangle_count) {
  if (!impl_->frame_open) return absl::FailedPreconditionError("AddChunk outside a frame");
  ISOSTREAM_RETURN_IF_ERROR(ValidateMeshSizes(mesh));
  ISOSTREAM_RETURN_IF_ERROR(ValidateTriangleRange(mesh, first_triangle, triangle_count));
  return impl_->Upload(impl_->Compact(mesh, first_triangle, triangle_count));
}

absl::Status MeshRenderer::EndFrame() {
  if (!impl_->frame_open) return absl::FailedPreconditionError("EndFrame without BeginFrame");
  impl_->current = std::move(impl_->pending);
  impl_->current_triangles = impl_->pending_triangles;
  impl_->pending.clear();
  impl_->pending_triangles = 0;
  impl_->frame_open = false;
  return gl::CheckGl("MeshRenderer::EndFrame");
}

absl::Status MeshRenderer::Render(const Camera& camera) {
  if (!IsValidCamera(camera)) {
    return absl::InvalidArgumentError(
        "Render: camera has no valid projection (eye == target, up parallel to the view, "
        "near/far, aspect or field of view out of range)");
  }
  const Impl& m = *impl_;
  // Order, not depth, decides visibility: each fragment is composited over everything drawn
  // before it. Alpha uses (ONE, ONE_MINUS_SRC_ALPHA) so the framebuffer stays opaque over an
  // opaque background instead of turning translucent where layers pile up.
  glDisable(GL_DEPTH_TEST);
  glDepthMask(GL_FALSE);
  glDisable(GL_CULL_FACE);
  glEnable(GL_BLEND);
  glBlendEquation(GL_FUNC_ADD);
  glBlendFuncSeparate(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA, GL_ONE, GL_ONE_MINUS_SRC_ALPHA);
  glClearColor(m.background.r, m.background.g, m.background.b, m.background.a);
  glClear(GL_COLOR_BUFFER_BIT);

  glUseProgram(m.program.get());
  glUniformMatrix4fv(m.uniforms.view_projection, 1, GL_FALSE,
                     glm::value_ptr(camera.ViewProjection()));
  GLfloat styles[4 * kMaxSurfaces];
  for (int s = 0; s < kMaxSurfaces; ++s) {
    const SurfaceStyle& style = m.palette[size_t(s)];
    styles[4 * s + 0] = std::clamp(style.color.r, 0.0f, 1.0f);
    styles[4 * s + 1] = std::clamp(style.color.g, 0.0f, 1.0f);
    styles[4 * s + 2] = std::clamp(style.color.b, 0.0f, 1.0f);
    styles[4 * s + 3] = std::clamp(style.opacity, 0.0f, 1.0f);
  }
  glUniform4fv(m.uniforms.surface_style, kMaxSurfaces, styles);
  glUniform3fv(m.uniforms.eye, 1, glm::value_ptr(camera.eye));
  glUniform1f(m.uniforms.view_scale,
              float(1.0 / glm::length(glm::dvec3(camera.target) - glm::dvec3(camera.eye))));
  const glm::vec3 forward = camera.Forward();
  glUniform3fv(m.uniforms.forward, 1, glm::value_ptr(forward));
  glUniform1i(m.uniforms.orthographic, camera.projection == Projection::kOrthographic);
  const glm::vec3 light = LightDirectionInWorld(m.lighting, camera);
  glUniform3fv(m.uniforms.light, 1, glm::value_ptr(light));
  // pow(0, 0) is undefined in GLSL; a non-positive exponent is clamped away from it.
  glUniform4f(m.uniforms.light_terms, m.lighting.ambient, m.lighting.diffuse, m.lighting.specular,
              std::max(m.lighting.shininess, 1e-3f));

  for (const Chunk& c : m.current) {
    glBindVertexArray(c.vertex_array.get());
    // A disabled attribute array reads the context's current value, not the VAO's.
    if (!c.has_normals) glVertexAttrib3f(kNormalAttribute, 0.0f, 0.0f, 0.0f);
    glDrawElements(GL_TRIANGLES, c.index_count, GL_UNSIGNED_INT, nullptr);
  }
  glBindVertexArray(0);
  glUseProgram(0);
  return gl::CheckGl("MeshRenderer::Render");
}

void MeshRenderer::SetPalette(const Palette& palette) { impl_->palette = palette; }
const Palette& MeshRenderer::palette() const { return impl_->palette; }
void MeshRenderer::SetLighting(const Lighting& lighting) { impl_->lighting = lighting; }
const Lighting& MeshRenderer::lighting() const { return impl_->lighting; }
void MeshRenderer::SetBackground(const glm::vec4& rgba) { impl_->background = rgba; }
const glm::vec4& MeshRenderer::background() const { return impl_->background; }
size_t MeshRenderer::chunk_count() const { return impl_->current.size(); }
size_t MeshRenderer::triangle_count() const { return impl_->current_triangles; }
bool MeshRenderer::frame_pending() const { return impl_->frame_open; }

}  // namespace isostream::render
