#include "shared/internal/chunk_gather.h"

#include <absl/container/flat_hash_map.h>
#include <absl/strings/str_cat.h>

#include <algorithm>
#include <cmath>
#include <cstring>
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
    // Local indices are below the corner count, kept below 2^28 here: 4 bits for the surface.
    dense_ = mesh_vertex_count <= 4 * corner_count && corner_count < (size_t{1} << 28);
    if (dense_) {
      entry_.assign(mesh_vertex_count, kUnset);
    } else {
      split_.reserve(corner_count);
    }
  }

  // Returns the local index of (vertex, surface), giving it `next` if it has none yet.
  uint32_t FindOrAdd(uint32_t vertex, uint8_t surface, uint32_t next) {
    if (dense_) {
      // Local index and surface share one word: one memory access per lookup.
      uint32_t& entry = entry_[vertex];
      if (entry == kUnset) {
        entry = (next << 4) | surface;
        return next;
      }
      if ((entry & 15) == surface) return entry >> 4;
    }
    return split_.try_emplace(SplitKey(vertex, surface), next).first->second;
  }

 private:
  static_assert(kMaxSurfaces <= 16, "the dense table keeps the surface in 4 bits");
  bool dense_ = false;
  std::vector<uint32_t> entry_;  // per mesh vertex: local << 4 | surface, or kUnset
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
  // A range has at most 3 local vertices per triangle (not at most the mesh's vertex count: a
  // vertex shared by two surfaces becomes two). Pages past the vertices actually written are
  // never touched.
  const size_t vertex_bound = 3 * triangle_count;
  out->triangles.resize(3 * triangle_count);
  out->surface.assign(mesh.surface.begin() + first_triangle,
                      mesh.surface.begin() + first_triangle + triangle_count);
  out->positions.resize(3 * vertex_bound);
  out->normals.resize(has_normals ? 3 * vertex_bound : 0);
  out->vertex_surface.resize(vertex_bound);
  const uint32_t* corners = mesh.triangles.data() + 3 * first_triangle;
  const float* mesh_positions = mesh.positions.data();
  const float* mesh_normals = mesh.normals.data();
  uint32_t* local_corners = out->triangles.data();
  float* positions = out->positions.data();
  float* normals = out->normals.data();
  uint8_t* vertex_surface = out->vertex_surface.data();

  // Assign local indices in first-use order, copying each vertex when first seen.
  uint32_t next = 0;
  for (size_t t = 0; t < triangle_count; ++t) {
    const uint8_t surface = out->surface[t];
    for (int c = 0; c < 3; ++c) {
      const uint32_t vertex = corners[3 * t + c];
      const uint32_t local = map->FindOrAdd(vertex, surface, next);
      local_corners[3 * t + c] = local;
      if (local != next) continue;
      const float* position = mesh_positions + 3 * size_t{vertex};
      if (!std::isfinite(position[0]) || !std::isfinite(position[1]) ||
          !std::isfinite(position[2])) {
        return absl::InvalidArgumentError(absl::StrCat("vertex ", vertex, " (used by triangle ",
                                                       first_triangle + t,
                                                       ") has a non-finite position"));
      }
      std::memcpy(positions + 3 * size_t{next}, position, 3 * sizeof(float));
      if (has_normals) {
        const float* normal = mesh_normals + 3 * size_t{vertex};
        if (!std::isfinite(normal[0]) || !std::isfinite(normal[1]) || !std::isfinite(normal[2])) {
          return absl::InvalidArgumentError(absl::StrCat("vertex ", vertex, " (used by triangle ",
                                                         first_triangle + t,
                                                         ") has a non-finite normal"));
        }
        std::memcpy(normals + 3 * size_t{next}, normal, 3 * sizeof(float));
      }
      vertex_surface[next] = surface;
      ++next;
    }
  }
  out->positions.resize(3 * size_t{next});
  if (has_normals) out->normals.resize(3 * size_t{next});
  out->vertex_surface.resize(next);
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
