// The reference tetrahedra of the tetrahedral bisection hierarchy (Gerstner §3, §4.2, §5).
//
// The domain cube is split into the 6 Kuhn tetrahedra around its main diagonal; each
// tetrahedron is bisected at the midpoint of its unique longest edge (Maubach's rule produces
// the same edges). Up to translation and scale there are 72 shapes, 24 for each level mod 3.
// Everything here (vertices, child map, separating planes, gradient-update vectors, the order of
// the initial tetrahedra) is computed once by code from that definition, never typed in.
#pragma once

#include <array>
#include <cstdint>
#include <glm/vec3.hpp>
#include <vector>

namespace isostream {

// Id of a reference tetrahedron (its shape class). Not interchangeable with other integers.
struct TetClass {
  uint8_t value = 0xff;
  constexpr bool operator==(TetClass o) const { return value == o.value; }
  constexpr bool operator!=(TetClass o) const { return value != o.value; }
  constexpr bool valid() const { return value != 0xff; }
};
inline constexpr TetClass kInvalidTetClass{};
inline constexpr int kNumTetClasses = 72;
inline constexpr int kNumInitialTets = 6;

// Index into the 5 points of a bisection: the parent's 4 vertices, then its refinement vertex.
inline constexpr int kRefinementPoint = 4;

struct ReferenceTet {
  // Canonical vertex order; the refinement edge is (vertex[0], vertex[3]). Coordinates are
  // normalised: translated so the bounding box starts at 0, in units of half the box's largest
  // extent, so every coordinate is 0, 1 or 2.
  std::array<glm::ivec3, 4> vertex;
  int level_mod3 = 0;  // 0: refinement edge is a cube diagonal, 1: a face diagonal, 2: a cube edge
  // The canonical vertex order is left-handed: (v1 - v0, v2 - v0, v3 - v0) has a negative
  // determinant, so faces wound by vertex order face the other way.
  bool left_handed = false;
  // child[0] holds vertex[0], child[1] holds vertex[3]. child_point[c][i] says which of the
  // parent's 5 bisection points (0..3 vertices, 4 = refinement vertex) is the child's
  // canonical vertex i.
  std::array<TetClass, 2> child;
  std::array<std::array<uint8_t, 4>, 2> child_point;
  // Unit normal of the separating plane (through the refinement vertex, vertex[1], vertex[2]),
  // pointing into child[0]. child[0] is drawn first iff the eye is on child[1]'s side.
  glm::dvec3 plane_normal{0.0};
  // The same normal as small integers (entries 0 or +-1, a positive multiple of plane_normal):
  // the extractor tests the eye's side against a grid point with an exact integer dot product.
  std::array<int8_t, 3> plane_normal_int{0, 0, 0};
  // §5: gradient of child c = parent gradient + wavelet * gradient_update[c] / unit, where
  // wavelet = f(refinement vertex) - (f(vertex[0]) + f(vertex[3])) / 2 and unit is the real
  // length of one normalised coordinate step (half the tet's largest extent).
  std::array<glm::dvec3, 2> gradient_update{glm::dvec3(0.0), glm::dvec3(0.0)};
};

class ReferenceTets {
 public:
  // The tables, built on first use (thread-safe).
  static const ReferenceTets& Get();

  const ReferenceTet& operator[](TetClass c) const { return tets_[c.value]; }
  const std::vector<ReferenceTet>& all() const { return tets_; }
  // The classes at Kuhn levels (level_mod3 == 0, 24 of them): the roots of three-level blocks.
  const std::vector<TetClass>& kuhn_classes() const { return kuhn_classes_; }

  // The 6 initial tetrahedra of the domain cube: class and the cube corners (0 or 1 per axis)
  // of its canonical vertices.
  TetClass initial_class(int i) const { return initial_[i]; }

  // Writes the initial tetrahedra (indices 0..5) in back-to-front order for an eye at `eye`
  // (perspective, eye in the cube's own coordinates scaled to [0,1]^3) or, when `orthographic`,
  // for a viewing direction `eye` (from the eye into the scene). Exact: it walks a BSP tree over
  // the planes the 6 tetrahedra share.
  void InitialOrder(const glm::dvec3& eye, bool orthographic, int out[kNumInitialTets]) const;

  // Finds the class of a tetrahedron given by its 4 vertices (any order, any translation and
  // power-of-two scale) and returns the permutation perm with vertices[perm[i]] == canonical
  // vertex i. Returns kInvalidTetClass for a shape that is not in the hierarchy.
  TetClass Classify(const std::array<glm::ivec3, 4>& vertices, std::array<int, 4>* perm) const;

 private:
  ReferenceTets();
  struct BspNode {
    glm::dvec3 normal;  // plane through the cube's main diagonal
    int front = -1;     // child on the normal's side: node index, or ~initial tet index
    int back = -1;
  };
  void Walk(int node, const glm::dvec3& eye, bool orthographic, int* out, int* count) const;

  std::vector<ReferenceTet> tets_;
  std::vector<TetClass> kuhn_classes_;
  std::array<TetClass, kNumInitialTets> initial_{};
  std::array<std::array<glm::ivec3, 4>, kNumInitialTets> initial_vertices_{};
  std::vector<BspNode> bsp_;
  int bsp_root_ = -1;
};

}  // namespace isostream
