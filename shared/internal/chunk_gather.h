// Internal to shared/: the vertex re-indexing both chunk codecs and the GLB writer share, so a
// triangle range gets the same local vertex numbering whichever codec carries it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "shared/ordered_mesh.h"
#include "shared/status.h"
#include "shared/uninitialized_vector.h"

namespace isostream::internal {

// The triangles of a range with their own vertex arrays. Local vertices are numbered in order of
// first use by the range's corners. A local vertex belongs to exactly one surface: a mesh vertex
// used by triangles of two surfaces becomes two local vertices, so per-vertex encodings of the
// surface (Draco attributes, glTF COLOR_0) stay exact.
//
// Uninitialized vectors: the gather sizes them for the worst case (3 vertices per triangle),
// writes each element once and shrinks them, without zeroing first.
struct GatheredChunk {
  UninitializedVector<float> positions;         // 3 per local vertex
  UninitializedVector<float> normals;           // 3 per local vertex; empty when the mesh has none
  UninitializedVector<uint8_t> vertex_surface;  // 1 per local vertex
  UninitializedVector<uint32_t> triangles;      // 3 local indices per triangle, in range order
  UninitializedVector<uint8_t> surface;         // 1 per triangle

  size_t vertex_count() const { return vertex_surface.size(); }
  size_t triangle_count() const { return surface.size(); }
};

// A decoded chunk, checked, before it is appended to the caller's mesh.
struct DecodedChunk {
  std::vector<float> positions;  // 3 per local vertex
  std::vector<float> normals;    // 3 per local vertex; empty when the chunk has none
  std::vector<uint8_t> tags;     // per local vertex: surface | "normal undefined" bit (0x80)
  std::vector<uint32_t> triangles;
  std::vector<uint8_t> triangle_surface;
};

// Lookup state that GatherTriangleRange calls over one mesh can share: a table indexed by mesh
// vertex that is sized once and never cleared (entries carry the number of the call that set
// them). For a producer that gathers consecutive ranges of a mesh that keeps growing.
struct GatherScratch {
  struct Entry {
    uint32_t call = 0;  // the call that last assigned this mesh vertex; 0 never
    uint32_t local = 0;
    uint8_t surface = 0;
  };
  std::vector<Entry> entries;  // per mesh vertex, one memory access per lookup
  uint32_t call = 0;
};

// Fills `out` (reusing its capacity) with triangles [first_triangle, first_triangle +
// triangle_count) of `mesh`; with `scratch`, looks local indices up in its table. Validates what it
// reads: array sizes, the range, indices, surface indices and the finiteness of gathered positions
// and normals; returns InvalidArgument or OutOfRange naming the offending triangle or vertex. Cost
// O(triangle_count), plus O(vertex count of the mesh) when the range is large enough that a dense
// lookup table pays off.
absl::Status GatherTriangleRange(const OrderedMesh& mesh, size_t first_triangle,
                                 size_t triangle_count, GatheredChunk* out,
                                 GatherScratch* scratch = nullptr);

}  // namespace isostream::internal
