// Structural checks on an OrderedMesh, shared by every writer and encoder so that a malformed
// mesh is rejected at the module edge with a message naming the first offending element,
// instead of producing a file or a chunk that a reader would reject later.
#pragma once

#include <cstddef>

#include "shared/ordered_mesh.h"
#include "shared/status.h"

namespace isostream {

// Checks the array sizes of `mesh` only, in O(1): positions a multiple of 3, normals either
// empty (all undefined) or one triple per vertex, 3 indices per surface entry, and a vertex
// count that 32-bit indices can address. Returns InvalidArgument describing the mismatch.
absl::Status ValidateMeshSizes(const OrderedMesh& mesh);

// Checks triangles [first_triangle, first_triangle + triangle_count) in O(triangle_count):
// the range lies inside the mesh, every index is below vertex_count(), every surface index is
// below kMaxSurfaces. Assumes ValidateMeshSizes passed. Positions are not inspected.
absl::Status ValidateTriangleRange(const OrderedMesh& mesh, size_t first_triangle,
                                   size_t triangle_count);

// ValidateMeshSizes, ValidateTriangleRange over all triangles, and finite positions and
// normals: the full check a file writer runs before writing anything.
absl::Status ValidateMesh(const OrderedMesh& mesh);

}  // namespace isostream
