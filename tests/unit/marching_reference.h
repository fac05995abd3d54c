// Test helper: marching tetrahedra on one tetrahedron, written directly from the conventions
// the extractor documents, to compare its output with as a set of triangles: a vertex is inside
// when f >= iso; a crossing is interpolated from the lexicographically smaller endpoint
// (parameter in double, point in single precision), and a coordinate of a crossing whose
// endpoints' values are not the isovalue that has an endpoint's coordinate on an axis along
// which the edge runs moves one float step towards the other endpoint's; a quad is split along
// its shorter diagonal (ties broken by position); a triangle without an area (two crossings on a
// corner whose value is the isovalue) is left out.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>
#include <set>
#include <tuple>
#include <vector>

#include "shared/ordered_mesh.h"

namespace isostream::testing {

using TriKey = std::array<float, 10>;  // surface, then the 3 positions sorted

inline TriKey MakeKey(int surface, std::array<glm::vec3, 3> p) {
  std::sort(p.begin(), p.end(),
            [](auto& a, auto& b) { return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z); });
  return {float(surface), p[0].x, p[0].y, p[0].z, p[1].x, p[1].y, p[1].z, p[2].x, p[2].y, p[2].z};
}

// The triangles of a mesh as keys (world == grid coordinates in the tests that use this).
inline std::multiset<TriKey> MeshTriangles(const OrderedMesh& m) {
  std::multiset<TriKey> tris;
  for (size_t t = 0; t < m.triangle_count(); ++t) {
    std::array<glm::vec3, 3> p;
    for (int i = 0; i < 3; ++i) {
      const float* q = &m.positions[3 * size_t(m.triangles[3 * t + i])];
      p[i] = {q[0], q[1], q[2]};
    }
    tris.insert(MakeKey(m.surface[t], p));
  }
  return tris;
}

// Adds the triangles of tetrahedron (v, f) for every isovalue (surface = index in iso).
inline void MarchTet(const glm::ivec3 v[4], const float f[4], const std::vector<float>& iso,
                     std::multiset<TriKey>* tris) {
  auto add = [&](int s, const glm::vec3& a, const glm::vec3& b, const glm::vec3& c) {
    if (a != b && b != c && a != c) tris->insert(MakeKey(s, {a, b, c}));
  };
  for (size_t s = 0; s < iso.size(); ++s) {
    auto cross = [&](int i, int j) {
      glm::ivec3 a = v[i], b = v[j];
      float fa = f[i], fb = f[j];
      if (std::tie(b.x, b.y, b.z) < std::tie(a.x, a.y, a.z)) std::swap(a, b), std::swap(fa, fb);
      if (fa == iso[s]) return glm::vec3(a);
      if (fb == iso[s]) return glm::vec3(b);
      const float t = float((double(iso[s]) - fa) / (double(fb) - fa));
      glm::vec3 q = glm::vec3(a) + t * glm::vec3(b - a);
      for (int axis = 0; axis < 3; ++axis) {
        if (a[axis] == b[axis]) continue;
        if (q[axis] == float(a[axis]))
          q[axis] = std::nextafter(q[axis], float(b[axis]));
        else if (q[axis] == float(b[axis]))
          q[axis] = std::nextafter(q[axis], float(a[axis]));
      }
      return q;
    };
    std::vector<int> in, out;
    for (int i = 0; i < 4; ++i) (f[i] >= iso[s] ? in : out).push_back(i);
    if (in.empty() || out.empty()) continue;
    if (in.size() != 2) {
      const int lone = in.size() == 1 ? in[0] : out[0];
      const auto& rest = in.size() == 1 ? out : in;
      add(int(s), cross(lone, rest[0]), cross(lone, rest[1]), cross(lone, rest[2]));
      continue;
    }
    glm::vec3 q[4] = {cross(in[0], out[0]), cross(in[0], out[1]), cross(in[1], out[1]),
                      cross(in[1], out[0])};
    const glm::dvec3 p0(q[0]), p1(q[1]), p2(q[2]), p3(q[3]);
    const double d02 = glm::dot(p2 - p0, p2 - p0), d13 = glm::dot(p3 - p1, p3 - p1);
    auto less = [](const glm::vec3& a, const glm::vec3& b) {
      return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z);
    };
    bool along13 = d13 < d02;
    if (d02 == d13) along13 = less(less(q[1], q[3]) ? q[1] : q[3], less(q[0], q[2]) ? q[0] : q[2]);
    if (along13) std::rotate(q, q + 1, q + 4);
    add(int(s), q[0], q[1], q[2]);
    add(int(s), q[0], q[2], q[3]);
  }
}

}  // namespace isostream::testing
