// Builds the reference-tetrahedron tables from first principles (Gerstner §4.1, §4.2, §5).
//
// Steps: (1) the 6 Kuhn tetrahedra of a cube; (2) bisect each known class at its unique
// longest edge until no new shape appears; (3) per class, the separating plane and the
// gradient-update vectors from the barycentric gradients; (4) a BSP tree over the planes shared
// by the initial tetrahedra, so their back-to-front order is exact for any eye.
#include "server/hierarchy/reference_tets.h"

#include <algorithm>
#include <cstdlib>
#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>
#include <map>
#include <numeric>
#include <stdexcept>

namespace isostream {
namespace {

using Verts = std::array<glm::ivec3, 4>;
using Key = std::array<int, 12>;

bool LexLess(const glm::ivec3& a, const glm::ivec3& b) {
  if (a.x != b.x) return a.x < b.x;
  if (a.y != b.y) return a.y < b.y;
  return a.z < b.z;
}

int SquaredLength(const glm::ivec3& v) { return v.x * v.x + v.y * v.y + v.z * v.z; }

// Translates to the bounding-box corner and divides by half the largest extent. The caller
// passes coordinates scaled so the division is exact; anything else is not a hierarchy shape.
bool Normalise(const Verts& v, Verts* out) {
  glm::ivec3 lo = v[0], hi = v[0];
  for (const auto& p : v) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  const glm::ivec3 extent = hi - lo;
  const int e = std::max({extent.x, extent.y, extent.z});
  if (e <= 0 || e % 2 != 0) return false;
  const int unit = e / 2;
  for (int i = 0; i < 4; ++i) {
    const glm::ivec3 d = v[i] - lo;
    if (d.x % unit || d.y % unit || d.z % unit) return false;
    (*out)[i] = d / unit;
  }
  return true;
}

Key SortedKey(Verts v) {
  std::sort(v.begin(), v.end(), LexLess);
  Key k{};
  for (int i = 0; i < 4; ++i)
    for (int a = 0; a < 3; ++a) k[i * 3 + a] = v[i][a];
  return k;
}

// Canonical order: longest edge (a, d) with a lexicographically before d; b, c in between,
// lexicographically sorted. Throws if the longest edge is not unique (it always is here).
Verts CanonicalOrder(const Verts& v) {
  int best = -1, best_i = 0, best_j = 0, ties = 0;
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j) {
      const int l = SquaredLength(v[i] - v[j]);
      if (l > best) {
        best = l, best_i = i, best_j = j, ties = 0;
      } else if (l == best) {
        ++ties;
      }
    }
  if (ties) throw std::logic_error("reference tetrahedron with two longest edges");
  glm::ivec3 a = v[best_i], d = v[best_j];
  if (LexLess(d, a)) std::swap(a, d);
  std::array<glm::ivec3, 2> mid;
  int m = 0;
  for (int i = 0; i < 4; ++i)
    if (i != best_i && i != best_j) mid[m++] = v[i];
  if (LexLess(mid[1], mid[0])) std::swap(mid[0], mid[1]);
  return {a, mid[0], mid[1], d};
}

int LevelMod3(const Verts& canonical) {
  const glm::ivec3 e = glm::abs(canonical[3] - canonical[0]);
  const int nonzero = (e.x != 0) + (e.y != 0) + (e.z != 0);
  return 3 - nonzero;  // 3 axes: cube diagonal (0), 2: face diagonal (1), 1: edge (2)
}

}  // namespace

const ReferenceTets& ReferenceTets::Get() {
  static const ReferenceTets tables;
  return tables;
}

TetClass ReferenceTets::Classify(const Verts& vertices, std::array<int, 4>* perm) const {
  Verts norm;
  if (!Normalise(vertices, &norm)) {
    // Shapes whose half-extent is odd (the finest level seen at scale 1) normalise at scale 2.
    Verts doubled;
    for (int i = 0; i < 4; ++i) doubled[i] = vertices[i] * 2;
    if (!Normalise(doubled, &norm)) return kInvalidTetClass;
  }
  const Key key = SortedKey(norm);
  for (size_t c = 0; c < tets_.size(); ++c) {
    if (SortedKey(tets_[c].vertex) != key) continue;
    if (perm) {
      for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
          if (norm[j] == tets_[c].vertex[i]) (*perm)[i] = j;
    }
    return TetClass{static_cast<uint8_t>(c)};
  }
  return kInvalidTetClass;
}

