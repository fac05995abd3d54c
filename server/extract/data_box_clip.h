// Where the surface meets the data box of a volume smaller than the hierarchy's cube: the
// crossing points as the emitter stores them, the quad diagonal, and the clipping of a
// straddling leaf's triangles at the box. The emitting and the counting passes share these, so
// a count (budget search, count curves) is the number of triangles the emitter appends.
// Private to server/extract.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>
#include <utility>

#include "server/extract/edge_vertex_table.h"
#include "server/extract/marching_tets.h"
#include "server/extract/tree_node.h"

namespace isostream::extract_internal {

// The parts of a crossing of iso on an edge, shared by LeafEmitter::NewVertex and the counts.
// The edge is taken from its lexicographically smaller end, so every tetrahedron around it
// makes the same bits: OrientEdge swaps the ends (a, b, their values) if needed and gives
// d = b - a.
inline void OrientEdge(glm::ivec3& a, glm::ivec3& b, float& fa, float& fb, glm::ivec3& d) {
  d = b - a;
  if ((d.x != 0 ? d.x : d.y != 0 ? d.y : d.z) < 0) {
    std::swap(a, b);
    std::swap(fa, fb);
    d = -d;
  }
}
// The parameter in double (float differences of values near FLT_MAX overflow), the point in
// single precision: a grid coordinate below 2^13 keeps ~1e-3 voxel in its last bit, far below
// the codec's quantization step.
inline float CrossingParameter(float iso, float fa, float fb) {
  return float((double(iso) - fa) / (double(fb) - fa));
}
inline glm::vec3 CrossingWorld(const Context& c, const glm::ivec3& a, const glm::ivec3& d,
                               float t) {
  return c.world_origin + c.world_spacing * (glm::vec3(a) + t * glm::vec3(d));
}

// Context::snap_tau. A crossing at parameter t on an edge from grid point a along d is stored as
// o + s (a + t d) in single precision, and its end a as o + s a. On an axis x with |d_x| >= 1
// (every edge has one), with coordinates in [0, last], the roundings between the two move
// their difference s t d_x by at most 2^-24 (5 last |s| + 2 |o|), so both round alike only if
// t <= 2^-24 (5 last + 2 |o| / |s|) (plus a little for t's own rounding); for the far end b,
// 1 - t <= 2^-24 (7 last + 2 |o| / |s| + 1). The bound below adds a margin for the float
// arithmetic of CornersNearIso. An origin far from the grid, or a spacing that underflowed,
// makes it large: more components take the exact path, which is right, only slower.
inline float SnapTau(const glm::vec3& origin, const glm::vec3& spacing, int last) {
  double tau = 0;
  for (int a = 0; a < 3; ++a) {
    const double ratio = double(std::abs(origin[a])) / double(std::abs(spacing[a]));
    const double bound = 9.0 * last + 3.0 * (std::isfinite(ratio) ? ratio : 1e30) + 2.0;
    tau = std::max(tau, std::ldexp(bound, -24));
  }
  return float(std::min(tau, 1e30));
}

// The stored position of the crossing on edge (va, vb).
inline glm::vec3 EdgeCrossingWorld(const Context& c, PackedPoint va, PackedPoint vb, float fa,
                                   float fb, float iso) {
  glm::ivec3 a = Unpack(va), b = Unpack(vb), d;
  OrientEdge(a, b, fa, fb, d);
  return CrossingWorld(c, a, d, CrossingParameter(iso, fa, fb));
}

// The stored position of a crossing on a grid point (its value is the isovalue).
inline glm::vec3 CornerWorld(const Context& c, PackedPoint v) {
  return c.world_origin + c.world_spacing * glm::vec3(Unpack(v));
}

// A quad is split along its shorter diagonal (better triangles); equal lengths are broken by
// position, so the choice does not depend on the tetrahedron's vertex order.
__attribute__((always_inline)) inline bool QuadSplitsAlong13(const glm::dvec3 p[4]) {
  const double d02 = glm::dot(p[2] - p[0], p[2] - p[0]), d13 = glm::dot(p[3] - p[1], p[3] - p[1]);
  if (d02 != d13) return d13 < d02;
  auto less = [](const glm::dvec3& a, const glm::dvec3& b) {
    return a.x != b.x ? a.x < b.x : a.y != b.y ? a.y < b.y : a.z < b.z;
  };
  const glm::dvec3 m02 = less(p[0], p[2]) ? p[0] : p[2], m13 = less(p[1], p[3]) ? p[1] : p[3];
  return less(m13, m02);
}

struct ClipVertex {
  glm::vec3 p;  // as stored, so the tests below see what the output holds
  glm::dvec3 n;
  uint32_t id;  // EdgeVertexTable::kMissing: made by the clip
};

// Clips the polygon poly[0..count) (room for 9) to the data box, in place; returns how many
// vertices are left (below 3: nothing). Positions and the box's faces are in single precision,
// as stored, so a vertex on a face is on it exactly: such a vertex is the crossing there, and no
// copy of it is made (a copy made a triangle without area).
inline int ClipToDataBox(const Context& c, ClipVertex* poly, int count) {
  ClipVertex next[9];
  for (int axis = 0; axis < 3; ++axis) {
    const float limit = c.world_origin[axis] + c.world_spacing[axis] * float(c.data_max[axis]);
    int m = 0;
    for (int i = 0; i < count; ++i) {
      const ClipVertex& p = poly[i];
      const ClipVertex& q = poly[(i + 1) % count];
      const bool pin = p.p[axis] <= limit, qin = q.p[axis] <= limit;
      if (pin) next[m++] = p;
      if (pin != qin && p.p[axis] != limit && q.p[axis] != limit) {
        // From the edge's ends in one order (inside end first), whichever way this polygon runs
        // along it: the triangle across the edge then makes the same bits (ClipVertexKey).
        const ClipVertex& a = pin ? p : q;
        const ClipVertex& b = pin ? q : p;
        const double s = (double(limit) - a.p[axis]) / (double(b.p[axis]) - a.p[axis]);
        ClipVertex& x = next[m++];
        x.p = glm::vec3(glm::mix(glm::dvec3(a.p), glm::dvec3(b.p), s));
        x.p[axis] = limit;
        // Opposite or zero (flat data) end normals blend to nothing: the inside end's then.
        const glm::dvec3 n = glm::mix(a.n, b.n, s);
        const double length = std::sqrt(glm::dot(n, n));
        x.n = length > 0 && std::isfinite(length) ? n / length : a.n;
        x.id = EdgeVertexTable::kMissing;
      }
    }
    count = m;
    for (int i = 0; i < m; ++i) poly[i] = next[i];
    if (count < 3) return 0;
  }
  return count;
}

// Whether the clipped polygon's fan triangle (0, i, i + 1) is emitted: a crossing can round onto
// another corner of the polygon (near a box edge), and a triangle with two corners in one
// place has no area.
inline bool FanTriangleEmitted(const ClipVertex* poly, int i) {
  return poly[0].p != poly[i].p && poly[i].p != poly[i + 1].p && poly[0].p != poly[i + 1].p;
}

// Triangles left of triangle (a, b, d) inside the data box.
inline int ClippedTriangleCount(const Context& c, const glm::vec3& a, const glm::vec3& b,
                                const glm::vec3& d) {
  ClipVertex poly[9];
  poly[0] = {a, glm::dvec3(0.0), 0};
  poly[1] = {b, glm::dvec3(0.0), 0};
  poly[2] = {d, glm::dvec3(0.0), 0};
  const int n = ClipToDataBox(c, poly, 3);
  int triangles = 0;
  for (int i = 1; i + 1 < n; ++i) triangles += FanTriangleEmitted(poly, i);
  return triangles;
}

// The corner (ia or ib) of leaf t that the crossing of iso on edge (ia, ib) is on, or -1: the
// edge's end whose value is the isovalue (its parameter is 0 or 1, its stored position the
// corner's). Decided by value, not by the stored position: a crossing that only rounds onto a
// corner is moved off it (OffTheEnds). Were it the corner's vertex, the corner's vertex would
// stand for some of its crossings and not others (those on edges with other value differences,
// or other rounding), and two vertices of one closed surface that no triangle joins could be
// made one: edges used by four triangles.
inline int CornerAtIso(const Node& t, int ia, int ib, float iso) {
  return t.f[ia] == iso ? ia : t.f[ib] == iso ? ib : -1;
}

// The stored position of a crossing q of edge (ia, ib) of leaf t that is on neither end (no end
// at the isovalue): a coordinate that rounded onto an end's, on an axis along which the edge
// runs, moves one float step towards the other end's. Left there, the crossing could be stored
// where the crossing of another edge from that end is: one float step above integer terraces,
// every coordinate rounds onto the corner (64% of the triangles had two vertices in one place);
// two steps above, ~5e-7 of an edge is kept on a small coordinate and lost on a larger one (46%).
// Moved, crossings of two edges from one corner differ on an axis along which one of the edges
// runs (the hierarchy's edges run along axes and face and body diagonals, from a corner into
// different directions), and no triangle loses its area. SnapTau's bound is per axis, so the
// components that need this take the exact path; the others have no such coordinate. Symmetric
// in the ends, so every tetrahedron around the edge moves alike.
inline glm::vec3 OffTheEnds(const Context& c, const Node& t, int ia, int ib, glm::vec3 q) {
  const glm::vec3 pa = CornerWorld(c, t.v[ia]), pb = CornerWorld(c, t.v[ib]);
  for (int a = 0; a < 3; ++a) {
    if (pa[a] == pb[a]) continue;  // the edge does not run along a (or a float step is longer)
    if (q[a] == pa[a])
      q[a] = std::nextafter(q[a], pb[a]);
    else if (q[a] == pb[a])
      q[a] = std::nextafter(q[a], pa[a]);
  }
  return q;
}

// The crossings of sorted isovalue s on tetrahedron t as LeafEmitter places them: on which
// corner each sits (CornerAtIso) or 4 + its edge, its stored position (OffTheEnds), and the
// fan's order (a quad rotated to split along its shorter diagonal). mc is the case of t for s,
// with crossings.
struct ComponentCrossings {
  int edges;
  int where[4];
  glm::dvec3 p[4];
  int cycle[4];  // the crossings in the fan's order

