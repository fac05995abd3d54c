#include "shared/internal/chunk_gather.h"

#include <absl/container/flat_hash_map.h>
#include <absl/strings/str_cat.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "shared/mesh_validate.h"

namespace isostream::internal {
namespace {

constexpr uint32_t kUnset = std::numeric_limits<uint32_t>::max();

uint64_t SplitKey(uint32_t vertex, uint8_t surface) { return (uint64_t{vertex} << 8) | surface; }

// Maps (mesh vertex, surface) to a local index. Chunks of a large frame are small next to the
// mesh, so they use a hash map sized by the range; a range covering much of the mesh uses a
// table indexed by mesh vertex instead, which is several times faster per lookup. Vertices
// shared across surfaces are rare, so in the dense case they go to the hash map.
class LocalIndexMap {
 public:
  LocalIndexMap(size_t mesh_vertex_count, size_t corner_count) {
    dense_ = mesh_vertex_count <= 4 * corner_count;
    if (dense_) {
      local_.assign(mesh_vertex_count, kUnset);
      surface_of_.resize(mesh_vertex_count);
    } else {
      split_.reserve(corner_count);
    }
  }

  // Returns the local index of (vertex, surface), giving it `next` if it has none yet.
  uint32_t FindOrAdd(uint32_t vertex, uint8_t surface, uint32_t next) {
    if (dense_) {
      if (local_[vertex] == kUnset) {
        local_[vertex] = next;
        surface_of_[vertex] = surface;
        return next;
      }
      if (surface_of_[vertex] == surface) return local_[vertex];
    }
    return split_.try_emplace(SplitKey(vertex, surface), next).first->second;
  }

 private:
  bool dense_ = false;
  std::vector<uint32_t> local_;
  std::vector<uint8_t> surface_of_;
  absl::flat_hash_map<uint64_t, uint32_t> split_;
};

// The same mapping on a GatherScratch's table, for one call.
class StampedIndexMap {
 public:
  StampedIndexMap(GatherScratch* scratch, size_t mesh_vertex_count) : s_(scratch) {
    if (s_->entries.size() < mesh_vertex_count) s_->entries.resize(mesh_vertex_count);
    if (++s_->call == 0) {  // wrapped: old entries could look current
      std::fill(s_->entries.begin(), s_->entries.end(), GatherScratch::Entry{});
      s_->call = 1;
    }
  }

  uint32_t FindOrAdd(uint32_t vertex, uint8_t surface, uint32_t next) {
    GatherScratch::Entry& e = s_->entries[vertex];
    if (e.call != s_->call) {
      e = {s_->call, next, surface};
      return next;
    }
    if (e.surface == surface) return e.local;
    return split_.try_emplace(SplitKey(vertex, surface), next).first->second;
  }

 private:
  GatherScratch* s_;
  absl::flat_hash_map<uint64_t, uint32_t> split_;
};

template <typename Map>
absl::Status Gather(const OrderedMesh& mesh, size_t first_triangle, size_t triangle_count, Map* map,
                    GatheredChunk* out) {
  const bool has_normals = !mesh.normals.empty();
  out->positions.clear();
  out->normals.clear();
  out->vertex_surface.clear();
  out->triangles.resize(3 * triangle_count);
  out->surface.assign(mesh.surface.begin() + first_triangle,
                      mesh.surface.begin() + first_triangle + triangle_count);

  // A range has at most 3 vertices per triangle and never more than the mesh.
  const size_t vertex_bound = std::min(mesh.vertex_count(), 3 * triangle_count);
  out->positions.reserve(3 * vertex_bound);
  if (has_normals) out->normals.reserve(3 * vertex_bound);
  out->vertex_surface.reserve(vertex_bound);

  // Assign local indices in first-use order, copying each vertex when first seen.
  for (size_t t = 0; t < triangle_count; ++t) {
    const uint8_t surface = out->surface[t];
    for (int c = 0; c < 3; ++c) {
      const uint32_t vertex = mesh.triangles[3 * (first_triangle + t) + c];
      const uint32_t next = static_cast<uint32_t>(out->vertex_surface.size());
      const uint32_t local = map->FindOrAdd(vertex, surface, next);
      out->triangles[3 * t + c] = local;
      if (local != next) continue;
      const float* position = &mesh.positions[3 * size_t{vertex}];
      if (!std::isfinite(position[0]) || !std::isfinite(position[1]) ||
          !std::isfinite(position[2])) {
        return absl::InvalidArgumentError(absl::StrCat("vertex ", vertex, " (used by triangle ",
                                                       first_triangle + t,
                                                       ") has a non-finite position"));
      }
      out->positions.insert(out->positions.end(), position, position + 3);
      if (has_normals) {
        const float* normal = &mesh.normals[3 * size_t{vertex}];
        if (!std::isfinite(normal[0]) || !std::isfinite(normal[1]) || !std::isfinite(normal[2])) {
          return absl::InvalidArgumentError(absl::StrCat("vertex ", vertex, " (used by triangle ",
                                                         first_triangle + t,
                                                         ") has a non-finite normal"));
        }
        out->normals.insert(out->normals.end(), normal, normal + 3);
      }
      out->vertex_surface.push_back(surface);
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status GatherTriangleRange(const OrderedMesh& mesh, size_t first_triangle,
                                 size_t triangle_count, GatheredChunk* out,
                                 GatherScratch* scratch) {
  ISOSTREAM_RETURN_IF_ERROR(ValidateMeshSizes(mesh));
  ISOSTREAM_RETURN_IF_ERROR(ValidateTriangleRange(mesh, first_triangle, triangle_count));
  if (scratch) {
    StampedIndexMap map(scratch, mesh.vertex_count());
    return Gather(mesh, first_triangle, triangle_count, &map, out);
  }
  LocalIndexMap map(mesh.vertex_count(), 3 * triangle_count);
  return Gather(mesh, first_triangle, triangle_count, &map, out);
}

}  // namespace isostream::internal
