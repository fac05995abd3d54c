#include "shared/mesh_validate.h"

#include <absl/strings/str_cat.h>

#include <cmath>
#include <cstdint>
#include <limits>

namespace isostream {

absl::Status ValidateMeshSizes(const OrderedMesh& mesh) {
  if (mesh.positions.size() % 3 != 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("mesh has ", mesh.positions.size(), " position floats, not a multiple of 3"));
  }
  if (!mesh.normals.empty() && mesh.normals.size() != mesh.positions.size()) {
    return absl::InvalidArgumentError(absl::StrCat("mesh has ", mesh.normals.size(),
                                                   " normal floats for ", mesh.vertex_count(),
                                                   " vertices (expected 0 or 3 per vertex)"));
  }
  if (mesh.triangles.size() != 3 * mesh.surface.size()) {
    return absl::InvalidArgumentError(absl::StrCat("mesh has ", mesh.triangles.size(),
                                                   " triangle indices for ", mesh.surface.size(),
                                                   " surface entries (expected 3 per triangle)"));
  }
  // Index value 0xffffffff is kept free so that no valid vertex can collide with the "unset"
  // sentinel the encoders use while re-indexing.
  if (mesh.vertex_count() >= std::numeric_limits<uint32_t>::max()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "mesh has ", mesh.vertex_count(), " vertices; 32-bit indices cannot address them"));
  }
  return absl::OkStatus();
}

absl::Status ValidateTriangleRange(const OrderedMesh& mesh, size_t first_triangle,
                                   size_t triangle_count) {
  const size_t total = mesh.triangle_count();
  if (first_triangle > total || triangle_count > total - first_triangle) {
    return absl::OutOfRangeError(absl::StrCat("triangle range [", first_triangle, ", +",
                                              triangle_count, ") exceeds the mesh's ", total,
                                              " triangles"));
  }
  const size_t vertex_count = mesh.vertex_count();
  const size_t end = first_triangle + triangle_count;
  for (size_t t = first_triangle; t < end; ++t) {
    for (int c = 0; c < 3; ++c) {
      const uint32_t v = mesh.triangles[3 * t + c];
      if (v >= vertex_count) {
        return absl::InvalidArgumentError(absl::StrCat(
            "triangle ", t, " uses vertex ", v, " but the mesh has ", vertex_count, " vertices"));
      }
    }
    if (mesh.surface[t] >= kMaxSurfaces) {
      return absl::InvalidArgumentError(absl::StrCat("triangle ", t, " has surface index ",
                                                     int{mesh.surface[t]}, "; at most ",
                                                     kMaxSurfaces, " surfaces are supported"));
    }
  }
  return absl::OkStatus();
}

absl::Status ValidateMesh(const OrderedMesh& mesh) {
  ISOSTREAM_RETURN_IF_ERROR(ValidateMeshSizes(mesh));
  ISOSTREAM_RETURN_IF_ERROR(ValidateTriangleRange(mesh, 0, mesh.triangle_count()));
  for (size_t i = 0; i < mesh.positions.size(); ++i) {
    if (!std::isfinite(mesh.positions[i])) {
      return absl::InvalidArgumentError(
          absl::StrCat("vertex ", i / 3, " has a non-finite position coordinate"));
    }
  }
  for (size_t i = 0; i < mesh.normals.size(); ++i) {
    if (!std::isfinite(mesh.normals[i])) {
      return absl::InvalidArgumentError(
          absl::StrCat("vertex ", i / 3, " has a non-finite normal coordinate"));
    }
  }
  return absl::OkStatus();
}

}  // namespace isostream
