// Leaf output of the traversal: marching tetrahedra on a leaf for each isovalue crossing it
// (components ordered far to near, §4.3), vertices shared per surface by edge key (each edge
// crossing computed once, Kipfer & Westermann), smooth normals from central differences,
// winding from the case table, and clipping at the data box. Private to server/extract.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>
#include <limits>

#include "server/extract/block_sets.h"
#include "server/extract/cut_recorder.h"
#include "server/extract/data_box_clip.h"
#include "server/extract/edge_vertex_table.h"
#include "server/extract/subtree_mesh.h"
#include "server/extract/tree_node.h"

namespace isostream::extract_internal {

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

// Emits the leaves of one subtree into `out` (kEmit), or only counts their triangles; with
// kRecord (emitting only) also records them into a CutPart.
template <bool kEmit, bool kRecord = false>
class LeafEmitter {
 public:
  using GradientFn = glm::dvec3 (*)(const void* state);

  // kRecord: every leaf that emits triangles is recorded in `cut` too (cut_recorder.h).
  LeafEmitter(const Context& c, EdgeVertexTable* table, SubtreeMesh* out, CutPart* cut = nullptr)
      : c_(c), table_(table), out_(out), cut_(cut) {}

  // A new subtree: vertices on its root's faces are the ones the join may merge.
  void BeginSubtree(const Node& root) {
    faces_ =
        RootFaces({Unpack(root.v[0]), Unpack(root.v[1]), Unpack(root.v[2]), Unpack(root.v[3])});
    if (kEmit) table_->Reset();
  }

  // Marching tetrahedra on leaf t for the sorted isovalues [first, last) crossing it, components
  // far to near. A leaf whose node carries no gradient (a block's, with smooth normals) passes
  // how to derive it; that is read only to order several surfaces (and recorded with them), so
  // an indirect call is cheap enough. Always inlined: with two emitting traversals
  // (with and without gradients) GCC stopped inlining it into the blocks' leaves (+0.8%).
  __attribute__((always_inline)) int Leaf(const Node& t, int first, int last,
                                          GradientFn lazy = nullptr,
                                          const void* lazy_state = nullptr) {
    lazy_ = lazy, lazy_state_ = lazy_state;
    const int n = Components(t, first, last);
    lazy_ = nullptr;
    return n;
  }

  void AddVisited(int64_t visited) {
    if (kEmit) out_->visited += visited;
  }

 private:
  glm::dvec3 LeafGradient(const Node& t) const { return lazy_ ? lazy_(lazy_state_) : t.g; }

  // Always inlined, as QuadSplitsAlong13: GCC's choices shifted when the clipping path grew
  // (+1.2% instructions at cayley:257 eps 0, where nothing clips).
  __attribute__((always_inline)) int Components(const Node& t, int first, int last) {
    if (kEmit) ++out_->leaves;
    if (last - first == 1) {
      if constexpr (!kEmit || !kRecord) return Component(t, first);
      const size_t before = out_->surface.size();
      const int n = Component(t, first);
      cut_->AddLeaf(uint32_t(before), uint32_t(out_->surface.size() - before));
      return n;
    }
    const int count = last - first;
    int triangles = 0;
    if constexpr (!kEmit) {  // a count needs no order (nor the gradient that makes it)
      for (int s = first; s < last; ++s) triangles += Component(t, s);
      return triangles;
    }
    int order[kMaxSurfaces];  // of the isovalues from `first`
    ComponentOrder(
        c_, [&] { return LeafGradient(t); }, t.f[0], t.v[0],
        [&](int i) { return c_.iso[first + i]; }, count, order);
    if constexpr (!kRecord) {
      for (int j = 0; j < count; ++j) triangles += Component(t, first + order[j]);
      return triangles;
    }
    // Recorded with what orders the components for another view (ComponentOrder reads the
    // same), components by ascending isovalue.
    size_t start[kMaxSurfaces], end[kMaxSurfaces];
    for (int j = 0; j < count; ++j) {
      start[order[j]] = out_->surface.size();
      triangles += Component(t, first + order[j]);
      end[order[j]] = out_->surface.size();
    }
    uint32_t nonempty = 0;
    for (int i = 0; i < count; ++i) nonempty += end[i] > start[i];
    if (nonempty == 0) return triangles;  // all clipped away
    cut_->AddMultiLeaf({LeafGradient(t), t.v[0], t.f[0]}, nonempty);
    for (int i = 0; i < count; ++i)
      if (end[i] > start[i])
        cut_->AddComponent(uint8_t(first + i), uint32_t(start[i]), uint32_t(end[i] - start[i]));
    return triangles;
  }

