// The adaptive, view-ordered traversal of the bisection tree (Gerstner §3-§5) over one subtree.
// Private to server/extract: extractor.cpp drives it over subtrees in parallel.
//
// Steps per tetrahedron T (explicit stack, no allocation per node; tree_node.h):
//  1. cull: outside the data box, or no isovalue within [min f - eta, max f + eta] (§3; the
//     bound is proved in hierarchy.cpp);
//  2. stop where eta(x_ref) < eps or at the finest level, else bisect: children get their
//     corner values from the parent plus f(x_ref), and their gradients by the §5 update;
//  3. order: the child on the far side of the separating plane first (§4.2); the initial six
//     come from the BSP in ReferenceTets (§4.1);
//  4. leaf: marching tetrahedra for every isovalue crossing T (leaf_emitter.h), components
//     ordered far to near by |iso - f_T(eye)| (§4.3: parallel planes, so the one farther from
//     the eye in function value is farther along every ray that crosses both).
// The last three levels (below 3k - 3) run as table-driven blocks with the same leaves, order
// and arithmetic (Block; ExtractRequest::blocks turns them off for comparison).
#pragma once

#include <algorithm>
#include <cstdint>
#include <glm/vec3.hpp>
#include <utility>

#include "server/extract/block_sets.h"
#include "server/extract/count_curve.h"
#include "server/extract/edge_vertex_table.h"
#include "server/extract/leaf_emitter.h"
#include "server/extract/subtree_mesh.h"
#include "server/extract/tree_node.h"
#include "server/hierarchy/block_tables.h"

namespace isostream::extract_internal {

// Emits triangles (kEmit) or only counts them, for one subtree. A count pass may also gather
// the count at every coarser eps into `curve` (count_curve.h); its context must have blocks off
// (block_level -1), since the curve needs the eta of every node the blocks skip. Without
// kGradient the nodes carry no §5 gradient: for counting, and for emission that reads none
// (NeedsGradients).
template <bool kEmit, bool kRecord = false, bool kGradient = kEmit>
class Traverser {
  static_assert(kEmit || !kRecord, "only an emitting traversal records");

 public:
  // kRecord (emitting only): the refined nodes and the leaves are recorded in `cut` as well
  // (cut_recorder.h).
  Traverser(const Context& c, EdgeVertexTable* table, SubtreeMesh* out, CountCurve* curve = nullptr,
            CutPart* cut = nullptr)
      : c_(c), emit_(c, table, out, cut), curve_(curve), cut_(cut) {}

  // Returns the triangle count (stops early past `limit` when counting).
  int64_t Run(const Node& root, int64_t limit = INT64_MAX) {
    emit_.BeginSubtree(root);
    int64_t triangles = 0, visited = 0;
    // Depth first, far child first. The current node stays out of the stack: bisection writes
    // the far child into the spare slot and pushes only the near one.
    Node stack[3 * 16 + 4];
    uint32_t second_of[3 * 16 + 4];  // recording: the refine record stack[i] is the second of
    Node slots[2];
    Node* cur = &slots[0];
    Node* spare = &slots[1];
    *cur = root;
    int top = 0;
    for (;;) {
      ++visited;
      int first, last;
      switch (Decide(c_, *cur, &first, &last)) {
        case Decision::kRefine:
          if (cur->level == c_.block_level && (!c_.clip || InsideDataBox(c_, *cur)) &&
              BlockPays(*cur)) {
            triangles += Block(*cur, &visited);
            if (!kEmit && triangles > limit) return triangles;
            break;
          }
          Bisect<kGradient>(c_, *cur, spare, &stack[top++]);
          if constexpr (kRecord)
            second_of[top - 1] = cut_->AddRefine(
                PlaneSide(c_, cur->cls, (cur->v[0] + cur->v[3]) >> 1), cur->cls, cur->child0_first);
          if (!kEmit && curve_) {
            // A leaf at the eta codes above its own, up to its nearest ancestor's: counted only
            // where some of those are on the curve (most nodes above the cut are leaves only
            // past the codes a pass gathers).
            const uint32_t code = EtaCode(c_, *cur);
            if (code < std::min(cur->eta_cap, curve_->last()))
              curve_->Add(code + 1, cur->eta_cap, LeafTriangles(c_, *cur));
            spare->eta_cap = stack[top - 1].eta_cap = std::min(cur->eta_cap, code);
          }
          std::swap(cur, spare);
          continue;
        case Decision::kLeaf: {
          const int n = emit_.Leaf(*cur, first, last);
          triangles += n;
          // Its eta (if any) is below this pass's eps: a leaf at every code the curve holds.
          if (!kEmit && curve_) {
            curve_->Add(0, cur->eta_cap, n);
            if (cur->level < 3 * c_.k) curve_->NoteStop(EtaCode(c_, *cur));
          }
          if (!kEmit && triangles > limit) return triangles;  // counting: enough seen
          break;
        }
        case Decision::kCull:
          // A leaf without crossings may gain some below its eta (culled ones never do; noting
          // them too only shortens what the curve claims is constant).
          if (!kEmit && curve_ && cur->level < 3 * c_.k) curve_->NoteStop(EtaCode(c_, *cur));
          break;
      }
      if (top == 0) break;
      *cur = stack[--top];
      if constexpr (kRecord) cut_->SecondChildStarts(second_of[top]);
    }
    emit_.AddVisited(visited);
    return triangles;
  }

