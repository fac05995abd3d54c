// One bisection step on concrete grid coordinates, driven by the reference tables: the only
// place where a tetrahedron's vertices become its children's. Header-only: the extractor's
// traversal inlines it.
#pragma once

#include <array>
#include <glm/vec3.hpp>

#include "server/hierarchy/reference_tets.h"

namespace isostream {

using TetVertices = std::array<glm::ivec3, 4>;  // canonical order of the tet's class

// The refinement vertex: midpoint of the refinement edge (vertex 0, vertex 3).
inline glm::ivec3 RefinementPoint(const TetVertices& v) { return (v[0] + v[3]) / 2; }

// Writes child c's vertices in the canonical order of class rt.child[c].
inline void ChildVertices(const ReferenceTet& rt, const TetVertices& v, int c, TetVertices* out) {
  const glm::ivec3 points[5] = {v[0], v[1], v[2], v[3], RefinementPoint(v)};
  for (int i = 0; i < 4; ++i) (*out)[i] = points[rt.child_point[c][i]];
}

// The 6 initial tetrahedra of the cube [0, size]^3.
inline TetVertices InitialVertices(const ReferenceTets& tables, int i, int size) {
  const ReferenceTet& rt = tables[tables.initial_class(i)];
  TetVertices v;
  for (int j = 0; j < 4; ++j) v[j] = rt.vertex[j] * (size / 2);
  return v;
}

}  // namespace isostream