  // Out of line: the paths that need it are rare (corners near the isovalue, the data box).
  __attribute__((noinline))
  ComponentCrossings(const Context& c, const Node& t, int s, const MarchingTetsCase& mc)
      : edges(mc.edge_count), cycle{0, 1, 2, 3} {
    for (int i = 0; i < edges; ++i) {
      const int ia = mc.edge[i][0], ib = mc.edge[i][1];
      const glm::vec3 q = EdgeCrossingWorld(c, t.v[ia], t.v[ib], t.f[ia], t.f[ib], c.iso[s]);
      const int corner = CornerAtIso(t, ia, ib, c.iso[s]);
      where[i] = corner >= 0 ? corner : 4 + i;
      p[i] = glm::dvec3(corner >= 0 ? q : OffTheEnds(c, t, ia, ib, q));
    }
    if (edges == 4 && QuadSplitsAlong13(p)) std::rotate(cycle, cycle + 1, cycle + 4);
  }
  // Fan triangle (0, k, k + 1), as crossing indices.
  int Corner(int k) const { return cycle[k]; }
  // Two of its crossings on one corner leave it without an area: it is not emitted.
  bool HasArea(int k) const {
    const int a = where[cycle[0]], b = where[cycle[k]], d = where[cycle[k + 1]];
    return a != b && b != d && a != d;
  }
  // The triangles with an area: what the emitter appends for a leaf inside the data box.
  int Triangles() const {
    int n = 0;
    for (int k = 1; k + 1 < edges; ++k) n += HasArea(k);
    return n;
  }
};

// The triangles LeafEmitter::Component appends for sorted isovalue s on leaf t, a leaf that
// straddles the data box: the same crossings, diagonal and triangles without area dropped,
// each triangle clipped.
inline int StraddlingComponentTriangles(const Context& c, const Node& t, int s,
                                        const MarchingTetsCase& mc) {
  const ComponentCrossings x(c, t, s, mc);
  // In the emitter's corner order (its winding flip included): the clip's crossings are
  // computed along the polygon's edges, so the reversed triangle can differ in a last bit.
  const bool flip = mc.flip[c.negative[t.cls.value]];
  int n = 0;
  for (int k = 1; k + 1 < x.edges; ++k) {
    if (!x.HasArea(k)) continue;
    const glm::dvec3 &a = x.p[x.Corner(0)], &b = x.p[x.Corner(k)], &d = x.p[x.Corner(k + 1)];
    n += ClippedTriangleCount(c, glm::vec3(a), glm::vec3(flip ? d : b), glm::vec3(flip ? b : d));
  }
  return n;
}

}  // namespace isostream::extract_internal