  // Marching tetrahedra for sorted isovalue index s.
  int Component(const Node& t, int s) {
    const float iso = c_.iso[s];
    const unsigned above = AboveCorners(t.f, iso);
    const MarchingTetsCase& mc = (*c_.cases)[above];
    if (mc.edge_count == 0) return 0;
    if (c_.clip && !InsideDataBox(c_, t)) return StraddlingComponent(t, s, mc);
    // Only crossings on a corner at the isovalue drop triangles; where the others are stored
    // (OffTheEnds) does not change the count, so counting needs no positions.
    if constexpr (!kEmit)
      return CornersAtIso(t.f, iso) != 0 ? ComponentNearCorners(t, s, mc) : mc.edge_count - 2;
    // A component with a corner at the isovalue (its crossings are the corner's vertex) or next
    // to it (a crossing's coordinate may round onto the corner's: OffTheEnds) is placed
    // exactly, out of line.
    if (CornersNearIso(t.f, iso, c_.snap_tau) != 0) return ComponentNearCorners(t, s, mc);
    const int count = mc.edge_count - 2;
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

  // A component of a leaf that straddles the data box, clipped there (the vertices of parts
  // clipped away are dropped with the subtree's unused ones). Out of line: rare.
  __attribute__((noinline)) int StraddlingComponent(const Node& t, int s,
                                                    const MarchingTetsCase& mc) {
    if constexpr (!kEmit) return StraddlingComponentTriangles(c_, t, s, mc);
    return ComponentThroughCorners(t, s, mc, true);
  }

  // A component with a corner near the isovalue. Out of line: rare.
  __attribute__((noinline)) int ComponentNearCorners(const Node& t, int s,
                                                     const MarchingTetsCase& mc) {
    if constexpr (!kEmit) return ComponentCrossings(c_, t, s, mc).Triangles();
    return ComponentThroughCorners(t, s, mc, false);
  }

  // A component with crossings on corners whose value is the isovalue (flat or integer data):
  // the crossings of one such corner are one vertex, named by the corner, and a triangle left
  // without an area is not emitted (most of a terrace's triangles had none); or with crossings
  // that round onto a corner on some coordinate, moved off it (OffTheEnds: one float step off
  // integer data, 64% of the triangles had two corners in one place). Also the path of
  // straddling leaves (`clip`). Without such crossings it emits what Component does, vertex for
  // vertex.
  int ComponentThroughCorners(const Node& t, int s, const MarchingTetsCase& mc, bool clip) {
    const ComponentCrossings x(c_, t, s, mc);
    const int edges = x.edges;
    // Only crossings of triangles with an area get vertices: the others would be used by none.
    unsigned used = 0;
    for (int k = 1; k + 1 < edges; ++k)
      if (x.HasArea(k)) used |= 1u << x.Corner(0) | 1u << x.Corner(k) | 1u << x.Corner(k + 1);
    uint32_t made[4];
    for (int i = 0; i < edges; ++i)
      if ((used >> i) & 1)
        made[i] = x.where[i] < 4 ? CornerVertex(t, x.where[i], s)
                                 : EdgeVertex(t, mc.edge[i][0], mc.edge[i][1], s, &x.p[i]);
    uint32_t v[4];
    for (int i = 0; i < edges; ++i) v[i] = (used >> x.Corner(i)) & 1 ? made[x.Corner(i)] : 0;
    const bool flip = mc.flip[c_.negative[t.cls.value]];
    const uint8_t surface = c_.iso_surface[s];
    int emitted = 0;
    for (int k = 1; k + 1 < edges; ++k) {
      if (!x.HasArea(k)) continue;
      const uint32_t a = v[0], b = flip ? v[k + 1] : v[k], d = flip ? v[k] : v[k + 1];
      if (clip) {
        emitted += ClipTriangle(a, b, d, surface);
      } else {
        uint32_t* out = out_->triangles.Extend(3);
        out[0] = a, out[1] = b, out[2] = d;
        out_->surface.Push(surface);
        ++emitted;
      }
    }
    return emitted;
  }

  __attribute__((always_inline)) bool QuadSplitsAlong13(const uint32_t v[4]) const {
    const glm::dvec3 p[4] = {Position(v[0]), Position(v[1]), Position(v[2]), Position(v[3])};
    return extract_internal::QuadSplitsAlong13(p);
  }

  glm::dvec3 Position(uint32_t i) const {
    const float* p = &out_->positions[3 * size_t(i)];
    return {p[0], p[1], p[2]};
  }

  // The crossing of surface s on the edge between corners ia and ib: found by edge key, or
  // computed (interpolated from the edge's lexicographically smaller end, so every
  // tetrahedron around the edge produces the same bits) and stored.
  // `placed`: the position ComponentCrossings stores it at (OffTheEnds), on the exact path.
  uint32_t EdgeVertex(const Node& t, int ia, int ib, int s, const glm::dvec3* placed = nullptr) {
    const PackedPoint mid2 = t.v[ia] + t.v[ib];
    if (c_.normals != NormalMode::kSmooth) return NewVertex(t, ia, ib, s, mid2, 0, placed);
    const uint64_t key = EdgeKey(mid2, s);
    const uint32_t found = table_->FindOrInsert(key, out_->vertices);
    return found != EdgeVertexTable::kMissing ? found : NewVertex(t, ia, ib, s, mid2, key, placed);
  }

  // The crossings of surface s stored on corner `corner` (ComponentCrossings): one vertex for
  // every edge through that corner, keyed by the corner's doubled point (no edge of the
  // conforming mesh has a vertex of it as its midpoint, so no edge key is the same).
  uint32_t CornerVertex(const Node& t, int corner, int s) {
    const PackedPoint mid2 = t.v[corner] + t.v[corner];
    if (c_.normals != NormalMode::kSmooth) return NewCornerVertex(t, corner, mid2, 0);
    const uint64_t key = EdgeKey(mid2, s);
    const uint32_t found = table_->FindOrInsert(key, out_->vertices);
    return found != EdgeVertexTable::kMissing ? found : NewCornerVertex(t, corner, mid2, key);
  }

  // A crossing on corner `corner` (CornerVertex): the corner's point, exactly where the edge
  // interpolation puts it, and the corner's own differences (a mix weighting an edge's other end
  // by 0 would let that end decide the sign of a zero or, infinite, make NaN: edge by edge).
  // Out of line: rare.
  __attribute__((noinline)) uint32_t NewCornerVertex(const Node& t, int corner, PackedPoint mid2,
                                                     uint64_t key) {
    const bool share = c_.normals == NormalMode::kSmooth;
    const glm::ivec3 at = Unpack(t.v[corner]);
    const glm::vec3 pw = CornerWorld(c_, t.v[corner]);
    glm::vec3 grad = share ? GridGradient(at) : glm::vec3(t.g);
    if (share && glm::dot(grad, grad) == 0) grad = CornerGradient<float>(at);
    grad *= c_.inv_spacing;
    const float len2 = glm::dot(grad, grad);
    glm::vec3 nrm;
    if (len2 >= std::numeric_limits<float>::min() && len2 <= std::numeric_limits<float>::max()) {
      nrm = grad * (-1.0f / std::sqrt(len2));
    } else {
      glm::dvec3 g = share ? GridGradient<double>(at) : t.g;
      if (share && glm::dot(g, g) == 0) g = CornerGradient<double>(at);
      nrm = UnitNormal(g);
    }
    return StoreVertex(pw, nrm, mid2, key, share);
  }

  // Appends a vertex; a shared one on the subtree root's faces is noted for the join.
  uint32_t StoreVertex(const glm::vec3& pw, const glm::vec3& nrm, PackedPoint mid2, uint64_t key,
                       bool share) {
    const uint32_t fresh = out_->vertices;
    float* p = out_->positions.Extend(3);
    p[0] = pw.x, p[1] = pw.y, p[2] = pw.z;
    float* q = out_->normals.Extend(3);
    q[0] = nrm.x, q[1] = nrm.y, q[2] = nrm.z;
    ++out_->vertices;
    if (share && faces_.EdgeOnFace(Unpack(mid2))) out_->boundary.push_back({fresh, key});
    return fresh;
  }

  // Out of line: most lookups hit, and the hit path stays small enough to inline.
  __attribute__((noinline)) uint32_t NewVertex(const Node& t, int ia, int ib, int s,
                                               PackedPoint mid2, uint64_t key,
                                               const glm::dvec3* placed) {
    const bool share = c_.normals == NormalMode::kSmooth;
    glm::ivec3 a = Unpack(t.v[ia]), b = Unpack(t.v[ib]), d;
    float fa = t.f[ia], fb = t.f[ib];
    OrientEdge(a, b, fa, fb, d);
    const float tt = CrossingParameter(c_.iso[s], fa, fb);
    const glm::vec3 pw = placed != nullptr ? glm::vec3(*placed) : CrossingWorld(c_, a, d, tt);
    glm::vec3 grad;
    if (share) {
      grad = glm::mix(GridGradient(a), GridGradient(b), tt);
      if (glm::dot(grad, grad) == 0) grad = VanishedGradient<float>(a, b, fa, fb);
    } else {
      grad = glm::vec3(t.g);
    }
    grad *= c_.inv_spacing;
    const float len2 = glm::dot(grad, grad);
    const glm::vec3 nrm =
        len2 >= std::numeric_limits<float>::min() && len2 <= std::numeric_limits<float>::max()
            ? grad * (-1.0f / std::sqrt(len2))
            : NormalInDouble(t, a, b, fa, fb, tt, share);
    return StoreVertex(pw, nrm, mid2, key, share);
  }

  // The normal when the float gradient's squared length leaves the normal float range (samples
  // near FLT_MAX overflow it; tiny gradients, below ~1e-19 per world unit, underflow it): the
  // same gradient in double, (0, 0, 0) only where the data are flat.
  __attribute__((noinline)) glm::vec3 NormalInDouble(const Node& t, const glm::ivec3& a,
                                                     const glm::ivec3& b, float fa, float fb,
                                                     float tt, bool share) const {
    glm::dvec3 g;
    if (share) {
      g = glm::mix(GridGradient<double>(a), GridGradient<double>(b), double(tt));
      if (glm::dot(g, g) == 0) g = VanishedGradient<double>(a, b, fa, fb);
    } else {
      g = t.g;  // set for every leaf when normals are flat (a block leaf's only then)
    }
    return UnitNormal(g);
  }

  // The unit normal of grid-space gradient g, computed without overflow; (0, 0, 0) where g is
  // zero or not finite.
  glm::vec3 UnitNormal(glm::dvec3 g) const {
    g /= c_.xf.spacing;
    const double scale = std::max({std::abs(g.x), std::abs(g.y), std::abs(g.z)});
    if (!(scale > 0) || !std::isfinite(scale)) return glm::vec3(0.0f);
    g /= scale;  // no overflow in the squares below
    return glm::vec3(g * (-1.0 / std::sqrt(glm::dot(g, g))));
  }

  // A shared edge vertex's gradient where central differences blend to zero (flat data, such
  // as a terrace at the isovalue): from its edge (a to b) alone, so that whichever tetrahedron
  // makes the vertex, in whatever view, makes the same normal (the making leaf's gradient made
  // normals depend on the view). Out of line: rare, and inlined it cost the vertex path ~25
  // instructions.
  template <typename T>
  __attribute__((noinline)) glm::vec<3, T> VanishedGradient(const glm::ivec3& a,
                                                            const glm::ivec3& b, float fa,
                                                            float fb) const {
    return FlatDataGradient(GridGradient<T>(a), GridGradient<T>(b), b - a, fa, fb);
  }

  // An edge's part of VanishedGradient: both ends' differences if they do not cancel, else the
  // edge's own slope, never zero on a crossed edge (d from a to b, fa != fb).
  template <typename T>
  static glm::vec<3, T> FlatDataGradient(const glm::vec<3, T>& ga, const glm::vec<3, T>& gb,
                                         const glm::ivec3& d, float fa, float fb) {
    const glm::vec<3, T> sum = ga + gb;
    if (glm::dot(sum, sum) != 0) return sum;
    const glm::vec<3, T> dir(d);
    return (T(fb) - T(fa)) / glm::dot(dir, dir) * dir;
  }

  // A corner vertex's gradient where its central differences vanish (inside a terrace): the
  // differences to its 26 neighbours at distances 1, 2, 4, ... until some differ (then one-sided
  // ones, where they cancel at every distance). From the corner alone, so that every edge
  // through it, in every view, gives it the same normal.
  template <typename T>
  glm::vec<3, T> CornerGradient(const glm::ivec3& p) const {
    const int last = c_.n - 1;
    const T fp = F<T>(c_.ValueOffset(p));
    for (int r = 1; r <= last; r *= 2) {
      glm::vec<3, T> g(0);
      for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            if (dx == 0 && dy == 0 && dz == 0) continue;
            const glm::ivec3 o(dx, dy, dz);
            const glm::ivec3 q = glm::clamp(p + r * o, glm::ivec3(0), glm::ivec3(last));
            const glm::vec<3, T> u(o);
            g += (F<T>(c_.ValueOffset(q)) - fp) / glm::dot(u, u) * u;
          }
      if (glm::dot(g, g) != 0) return g;
    }
    // Symmetric about the corner at every distance (the apex of |x| + |y| - |z|): the
    // differences to its forward neighbours, else its backward ones.
    for (const int side : {1, -1}) {
      glm::vec<3, T> g(0);
      for (int a = 0; a < 3; ++a) {
        glm::ivec3 q = p;
        q[a] = std::clamp(q[a] + side, 0, last);
        g[a] = T(side) * (F<T>(c_.ValueOffset(q)) - fp);
      }
      if (glm::dot(g, g) != 0) return g;
    }
    return glm::vec<3, T>(0);
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

  // A leaf that straddles the data box: keeps the part of the triangle inside it (ClipToDataBox)
  // and returns how many triangles that is. Out of line: rare, and its polygon buffers would
  // otherwise enlarge every leaf's frame.
  __attribute__((noinline)) int ClipTriangle(uint32_t a, uint32_t b, uint32_t d, uint8_t surface) {
    ClipVertex poly[9];
    const uint32_t ids[3] = {a, b, d};
    for (int i = 0; i < 3; ++i) {
      const float* q = &out_->normals[3 * size_t(ids[i])];
      const float* p = &out_->positions[3 * size_t(ids[i])];
      poly[i] = {glm::vec3(p[0], p[1], p[2]), glm::dvec3(q[0], q[1], q[2]), ids[i]};
    }
    const int count = ClipToDataBox(c_, poly, 3);
    out_->maybe_unused = true;
    const bool share = c_.normals == NormalMode::kSmooth;
    for (int i = 0; i < count; ++i) {
      if (poly[i].id != EdgeVertexTable::kMissing) continue;
      const ClipVertexKey key = ClipVertexKey::Of(poly[i].p, surface);
      if (share) {
        const auto [at, made] = out_->clip_ids.try_emplace(key, out_->vertices);
        if (!made) {
          poly[i].id = at->second;  // a triangle beside this one made it
          continue;
        }
        out_->clipped.push_back({out_->vertices, key});
      }
      poly[i].id = out_->vertices++;
      float* p = out_->positions.Extend(3);
      p[0] = poly[i].p.x, p[1] = poly[i].p.y, p[2] = poly[i].p.z;
      const glm::vec3 n = share ? ClipNormal(poly[i].p, poly[i].n) : glm::vec3(poly[i].n);
      float* q = out_->normals.Extend(3);
      q[0] = n.x, q[1] = n.y, q[2] = n.z;
    }
    int emitted = 0;
    for (int i = 1; i + 1 < count; ++i) {
      if (!FanTriangleEmitted(poly, i)) continue;
      uint32_t* out = out_->triangles.Extend(3);
      out[0] = poly[0].id, out[1] = poly[i].id, out[2] = poly[i + 1].id;
      out_->surface.Push(surface);
      ++emitted;
    }
    return emitted;
  }

  // The smooth normal of a vertex made by clipping, from its position alone: the grid's central
  // differences blended trilinearly over the cell holding it. Two triangles can make one such
  // vertex from different edges (a surface crossing an edge of the box, cut there by both its
  // faces), and blending along each edge gave each its own normal, so the triangle drawn first
  // would decide it. Where the differences cancel (flat data): `along`, the blend along the
  // clipped edge.
  glm::vec3 ClipNormal(const glm::vec3& pw, const glm::dvec3& along) const {
    const glm::dvec3 g = (glm::dvec3(pw) - c_.xf.origin) / c_.xf.spacing;
    const int last = c_.n - 1;
    glm::ivec3 cell;
    glm::dvec3 w;
    for (int a = 0; a < 3; ++a) {
      cell[a] = std::clamp(int(std::floor(g[a])), 0, last - 1);
      w[a] = std::clamp(g[a] - cell[a], 0.0, 1.0);
    }
    glm::dvec3 sum(0.0);
    for (int corner = 0; corner < 8; ++corner) {
      const glm::ivec3 o(corner & 1, (corner >> 1) & 1, corner >> 2);
      const double weight = (o.x ? w.x : 1 - w.x) * (o.y ? w.y : 1 - w.y) * (o.z ? w.z : 1 - w.z);
      if (weight != 0) sum += weight * GridGradient<double>(cell + o);
    }
    const glm::vec3 n = UnitNormal(sum);
    return n == glm::vec3(0.0f) ? glm::vec3(along) : n;
  }

  const Context& c_;
  EdgeVertexTable* table_;
  SubtreeMesh* out_;
  CutPart* cut_;
  RootFaces faces_{TetVertices{}};
  GradientFn lazy_ = nullptr;  // set during Leaf for a node without its gradient
  const void* lazy_state_ = nullptr;
};

}  // namespace isostream::extract_internal
