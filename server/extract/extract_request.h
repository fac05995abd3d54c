// What a caller asks the extractor for, and what it reports back. Plain data: the CLI, the
// daemon and the tests fill it; ValidateRequest says what is wrong in words a user can act on.
#pragma once

#include <array>
#include <cstdint>
#include <glm/vec3.hpp>
#include <string>
#include <vector>

#include "server/extract/budget_memo.h"
#include "server/hierarchy/hierarchy.h"
#include "shared/ordered_mesh.h"
#include "shared/status.h"

namespace isostream {

enum class DrawOrder : uint8_t {
  kBackToFront,  // Gerstner §4: initial tets by BSP, children by separating plane, components
  kNone,         // same mesh, traversal order with no view dependence (to measure sorting)
};

enum class NormalMode : uint8_t {
  kSmooth,  // central differences of the volume, interpolated along the edge
  kFlat,    // the leaf tetrahedron's gradient; vertices are then not shared between tets
};

struct View {
  bool orthographic = false;
  glm::dvec3 eye{0.0};        // perspective: eye position, world units
  glm::dvec3 direction{0.0};  // orthographic: viewing direction (eye into the scene)
};

struct ExtractRequest {
  std::vector<float> isovalues;  // 1..kMaxSurfaces, any order; surface i is isovalues[i]
  // Exactly one of eps (>= 0, data units) or budget (> 0 triangles) is used: budget when > 0.
  double eps = 0.0;
  int64_t budget = 0;
  View view;
  DrawOrder order = DrawOrder::kBackToFront;
  NormalMode normals = NormalMode::kSmooth;
  int threads = 0;  // 0: all cores
  // The last three levels of the tree run as table-driven blocks (traversal.h). Off refines
  // them node by node: the same mesh byte for byte, slower; for tests and measurements.
  bool blocks = true;
  // Optional, not owned: remembers budget -> eps for this hierarchy across requests.
  BudgetMemo* budget_memo = nullptr;
};

// What names a request's mesh on a given volume, whatever its view and order: the isovalues in
// request order (which numbers the surfaces), the normal mode, and eps, or the budget for a
// budget request. A retained cut is matched by it, and a daemon stream's last frame.
struct MeshName {
  std::vector<float> isovalues;
  NormalMode normals = NormalMode::kSmooth;
  double eps = 0;  // 0 for a budget request
  int64_t budget = 0;

  static MeshName Of(const ExtractRequest& r) {
    return {r.isovalues, r.normals, r.budget > 0 ? 0.0 : r.eps, r.budget};
  }
  bool operator==(const MeshName& o) const {
    return isovalues == o.isovalues && normals == o.normals && eps == o.eps && budget == o.budget;
  }
};

struct ExtractStats {
  double eps_used = 0.0;
  int64_t triangles = 0;
  std::array<int64_t, kMaxSurfaces> triangles_per_surface{};
  int64_t vertices = 0;
  // Tetrahedra decided by the emitting traversal; a block enters only subtrees holding a
  // crossing finest tetrahedron, so blocks decide fewer than node-by-node refinement.
  int64_t tets_visited = 0;
  int64_t leaves = 0;      // leaf tetrahedra that produced triangles
  int subtrees = 0;        // units of parallel work
  int budget_passes = 0;   // count-only traversals run to find eps for a budget
  bool reordered = false;  // drawn from a retained cut (retained_cut.h), not extracted
  double budget_ms = 0, split_ms = 0, extract_ms = 0, join_ms = 0, total_ms = 0;
};

absl::Status ValidateRequest(const ExtractRequest& request);

}  // namespace isostream
