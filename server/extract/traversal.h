// The adaptive, view-ordered traversal of the bisection tree (Gerstner §3-§5). Private to
// server/extract: extractor.cpp drives it over subtrees in parallel.
//
// Steps per tetrahedron T (explicit stack, no allocation per node):
//  1. cull: outside the data box, or no isovalue within [min f - eta, max f + eta] (§3; the
//     bound is proved in hierarchy.cpp);
//  2. stop where eta(x_ref) < eps or at the finest level, else bisect: children get their
//     corner values from the parent plus f(x_ref), and their gradients by the §5 update;
//  3. order: the child on the far side of the separating plane first (§4.2); the initial six
//     come from the BSP in ReferenceTets (§4.1);
//  4. leaf: marching tetrahedra for every isovalue crossing T, components ordered far to near
//     by |iso - f_T(eye)| (§4.3: parallel planes, so the one farther from the eye in function
//     value is farther along every ray that crosses both).
// The last three levels (below 3k - 3) run as table-driven blocks with the same leaves, order
// and arithmetic (Block; ExtractRequest::blocks turns them off for comparison).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>
#include <limits>
#include <vector>

#include "server/extract/block_sets.h"
#include "server/extract/edge_vertex_table.h"
#include "server/extract/extract_request.h"
#include "server/extract/marching_tets.h"
#include "server/extract/subtree_mesh.h"
#include "server/hierarchy/bisection.h"
#include "server/hierarchy/block_tables.h"
#include "server/hierarchy/hierarchy.h"

namespace isostream::extract_internal {

// A grid point packed as x | y << 21 | z << 42. Coordinates are below 2^13 (k <= 12), so sums
// of two points stay inside their fields: a refinement vertex is (v0 + v3) >> 1 (both ends have
// the same parity per axis, so no bit crosses a field), and a + b is an edge's doubled midpoint.
using PackedPoint = uint64_t;
inline constexpr int kFieldBits = 21;
inline constexpr uint64_t kFieldMask = (uint64_t{1} << kFieldBits) - 1;
inline PackedPoint Pack(const glm::ivec3& p) {
  return uint64_t(p.x) | (uint64_t(p.y) << kFieldBits) | (uint64_t(p.z) << (2 * kFieldBits));
}
inline glm::ivec3 Unpack(PackedPoint p) {
  return {int(p & kFieldMask), int((p >> kFieldBits) & kFieldMask), int(p >> (2 * kFieldBits))};
}

struct Node {
  PackedPoint v[4];  // canonical vertex order of the class
  float f[4];
  glm::dvec3 g;  // gradient of the linear interpolant on T, grid units
  // Byte offsets in the store of the refinement vertex's sample and eta (unused at the finest
  // level).
  uint64_t xref_value, xref_eta;
  TetClass cls;
  // Which child Bisect draws first, decided when the node is made: off the chain from a node
  // to its far child, where the plane test would delay every step (unused at the finest level).
  bool child0_first;
  int level;
};

// Everything the traversal reads, fixed for one request.
struct Context {
  const char* store = nullptr;                              // Hierarchy::bricks()
  const uint64_t* value_bytes[3] = {nullptr, nullptr, nullptr};  // Hierarchy::value_byte_offsets()
  const uint64_t* eta_bytes[3] = {nullptr, nullptr, nullptr};    // Hierarchy::eta_byte_offsets()
  int k = 0, n = 0;
  glm::ivec3 data_max{0};             // data box is [0, data_max]
  bool clip = false;                  // the data box is smaller than the cube
  float iso[kMaxSurfaces];            // ascending
  uint8_t iso_surface[kMaxSurfaces];  // request index of iso[i]
  int iso_count = 0;
  float eps = 0;
  bool ordered = true;
  bool orthographic = false;
  glm::dvec3 eye{0.0}, dir{0.0};  // grid space
  NormalMode normals = NormalMode::kSmooth;
  GridToWorld xf;
  glm::vec3 world_origin{0.0f}, world_spacing{1.0f};  // xf in single precision
  glm::vec3 inv_spacing{1.0f};  // grid-space gradient -> world-space gradient
  const ReferenceTets* tables = nullptr;
  const BlockTables* blocks = nullptr;
  int block_level = 0;  // 3k - 3: nodes refined here run the last three levels as one block
                        // (-1: none)
  const MarchingTets* cases = nullptr;
  uint8_t negative[kNumTetClasses];  // ReferenceTet::left_handed, beside the other per-class data
  // Per class, against ReferenceTet::plane_normal_int: perspective, normal . eye (grid space),
  // so the eye's side of a plane through grid point x is an exact integer dot product and one
  // comparison; orthographic, whether child 0 is drawn first (the same for every node).
  double plane_eye[kNumTetClasses];
  uint8_t ortho_child0_first[kNumTetClasses];
  // 1 / (real length of one normalised class unit) per level: half the level's cube cell.
  double inv_unit[3 * 16 + 1];