 private:
  // The last three levels below a node at level 3k - 3 that is to be refined, as one block:
  // its 6 edge midpoints are read once, and which of the 8 finest tetrahedra cross an isovalue
  // is decided on bit sets of the block's 10 points. Only subtrees holding a crossing finest
  // tetrahedron are entered (exact: a tetrahedron of the block crosses only if some finest one
  // below it does, the finest ones tiling it), so no eta is read but to stop refining when
  // eps > 0. Leaves, their order and their arithmetic are those of refining node by node.
  struct BlockFrame {
    const Node* root;
    const BlockNode* nodes;
    PackedPoint p[kBlockPoints];
    float f[kBlockPoints];
    unsigned above[kMaxSurfaces];  // points with f >= iso[s], for s in [s0, s1)
    int s0, s1;
    unsigned crossing;      // bit j: the finest tetrahedron at heap position 8 + j crosses
    unsigned child1_first;  // bit p: position p draws its child 1 first
  };

  // A block's up-front work (6 samples, 7 plane sides) is ~2.5 bisections': with eps > 0 it
  // runs only where both children refine too (eta at their refinement vertices >= eps).
  // Unconditional blocks cost adaptive ~1 M-triangle frames 4-7% more instructions (most of
  // those stop one level down); with this test they are within 1.3% of node by node (requiring
  // all six inner tetrahedra to refine was worse).
  bool BlockPays(const Node& root) const {
    if (c_.eps <= 0) return true;
    const BlockNode* nodes = (*c_.blocks)[root.cls];
    for (int ch = 2; ch < 4; ++ch) {
      const uint8_t* e = kBlockEdge[nodes[ch].refinement - 4];
      if (c_.Eta(c_.EtaOffset((root.v[e[0]] + root.v[e[1]]) >> 1)) < c_.eps) return false;
    }
    return true;
  }

  int64_t Block(const Node& root, int64_t* visited) {
    BlockFrame fr;
    fr.root = &root;
    fr.nodes = (*c_.blocks)[root.cls];
    for (int i = 0; i < 4; ++i) fr.p[i] = root.v[i], fr.f[i] = root.f[i];
    for (int e = 0; e < 6; ++e) {
      fr.p[4 + e] = (root.v[kBlockEdge[e][0]] + root.v[kBlockEdge[e][1]]) >> 1;
      fr.f[4 + e] = c_.F(c_.ValueOffset(fr.p[4 + e]));
    }
    float lo = fr.f[0], hi = fr.f[0];
    for (int i = 1; i < kBlockPoints; ++i) lo = std::min(lo, fr.f[i]), hi = std::max(hi, fr.f[i]);
    IsoRange(c_, lo, hi, &fr.s0, &fr.s1);
    const uint16_t* leaf_corners = c_.blocks->leaf_corners(root.cls);
    fr.crossing = 0;
    for (int s = fr.s0; s < fr.s1; ++s) {
      const unsigned m = AbovePoints(fr.f, c_.iso[s]);
      fr.above[s] = m;
      fr.crossing |= CrossingLeaves(leaf_corners, m);
    }
    if (fr.crossing == 0) return 0;
    // All 7 separating-plane sides up front: independent of each other, so they overlap
    // instead of each waiting on the walk that reaches its tetrahedron.
    fr.child1_first = 0;
    if (c_.ordered)
      for (unsigned at = 1; at < kBlockNodes / 2; ++at) {
        const BlockNode& b = fr.nodes[at];
        fr.child1_first |= unsigned(!ChildZeroFirst(c_, b.cls, fr.p[b.refinement])) << at;
      }
    return BlockVisit<0>(fr, 1, visited);
  }

