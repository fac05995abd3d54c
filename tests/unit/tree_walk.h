// Test helpers: walk the whole bisection tree, or the adaptive tree for an eps, on small cubes.
#pragma once

#include <functional>

#include "server/hierarchy/bisection.h"
#include "server/hierarchy/hierarchy.h"

namespace isostream::testing {

struct TetNode {
  TetVertices v;
  TetClass cls;
  int level = 0;
};

// Visits every tetrahedron of the tree on [0, 2^k]^3 down to level 3k (the unit-cube Kuhn tets),
// parents before children. `visit` returns false to stop descending below a node.
inline void WalkTree(int k, const std::function<bool(const TetNode&)>& visit) {
  const ReferenceTets& tables = ReferenceTets::Get();
  std::function<void(const TetNode&)> rec = [&](const TetNode& t) {
    if (!visit(t) || t.level == 3 * k) return;
    const ReferenceTet& rt = tables[t.cls];
    for (int c = 0; c < 2; ++c) {
      TetNode child;
      ChildVertices(rt, t.v, c, &child.v);
      child.cls = rt.child[c];
      child.level = t.level + 1;
      rec(child);
    }
  };
  for (int i = 0; i < kNumInitialTets; ++i)
    rec(TetNode{InitialVertices(tables, i, 1 << k), tables.initial_class(i), 0});
}

// Leaves of the adaptive mesh for eps: refine T iff eta(x_ref(T)) >= eps and T is not finest.
inline std::vector<TetNode> AdaptiveLeaves(const Hierarchy& h, double eps) {
  std::vector<TetNode> leaves;
  WalkTree(h.k(), [&](const TetNode& t) {
    const glm::ivec3 x = RefinementPoint(t.v);
    const bool refine = t.level < 3 * h.k() && h.eta(x.x, x.y, x.z) >= eps;
    if (!refine) leaves.push_back(t);
    return refine;
  });
  return leaves;
}

}  // namespace isostream::testing