  static uint64_t Sum(const uint64_t* const table[3], PackedPoint p) {
    return table[0][p & kFieldMask] + table[1][(p >> kFieldBits) & kFieldMask] +
           table[2][p >> (2 * kFieldBits)];
  }
  uint64_t ValueOffset(PackedPoint p) const { return Sum(value_bytes, p); }
  uint64_t EtaOffset(PackedPoint p) const { return Sum(eta_bytes, p); }
  uint64_t ValueOffset(const glm::ivec3& p) const {
    return value_bytes[0][p.x] + value_bytes[1][p.y] + value_bytes[2][p.z];
  }
  float F(uint64_t value_offset) const {
    return *reinterpret_cast<const float*>(store + value_offset);
  }
  float Eta(uint64_t eta_offset) const {
    return DecodeEta(*reinterpret_cast<const uint16_t*>(store + eta_offset));
  }
  float F(const glm::ivec3& p) const { return F(ValueOffset(p)); }
};

enum class Decision { kCull, kLeaf, kRefine };

// Lowest sorted-iso index with iso > lo, and one past the highest with iso <= hi.
inline void IsoRange(const Context& c, float lo, float hi, int* first, int* last) {
  int a = 0;
  while (a < c.iso_count && c.iso[a] <= lo) ++a;
  int b = a;
  while (b < c.iso_count && c.iso[b] <= hi) ++b;
  *first = a;
  *last = b;
}

// For a leaf, [*first, *last) are the sorted isovalues that cross it.
inline Decision Decide(const Context& c, const Node& t, int* first, int* last) {
  if (c.clip) {
    const glm::ivec3 v[4] = {Unpack(t.v[0]), Unpack(t.v[1]), Unpack(t.v[2]), Unpack(t.v[3])};
    for (int a = 0; a < 3; ++a) {
      const int lo = std::min(std::min(v[0][a], v[1][a]), std::min(v[2][a], v[3][a]));
      if (lo >= c.data_max[a]) return Decision::kCull;
    }
  }
  const float fmin = std::min(std::min(t.f[0], t.f[1]), std::min(t.f[2], t.f[3]));
  const float fmax = std::max(std::max(t.f[0], t.f[1]), std::max(t.f[2], t.f[3]));
  if (t.level == 3 * c.k) {
    IsoRange(c, fmin, fmax, first, last);  // exact: a crossing needs fmin < iso <= fmax
    return *first < *last ? Decision::kLeaf : Decision::kCull;
  }
  const float e = c.Eta(t.xref_eta);
  // Any iso in [fmin - e, fmax + e] may meet f_full inside T.
  int a = 0;
  while (a < c.iso_count && c.iso[a] < fmin - e) ++a;
  if (a == c.iso_count || c.iso[a] > fmax + e) return Decision::kCull;
  if (e >= c.eps) return Decision::kRefine;
  IsoRange(c, fmin, fmax, first, last);
  return *first < *last ? Decision::kLeaf : Decision::kCull;
}

inline Decision Decide(const Context& c, const Node& t) {
  int first, last;
  return Decide(c, t, &first, &last);
}

// Whether child 0 of a tetrahedron of class cls (tables entry rt) with refinement vertex x is
// drawn first: unless the eye is on its side of the separating plane.
inline bool ChildZeroFirst(const Context& c, const ReferenceTet& rt, TetClass cls, PackedPoint x) {
  if (!c.ordered) return true;
  if (c.orthographic) return c.ortho_child0_first[cls.value];
  const int8_t* n = rt.plane_normal_int.data();
  const int64_t nx = n[0] * int64_t(x & kFieldMask) + n[1] * int64_t((x >> kFieldBits) & kFieldMask) +
                     n[2] * int64_t(x >> (2 * kFieldBits));
  return c.plane_eye[cls.value] <= double(nx);
}

// The children of t in draw order: the farther one (drawn first) in *first.
inline void Bisect(const Context& c, const Node& t, Node* first, Node* second) {
  const ReferenceTet& rt = (*c.tables)[t.cls];
  const PackedPoint x = (t.v[0] + t.v[3]) >> 1;
  const float fx = c.F(t.xref_value);
  const float fp[5] = {t.f[0], t.f[1], t.f[2], t.f[3], fx};
  const PackedPoint points[5] = {t.v[0], t.v[1], t.v[2], t.v[3], x};
  const double w = (double(fx) - 0.5 * (double(t.f[0]) + double(t.f[3]))) * c.inv_unit[t.level];
  const bool child0_first = t.child0_first;
  for (int ch = 0; ch < 2; ++ch) {
    Node& o = *((ch == 0) == child0_first ? first : second);
    const uint8_t* cp = rt.child_point[ch].data();
    for (int i = 0; i < 4; ++i) {
      o.v[i] = points[cp[i]];
      o.f[i] = fp[cp[i]];
    }
    o.g = t.g + w * rt.gradient_update[ch];
    o.cls = rt.child[ch];
    o.level = t.level + 1;
    // The child's first read is its refinement vertex: start fetching it now (the second
    // child has a whole subtree's time to arrive).
    if (o.level < 3 * c.k) {
      const PackedPoint ox = (o.v[0] + o.v[3]) >> 1;
      o.xref_value = c.ValueOffset(ox);
      o.xref_eta = c.EtaOffset(ox);
      __builtin_prefetch(c.store + o.xref_value);
      __builtin_prefetch(c.store + o.xref_eta);
      o.child0_first = ChildZeroFirst(c, (*c.tables)[o.cls], o.cls, ox);
    }
  }
}

// Integer planes of a subtree root's faces, to recognise edges that lie on them.
struct RootFaces {
  glm::i64vec3 normal[4];
  int64_t offset2[4];  // twice the plane offset: tested against doubled midpoints
  static int64_t Dot(const glm::i64vec3& a, const glm::i64vec3& b) {
    return a.x * b.x + a.y * b.y + a.z * b.z;
  }
  explicit RootFaces(const TetVertices& v) {
    for (int i = 0; i < 4; ++i) {
      const glm::i64vec3 a(v[(i + 1) % 4]), b(v[(i + 2) % 4]), c(v[(i + 3) % 4]);
      const glm::i64vec3 u = b - a, w = c - a;
      normal[i] = {u.y * w.z - u.z * w.y, u.z * w.x - u.x * w.z, u.x * w.y - u.y * w.x};
      offset2[i] = 2 * Dot(normal[i], a);
    }
  }
  // `doubled_mid` = a + b for an edge (a, b) inside the root. The root is convex, so the
  // edge's midpoint lies on a face plane only if both ends do.
  bool EdgeOnFace(const glm::ivec3& doubled_mid) const {
    const glm::i64vec3 m(doubled_mid);
    for (int i = 0; i < 4; ++i)
      if (Dot(normal[i], m) == offset2[i]) return true;
    return false;
  }
};

// Key of (edge, surface): the edge's doubled midpoint (packed). Leaves of the adaptive mesh
// form a conforming tetrahedral mesh (saturated eta: no hanging node), where two distinct
// edges never share an interior point, so the midpoint alone names the edge. Symmetric in the
// endpoints; 3 fields of 21 bits leave the top bit clear, and the surface goes below.
inline uint64_t EdgeKey(PackedPoint mid2, int s) { return (mid2 << 4) | uint64_t(s); }

// Emits triangles (kEmit) or only counts them, for one subtree.
template <bool kEmit>
class Traverser {
 public:
  Traverser(const Context& c, EdgeVertexTable* table, SubtreeMesh* out)
      : c_(c), table_(table), out_(out) {}