ReferenceTets::ReferenceTets() {
  // (1) The 6 Kuhn tetrahedra of the cube [0,2]^3 around the diagonal (0,0,0)-(2,2,2).
  int axes[3] = {0, 1, 2};
  int initial = 0;
  std::map<Key, int> index;
  auto add_class = [&](const Verts& normalised) {
    const Key key = SortedKey(normalised);
    auto it = index.find(key);
    if (it != index.end()) return it->second;
    ReferenceTet t;
    t.vertex = CanonicalOrder(normalised);
    t.level_mod3 = LevelMod3(t.vertex);
    tets_.push_back(t);
    return index[key] = static_cast<int>(tets_.size()) - 1;
  };
  do {
    Verts v;
    glm::ivec3 p(0);
    v[0] = p;
    for (int i = 0; i < 3; ++i) {
      p[axes[i]] = 2;
      v[i + 1] = p;
    }
    const int c = add_class(v);
    initial_[initial] = TetClass{static_cast<uint8_t>(c)};
    initial_vertices_[initial] = tets_[c].vertex;
    ++initial;
  } while (std::next_permutation(axes, axes + 3));

  // (2) Bisect every class until closure. Work at scale 2 so midpoints stay integer.
  for (size_t c = 0; c < tets_.size(); ++c) {
    std::array<glm::ivec3, 5> points;
    for (int i = 0; i < 4; ++i) points[i] = tets_[c].vertex[i] * 2;
    points[kRefinementPoint] = (points[0] + points[3]) / 2;
    const std::array<std::array<int, 4>, 2> members = {
        {{0, 1, 2, kRefinementPoint}, {kRefinementPoint, 1, 2, 3}}};
    for (int k = 0; k < 2; ++k) {
      Verts child;
      for (int i = 0; i < 4; ++i) child[i] = points[members[k][i]];
      Verts norm;
      if (!Normalise(child, &norm)) throw std::logic_error("child does not normalise");
      const int cc = add_class(norm);
      tets_[c].child[k] = TetClass{static_cast<uint8_t>(cc)};
      // Map the child's canonical vertices back to the parent's bisection points.
      for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
          if (norm[j] == tets_[cc].vertex[i])
            tets_[c].child_point[k][i] = static_cast<uint8_t>(members[k][j]);
    }
  }
  if (tets_.size() != kNumTetClasses)
    throw std::logic_error("bisection closure did not give 72 reference tetrahedra");

  // (3) Separating planes and gradient-update vectors, in normalised coordinates.
  for (auto& t : tets_) {
    const glm::dvec3 p0(t.vertex[0]), p1(t.vertex[1]), p2(t.vertex[2]), p3(t.vertex[3]);
    const glm::dvec3 mid = (p0 + p3) * 0.5;
    glm::dvec3 n = glm::cross(p1 - mid, p2 - mid);
    if (glm::dot(n, p0 - mid) < 0) n = -n;
    t.plane_normal = glm::normalize(n);
    {
      // In doubled coordinates the midpoint is a grid point and the cross product integral.
      const glm::ivec3 m2 = t.vertex[0] + t.vertex[3];
      const glm::ivec3 a = 2 * t.vertex[1] - m2, b = 2 * t.vertex[2] - m2;
      glm::ivec3 ni(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
      ni /= std::gcd(std::gcd(std::abs(ni.x), std::abs(ni.y)), std::abs(ni.z));
      if (glm::dot(glm::dvec3(ni), n) < 0) ni = -ni;
      for (int a2 = 0; a2 < 3; ++a2) t.plane_normal_int[a2] = static_cast<int8_t>(ni[a2]);
    }
    // Rows of E^-1 are the gradients of barycentric coordinates 1..3; lambda_0 = 1 - rest.
    const glm::dmat3 edges(p1 - p0, p2 - p0, p3 - p0);  // columns
    t.left_handed = glm::determinant(edges) < 0;
    const glm::dmat3 inv_t = glm::transpose(glm::inverse(edges));
    const glm::dvec3 grad3 = inv_t[2];
    const glm::dvec3 grad0 = -(inv_t[0] + inv_t[1] + inv_t[2]);
    // Child 0 replaces vertex 3 by the midpoint: its hat at the midpoint is 2*lambda_3.
    t.gradient_update[0] = 2.0 * grad3;
    t.gradient_update[1] = 2.0 * grad0;
  }

  for (size_t c = 0; c < tets_.size(); ++c)
    if (tets_[c].level_mod3 == 0) kuhn_classes_.push_back(TetClass{static_cast<uint8_t>(c)});

  // (4) BSP over the faces the initial tetrahedra share: all are planes through the diagonal.
  std::vector<glm::dvec3> planes;
  for (int a = 0; a < kNumInitialTets; ++a)
    for (int b = a + 1; b < kNumInitialTets; ++b) {
      std::vector<glm::ivec3> shared;
      for (const auto& p : initial_vertices_[a])
        for (const auto& q : initial_vertices_[b])
          if (p == q) shared.push_back(p);
      if (shared.size() != 3) continue;
      glm::dvec3 n =
          glm::cross(glm::dvec3(shared[1] - shared[0]), glm::dvec3(shared[2] - shared[0]));
      n = glm::normalize(n);
      bool known = false;
      for (const auto& m : planes) known |= std::abs(std::abs(glm::dot(m, n)) - 1.0) < 1e-12;
      if (!known) planes.push_back(n);
    }
  // Side of a whole tetrahedron: +1, -1, or 0 if it straddles. Planes pass through the origin.
  auto side = [&](const glm::dvec3& n, int tet) {
    int pos = 0, neg = 0;
    for (const auto& v : initial_vertices_[tet]) {
      const double s = glm::dot(n, glm::dvec3(v));
      pos += s > 1e-12;
      neg += s < -1e-12;
    }
    return pos && neg ? 0 : (pos ? 1 : -1);
  };
  struct Builder {
    ReferenceTets* self;
    const std::vector<glm::dvec3>& planes;
    decltype(side)& side_of;
    int Build(const std::vector<int>& set) {
      if (set.size() == 1) return ~set[0];
      for (const auto& n : planes) {
        std::vector<int> front, back;
        bool straddles = false;
        for (int t : set) {
          const int s = side_of(n, t);
          straddles |= s == 0;
          (s > 0 ? front : back).push_back(t);
        }
        if (straddles || front.empty() || back.empty()) continue;
        const int f = Build(front), b = Build(back);
        self->bsp_.push_back({n, f, b});
        return static_cast<int>(self->bsp_.size()) - 1;
      }
      throw std::logic_error("initial tetrahedra admit no BSP over their shared planes");
    }
  } builder{this, planes, side};
  bsp_root_ = builder.Build({0, 1, 2, 3, 4, 5});
}

void ReferenceTets::Walk(int node, const glm::dvec3& eye, bool orthographic, int* out,
                         int* count) const {
  if (node < 0) {
    out[(*count)++] = ~node;
    return;
  }
  const BspNode& b = bsp_[node];
  // The plane passes through the origin of the cube's coordinates.
  const double s = orthographic ? -glm::dot(b.normal, eye) : glm::dot(b.normal, eye);
  if (s > 0) {  // eye in front: the back side is farther
    Walk(b.back, eye, orthographic, out, count);
    Walk(b.front, eye, orthographic, out, count);
  } else {
    Walk(b.front, eye, orthographic, out, count);
    Walk(b.back, eye, orthographic, out, count);
  }
}

void ReferenceTets::InitialOrder(const glm::dvec3& eye, bool orthographic,
                                 int out[kNumInitialTets]) const {
  int count = 0;
  Walk(bsp_root_, eye, orthographic, out, &count);
}

}  // namespace isostream
