// Three-level blocks of the bisection tree: a tetrahedron with its descendants down to its
// great-grandchildren, 15 tetrahedra whose vertices are all among the root's 4 corners and 6
// edge midpoints when the root is a Kuhn tetrahedron (level 0 mod 3): its three levels of
// bisection cut every edge once. (Blocks starting at other levels do not have this property.)
// The extractor runs the last three levels of the tree as such blocks: it reads the 6 midpoints
// once and decides the whole block on bit sets of its 10 points (traversal.h).
//
// Computed by code from the reference tetrahedra's child maps, like them never typed in.
#pragma once

#include <array>
#include <cstdint>

#include "server/hierarchy/reference_tets.h"

namespace isostream {

inline constexpr int kBlockDepth = 3;
inline constexpr int kBlockPoints = 10;  // local points: 0..3 the root's corners, 4..9 midpoints
// Local point 4 + e is the midpoint of the root's canonical corners kBlockEdge[e].
inline constexpr uint8_t kBlockEdge[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
// Tetrahedra of a block in heap order: 1 is the root, 2p and 2p + 1 are the children 0 and 1
// (ReferenceTet::child) of p; depth of p = floor(log2 p). Index 0 is unused.
inline constexpr int kBlockNodes = 1 << (kBlockDepth + 1);

struct BlockNode {
  TetClass cls;
  std::array<uint8_t, 4> corner{};  // local point of each canonical vertex
  uint8_t refinement = 0;           // local point of the refinement vertex (depth < 3)
  uint16_t corners = 0;             // bit set of corner[]
};

class BlockTables {
 public:
  // Built on first use (thread-safe); throws std::logic_error if a descendant's vertex is not a
  // corner or an edge midpoint of the root, which would make the tables meaningless.
  static const BlockTables& Get();

  // The block below a root of class c (level_mod3 == 0), indexed by heap position.
  const BlockNode* operator[](TetClass c) const { return nodes_[c.value].data(); }
  // corners of the 8 finest tetrahedra (heap positions 8..15), contiguous.
  const uint16_t* leaf_corners(TetClass c) const { return leaf_corners_[c.value].data(); }

 private:
  BlockTables();
  std::array<std::array<BlockNode, kBlockNodes>, kNumTetClasses> nodes_{};
  // One 16-byte row per class: the traversal loads a row as one SSE2 register.
  alignas(16) std::array<std::array<uint16_t, kBlockNodes / 2>, kNumTetClasses> leaf_corners_{};
  static_assert(sizeof(leaf_corners_[0]) == 16, "a row of finest corner sets is one SSE2 load");
};

}  // namespace isostream