  // Returns the triangle count (stops early past `limit` when counting).
  int64_t Run(const Node& root, int64_t limit = INT64_MAX) {
    faces_ = RootFaces({Unpack(root.v[0]), Unpack(root.v[1]), Unpack(root.v[2]), Unpack(root.v[3])});
    if (kEmit) table_->Reset();
    int64_t triangles = 0, visited = 0;
    // Depth first, far child first. The current node stays out of the stack: bisection writes
    // the far child into the spare slot and pushes only the near one.
    Node stack[3 * 16 + 4];
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
          if (cur->level == c_.block_level && (!c_.clip || InsideDataBox(*cur)) &&
              BlockPays(*cur)) {
            triangles += Block(*cur, &visited);
            if (!kEmit && triangles > limit) return triangles;
            break;
          }
          Bisect(c_, *cur, spare, &stack[top++]);
          std::swap(cur, spare);
          continue;
        case Decision::kLeaf:
          triangles += Leaf(*cur, first, last);
          if (!kEmit && triangles > limit) return triangles;  // counting: enough seen
          break;
        case Decision::kCull:
          break;
      }
      if (top == 0) break;
      *cur = stack[--top];
    }
    if (kEmit) out_->visited += visited;
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
    unsigned crossing;  // bit j: the finest tetrahedron at heap position 8 + j crosses
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
        fr.child1_first |=
            unsigned(!ChildZeroFirst(c_, (*c_.tables)[b.cls], b.cls, fr.p[b.refinement])) << at;
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
      if (kDepth > 0) {  // the root was counted, and decided to refine, by the caller
        ++*visited;
        if (c_.eps > 0 && c_.Eta(c_.EtaOffset(fr.p[b.refinement])) < c_.eps)
          return BlockLeaf(fr, at, kDepth);
      }
      const unsigned far = 2 * at + ((fr.child1_first >> at) & 1);
      const int64_t n = BlockVisit<kDepth + 1>(fr, far, visited);
      return n + BlockVisit<kDepth + 1>(fr, far ^ 1, visited);
    }
  }

  // Emits block position `at` as a leaf if an isovalue crosses it.
  int BlockLeaf(const BlockFrame& fr, unsigned at, int depth) {
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
    t.level = fr.root->level + depth;
    // The gradient is needed for flat normals, and otherwise only to order several crossing
    // surfaces or when central differences vanish: computed on demand then (LeafGradient).
    if (c_.normals != NormalMode::kSmooth) {
      t.g = BlockGradient(fr, at, depth);
      return Leaf(t, first, last);
    }
    frame_ = &fr, frame_at_ = at, frame_depth_ = depth;
    const int n = Leaf(t, first, last);
    frame_ = nullptr;
    return n;
  }

  // The gradient of block position `at` by the §5 updates along its path, in the order and
  // arithmetic of Bisect.
  glm::dvec3 BlockGradient(const BlockFrame& fr, unsigned at, int depth) const {
    glm::dvec3 g = fr.root->g;
    for (int d = 0; d < depth; ++d) {
      const BlockNode& a = fr.nodes[at >> (depth - d)];
      const int ch = (at >> (depth - d - 1)) & 1;
      const double w = (double(fr.f[a.refinement]) -
                        0.5 * (double(fr.f[a.corner[0]]) + double(fr.f[a.corner[3]]))) *
                       c_.inv_unit[fr.root->level + d];
      g = g + w * (*c_.tables)[a.cls].gradient_update[ch];
    }
    return g;
  }

  glm::dvec3 LeafGradient(const Node& t) const {
    return frame_ ? BlockGradient(*frame_, frame_at_, frame_depth_) : t.g;
  }

  int Leaf(const Node& t, int first, int last) {
    if (kEmit) ++out_->leaves;
    if (last - first == 1) return Component(t, first);
    int order[kMaxSurfaces], count = 0;
    if (!c_.ordered) {
      for (int i = first; i < last; ++i) order[count++] = i;
    } else if (c_.orthographic) {
      const bool descending = glm::dot(LeafGradient(t), c_.dir) > 0;  // f grows away from the eye
      for (int i = first; i < last; ++i) order[count++] = descending ? last - 1 - (i - first) : i;
    } else {
      // Isovalues above f_T(eye), highest first; then those at or below it, lowest first.
      const double fe = t.f[0] + glm::dot(LeafGradient(t), c_.eye - glm::dvec3(Unpack(t.v[0])));
      int split = first;
      while (split < last && c_.iso[split] <= fe) ++split;
      for (int i = last - 1; i >= split; --i) order[count++] = i;
      for (int i = first; i < split; ++i) order[count++] = i;
    }
    int triangles = 0;
    for (int j = 0; j < count; ++j) triangles += Component(t, order[j]);
    return triangles;
  }

  // Marching tetrahedra for sorted isovalue index s.
  int Component(const Node& t, int s) {
    const float iso = c_.iso[s];
    const unsigned mask = unsigned(t.f[0] >= iso) | (unsigned(t.f[1] >= iso) << 1) |
                          (unsigned(t.f[2] >= iso) << 2) | (unsigned(t.f[3] >= iso) << 3);
    const MarchingTetsCase& mc = (*c_.cases)[mask];
    if (mc.edge_count == 0) return 0;
    const int count = mc.edge_count - 2;
    if (!kEmit) return count;
    uint32_t v[4];
    const int edges = mc.edge_count;  // a local: the stores below could alias the table
    for (int i = 0; i < edges; ++i) v[i] = EdgeVertex(t, mc.edge[i][0], mc.edge[i][1], s);
    if (count == 2 && QuadSplitsAlong13(v)) {
      // Rotate the cycle so the fan's diagonal (v0, v2) is the chosen one.
      const uint32_t v0 = v[0];
      v[0] = v[1], v[1] = v[2], v[2] = v[3], v[3] = v0;
    }
    // Wound so the geometric normal points to decreasing f (out of the region f >= iso).
    const bool flip = mc.flip[c_.negative[t.cls.value]];
    const uint8_t surface = c_.iso_surface[s];
    if (c_.clip && !InsideDataBox(t)) {
      ClipTriangle(v[0], flip ? v[2] : v[1], flip ? v[1] : v[2], surface);
      if (count == 2) ClipTriangle(v[0], flip ? v[3] : v[2], flip ? v[2] : v[3], surface);
      return count;
    }
    uint32_t* out = out_->triangles.Extend(3 * count);
    uint8_t* surf = out_->surface.Extend(count);
    out[0] = v[0], out[1] = flip ? v[2] : v[1], out[2] = flip ? v[1] : v[2];
    surf[0] = surface;
    if (count == 2) {
      out[3] = v[0], out[4] = flip ? v[3] : v[2], out[5] = flip ? v[2] : v[3];
      surf[1] = surface;
    }
    return count;
  }

  // A quad is split along its shorter diagonal (better triangles); equal lengths are broken by
  // position, so the choice does not depend on the tetrahedron's vertex order.
  bool QuadSplitsAlong13(const uint32_t v[4]) const {
    const glm::dvec3 p0 = Position(v[0]), p1 = Position(v[1]), p2 = Position(v[2]),
                     p3 = Position(v[3]);
    const double d02 = glm::dot(p2 - p0, p2 - p0), d13 = glm::dot(p3 - p1, p3 - p1);
    if (d02 != d13) return d13 < d02;
    auto less = [](const glm::dvec3& a, const glm::dvec3& b) {
      return a.x != b.x ? a.x < b.x : a.y != b.y ? a.y < b.y : a.z < b.z;
    };
    const glm::dvec3 m02 = less(p0, p2) ? p0 : p2, m13 = less(p1, p3) ? p1 : p3;
    return less(m13, m02);
  }

  glm::dvec3 Position(uint32_t i) const {
    const float* p = &out_->positions[3 * size_t(i)];
    return {p[0], p[1], p[2]};
  }

  bool InsideDataBox(const Node& t) const {
    for (int i = 0; i < 4; ++i)
      for (int a = 0; a < 3; ++a)
        if (Unpack(t.v[i])[a] > c_.data_max[a]) return false;
    return true;
  }

  // The crossing of surface s on the edge between corners ia and ib: found by edge key, or
  // computed (interpolated from the edge's lexicographically smaller end, so every
  // tetrahedron around the edge produces the same bits) and stored.
  uint32_t EdgeVertex(const Node& t, int ia, int ib, int s) {
    const PackedPoint mid2 = t.v[ia] + t.v[ib];
    if (c_.normals != NormalMode::kSmooth) return NewVertex(t, ia, ib, s, mid2, 0);
    const uint64_t key = EdgeKey(mid2, s);
    const uint32_t found = table_->FindOrInsert(key, out_->vertices);
    return found != EdgeVertexTable::kMissing ? found : NewVertex(t, ia, ib, s, mid2, key);
  }

  // Out of line: most lookups hit, and the hit path stays small enough to inline.
  __attribute__((noinline)) uint32_t NewVertex(const Node& t, int ia, int ib, int s,
                                               PackedPoint mid2, uint64_t key) {
    const uint32_t fresh = out_->vertices;
    const bool share = c_.normals == NormalMode::kSmooth;
    glm::ivec3 a = Unpack(t.v[ia]), b = Unpack(t.v[ib]);
    float fa = t.f[ia], fb = t.f[ib];
    glm::ivec3 d = b - a;
    if ((d.x != 0 ? d.x : d.y != 0 ? d.y : d.z) < 0) {
      std::swap(a, b);
      std::swap(fa, fb);
      d = -d;
    }
    // The parameter in double (float differences of values near FLT_MAX overflow), the point
    // in single precision: a grid coordinate below 2^13 keeps ~1e-3 voxel in its last bit, far
    // below the codec's quantization step.
    const float tt = float((double(c_.iso[s]) - fa) / (double(fb) - fa));
    const glm::vec3 pg = glm::vec3(a) + tt * glm::vec3(d);
    const glm::vec3 pw = c_.world_origin + c_.world_spacing * pg;
    glm::vec3 grad;
    if (share) {
      const glm::vec3 g = glm::mix(GridGradient(a), GridGradient(b), tt);
      grad = glm::dot(g, g) != 0 ? g : glm::vec3(LeafGradient(t));
    } else {
      grad = glm::vec3(t.g);
    }
    grad *= c_.inv_spacing;
    const float len2 = glm::dot(grad, grad);
    const glm::vec3 nrm = len2 >= std::numeric_limits<float>::min() &&
                                  len2 <= std::numeric_limits<float>::max()
                              ? grad * (-1.0f / std::sqrt(len2))
                              : NormalInDouble(t, a, b, tt, share);
    float* p = out_->positions.Extend(3);
    p[0] = pw.x, p[1] = pw.y, p[2] = pw.z;
    float* q = out_->normals.Extend(3);
    q[0] = nrm.x, q[1] = nrm.y, q[2] = nrm.z;
    ++out_->vertices;
    if (share && faces_.EdgeOnFace(Unpack(mid2))) out_->boundary.push_back({fresh, key});
    return fresh;
  }

  // The normal when the float gradient's squared length leaves the normal float range (samples
  // near FLT_MAX overflow it; tiny gradients, below ~1e-19 per world unit, underflow it): the
  // same gradient in double, (0, 0, 0) only where the data are flat.
  __attribute__((noinline)) glm::vec3 NormalInDouble(const Node& t, const glm::ivec3& a,
                                                     const glm::ivec3& b, float tt,
                                                     bool share) const {
    glm::dvec3 g;
    if (share) {
      const glm::dvec3 ga = GridGradient<double>(a), gb = GridGradient<double>(b);
      const glm::dvec3 mixed = glm::mix(ga, gb, double(tt));
      g = glm::dot(mixed, mixed) != 0 ? mixed : LeafGradient(t);
    } else {
      g = t.g;  // set for every leaf when normals are flat (a block leaf's only then)
    }
    g /= c_.xf.spacing;
    const double scale = std::max({std::abs(g.x), std::abs(g.y), std::abs(g.z)});
    if (!(scale > 0) || !std::isfinite(scale)) return glm::vec3(0.0f);
    g /= scale;  // no overflow in the squares below
    return glm::vec3(g * (-1.0 / std::sqrt(glm::dot(g, g))));
  }

  // Central differences of the samples at a grid point, one-sided on the cube's faces, in
  // precision T (float on the hot path; double differences cannot overflow).
  template <typename T = float>
  glm::vec<3, T> GridGradient(const glm::ivec3& p) const {
    return Interior(p) ? InteriorGradient<T>(p) : FaceGradient<T>(p);
  }

  // Both neighbours exist on every axis.
  bool Interior(const glm::ivec3& p) const {
    const unsigned span = unsigned(c_.n - 2);
    return unsigned(p.x - 1) < span && unsigned(p.y - 1) < span && unsigned(p.z - 1) < span;
  }

  template <typename T = float>
  glm::vec<3, T> InteriorGradient(const glm::ivec3& p) const {
    const uint64_t *ox = c_.value_bytes[0], *oy = c_.value_bytes[1], *oz = c_.value_bytes[2];
    const uint64_t x = ox[p.x], y = oy[p.y], z = oz[p.z];
    return T(0.5) * glm::vec<3, T>(F<T>(ox[p.x + 1] + y + z) - F<T>(ox[p.x - 1] + y + z),
                                   F<T>(x + oy[p.y + 1] + z) - F<T>(x + oy[p.y - 1] + z),
                                   F<T>(x + y + oz[p.z + 1]) - F<T>(x + y + oz[p.z - 1]));
  }

  // One-sided on the cube's faces. Out of line: rare, and it would crowd the vertex path.
  template <typename T = float>
  __attribute__((noinline)) glm::vec<3, T> FaceGradient(const glm::ivec3& p) const {
    const uint64_t *ox = c_.value_bytes[0], *oy = c_.value_bytes[1], *oz = c_.value_bytes[2];
    const int last = c_.n - 1;
    const glm::ivec3 lo(std::max(p.x - 1, 0), std::max(p.y - 1, 0), std::max(p.z - 1, 0));
    const glm::ivec3 hi(std::min(p.x + 1, last), std::min(p.y + 1, last), std::min(p.z + 1, last));
    const uint64_t x = ox[p.x], y = oy[p.y], z = oz[p.z];
    static constexpr T kInvSpan[3] = {T(0), T(1), T(0.5)};  // by hi - lo
    return {(F<T>(ox[hi.x] + y + z) - F<T>(ox[lo.x] + y + z)) * kInvSpan[hi.x - lo.x],
            (F<T>(x + oy[hi.y] + z) - F<T>(x + oy[lo.y] + z)) * kInvSpan[hi.y - lo.y],
            (F<T>(x + y + oz[hi.z]) - F<T>(x + y + oz[lo.z])) * kInvSpan[hi.z - lo.z]};
  }

  template <typename T>
  T F(uint64_t value_offset) const {
    return T(c_.F(value_offset));
  }

  // A leaf that straddles the data box: keep the part of the triangle inside it.
  // Out of line: rare, and its polygon buffers would otherwise enlarge every leaf's frame.
  __attribute__((noinline)) void ClipTriangle(uint32_t a, uint32_t b, uint32_t d,
                                              uint8_t surface) {
    struct V {
      glm::dvec3 p, n;
    };
    auto load = [&](uint32_t i) {
      const float* q = &out_->normals[3 * size_t(i)];
      return V{Position(i), glm::dvec3(q[0], q[1], q[2])};
    };
    V poly[9], next[9];
    uint32_t ids[9], next_ids[9];
    int count = 3;
    poly[0] = load(a), poly[1] = load(b), poly[2] = load(d);
    ids[0] = a, ids[1] = b, ids[2] = d;
    for (int axis = 0; axis < 3; ++axis) {
      const double limit = c_.xf.origin[axis] + c_.xf.spacing[axis] * c_.data_max[axis];
      int m = 0;
      for (int i = 0; i < count; ++i) {
        const V& p = poly[i];
        const V& q = poly[(i + 1) % count];
        const bool pin = p.p[axis] <= limit, qin = q.p[axis] <= limit;
        if (pin) next[m] = p, next_ids[m++] = ids[i];
        if (pin != qin) {
          const double s = (limit - p.p[axis]) / (q.p[axis] - p.p[axis]);
          next[m] = V{glm::mix(p.p, q.p, s), glm::normalize(glm::mix(p.n, q.n, s))};
          next[m].p[axis] = limit;
          next_ids[m++] = EdgeVertexTable::kMissing;
        }
      }
      count = m;
      std::copy(next, next + m, poly);
      std::copy(next_ids, next_ids + m, ids);
      if (count < 3) return;
    }
    for (int i = 0; i < count; ++i) {
      if (ids[i] != EdgeVertexTable::kMissing) continue;
      ids[i] = out_->vertices++;
      float* p = out_->positions.Extend(3);
      p[0] = float(poly[i].p.x), p[1] = float(poly[i].p.y), p[2] = float(poly[i].p.z);
      float* q = out_->normals.Extend(3);
      q[0] = float(poly[i].n.x), q[1] = float(poly[i].n.y), q[2] = float(poly[i].n.z);
    }
    for (int i = 1; i + 1 < count; ++i) {
      uint32_t* out = out_->triangles.Extend(3);
      out[0] = ids[0], out[1] = ids[i], out[2] = ids[i + 1];
      out_->surface.Push(surface);
    }
  }

  const Context& c_;
  EdgeVertexTable* table_;
  SubtreeMesh* out_;
  RootFaces faces_{TetVertices{}};
  // Set while a block leaf is emitted: its gradient is derived from the block on demand.
  const BlockFrame* frame_ = nullptr;
  unsigned frame_at_ = 0;
  int frame_depth_ = 0;
};

}  // namespace isostream::extract_internal
