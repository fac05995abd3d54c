// Marching tetrahedra cases, computed once by code: for each set of corners with f >= iso,
// the tetrahedron edges the surface crosses, in the order the triangles are built from, and
// whether the winding must be flipped so that the geometric normal points to decreasing f.
//
// The winding depends only on the case and on the orientation of the tetrahedron's vertex
// order (sign of det(v1 - v0, v2 - v0, v3 - v0)): every crossing lies on its edge between the
// same two corners, so moving it along the edge never turns the triangle over. One class of
// the hierarchy always has the same orientation, so the traversal looks the flip up instead
// of testing a cross product against the gradient per triangle.
#pragma once

#include <array>
#include <cstdint>
#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>
#include <glm/vec3.hpp>
#include <utility>

namespace isostream {

struct MarchingTetsCase {
  uint8_t edge_count = 0;         // 0 (no crossing), 3 (triangle) or 4 (quad, in cyclic order)
  uint8_t edge[4][2] = {};        // corner pairs (the lone corner first, in a triangle's case)
  bool flip[2] = {false, false};  // [0]: positively oriented tetrahedron, [1]: negatively
};

class MarchingTets {
 public:
  static const MarchingTets& Get() {
    static const MarchingTets table;
    return table;
  }
  // mask bit i: corner i has f >= iso.
  const MarchingTetsCase& operator[](unsigned mask) const { return cases_[mask]; }

 private:
  MarchingTets() {
    for (unsigned mask = 1; mask < 15; ++mask) {
      MarchingTetsCase& mc = cases_[mask];
      int inside[4], outside[4], ni = 0, no = 0;
      for (int i = 0; i < 4; ++i) ((mask >> i) & 1 ? inside[ni++] : outside[no++]) = i;
      auto set = [&](int e, int a, int b) {
        mc.edge[e][0] = uint8_t(a);
        mc.edge[e][1] = uint8_t(b);
      };
      if (ni == 1 || no == 1) {
        const int lone = ni == 1 ? inside[0] : outside[0];
        const int* others = ni == 1 ? outside : inside;
        for (int i = 0; i < 3; ++i) set(i, lone, others[i]);
        mc.edge_count = 3;
      } else {
        set(0, inside[0], outside[0]);
        set(1, inside[0], outside[1]);
        set(2, inside[1], outside[1]);
        set(3, inside[1], outside[0]);
        mc.edge_count = 4;
      }
      for (int o = 0; o < 2; ++o) mc.flip[o] = NeedsFlip(mask, mc, o == 1);
    }
  }

  // Decides the flip on a unit tetrahedron of the given orientation, with f = 1 on the
  // inside corners and 0 elsewhere, crossings at the edge midpoints.
  static bool NeedsFlip(unsigned mask, const MarchingTetsCase& mc, bool negative) {
    std::array<glm::dvec3, 4> v = {glm::dvec3(0, 0, 0), glm::dvec3(1, 0, 0), glm::dvec3(0, 1, 0),
                                   glm::dvec3(0, 0, 1)};
    if (negative) std::swap(v[1], v[2]);
    double f[4];
    for (int i = 0; i < 4; ++i) f[i] = (mask >> i) & 1 ? 1.0 : 0.0;
    const glm::dmat3 e(v[1] - v[0], v[2] - v[0], v[3] - v[0]);
    const glm::dvec3 g =
        glm::inverse(glm::transpose(e)) * glm::dvec3(f[1] - f[0], f[2] - f[0], f[3] - f[0]);
    glm::dvec3 p[3];
    for (int i = 0; i < 3; ++i) p[i] = 0.5 * (v[mc.edge[i][0]] + v[mc.edge[i][1]]);
    return glm::dot(glm::cross(p[1] - p[0], p[2] - p[0]), g) > 0;
  }

  std::array<MarchingTetsCase, 16> cases_{};
};

}  // namespace isostream