  template <int kDepth>
  int64_t BlockVisit(const BlockFrame& fr, unsigned at, int64_t* visited) {
    if constexpr (kDepth == kBlockDepth) {
      if (!((fr.crossing >> (at - 8)) & 1)) return 0;
      ++*visited;
      return BlockLeaf(fr, at, kDepth);
    } else {
      constexpr int kBelow = kBlockDepth - kDepth;
      const unsigned finest = (fr.crossing >> ((at << kBelow) - 8)) & ((1u << (1 << kBelow)) - 1);
      if (finest == 0) return 0;
      const BlockNode& b = fr.nodes[at];
      if (kDepth > 0) ++*visited;  // the root was counted, and decided to refine, by the caller
      // Depth 1 refines: BlockPays checked its etas before the block began.
      if (kDepth == 2 && c_.eps > 0 && c_.Eta(c_.EtaOffset(fr.p[b.refinement])) < c_.eps)
        return BlockLeaf(fr, at, kDepth);
      const unsigned far = 2 * at + ((fr.child1_first >> at) & 1);
      uint32_t record = 0;
      if constexpr (kRecord)
        record = cut_->AddRefine(PlaneSide(c_, b.cls, fr.p[b.refinement]), b.cls,
                                 !((fr.child1_first >> at) & 1));
      const int64_t n = BlockVisit<kDepth + 1>(fr, far, visited);
      if constexpr (kRecord) cut_->SecondChildStarts(record);
      return n + BlockVisit<kDepth + 1>(fr, far ^ 1, visited);
    }
  }

  // Emits block position `at` as a leaf if an isovalue crosses it. Always inlined: GCC's choice
  // flipped with unrelated growth of the leaf path (a call cost ~1.5%).
  __attribute__((always_inline)) int BlockLeaf(const BlockFrame& fr, unsigned at, int depth) {
    const BlockNode& b = fr.nodes[at];
    // Past the isovalues all corners reach, before those none does (the sets shrink with s).
    int first = fr.s0;
    while (first < fr.s1 && (fr.above[first] & b.corners) == b.corners) ++first;
    int last = first;
    while (last < fr.s1 && (fr.above[last] & b.corners) != 0) ++last;
    if (first == last) return 0;
    Node t;
    for (int i = 0; i < 4; ++i) t.v[i] = fr.p[b.corner[i]], t.f[i] = fr.f[b.corner[i]];
    t.cls = b.cls;
    t.level = uint8_t(fr.root->level + depth);
    // The gradient is needed for flat normals, and otherwise only to order several crossing
    // surfaces: computed on demand then (LeafGradient).
    if (c_.normals != NormalMode::kSmooth) {
      // Without kGradient (a count pass; emission takes it with flat normals: NeedsGradients)
      // the root's g is unset, and nothing reads t.g: zero, not a sum over an unset value.
      if constexpr (kGradient)
        t.g = BlockGradient(fr, at, depth);
      else
        t.g = glm::dvec3(0.0);
      return emit_.Leaf(t, first, last);
    }
    const BlockCursor cursor{this, &fr, at, depth};
    return emit_.Leaf(t, first, last, &CursorGradient, &cursor);
  }

  struct BlockCursor {
    const Traverser* self;
    const BlockFrame* frame;
    unsigned at;
    int depth;
  };
  static glm::dvec3 CursorGradient(const void* state) {
    const auto& c = *static_cast<const BlockCursor*>(state);
    return c.self->BlockGradient(*c.frame, c.at, c.depth);
  }

  // The gradient of block position `at` by the §5 updates along its path (Wavelet, as Bisect
  // does).
  glm::dvec3 BlockGradient(const BlockFrame& fr, unsigned at, int depth) const {
    glm::dvec3 g = fr.root->g;
    for (int d = 0; d < depth; ++d) {
      const BlockNode& a = fr.nodes[at >> (depth - d)];
      const int ch = (at >> (depth - d - 1)) & 1;
      const double w =
          Wavelet(c_, fr.f[a.refinement], fr.f[a.corner[0]], fr.f[a.corner[3]], fr.root->level + d);
      g = g + w * (*c_.tables)[a.cls].gradient_update[ch];
    }
    return g;
  }

  const Context& c_;
  LeafEmitter<kEmit, kRecord> emit_;
  CountCurve* curve_;
  CutPart* cut_;
};

}  // namespace isostream::extract_internal
