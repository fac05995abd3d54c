// Nested spheres for the render tests and benchmark: icospheres (no poles, so no degenerate
// triangles) with exact sphere normals, and an exact painter's order for nested convex shells.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>
#include <map>
#include <numeric>
#include <utility>
#include <vector>

#include "client/render/camera.h"
#include "shared/ordered_mesh.h"

namespace isostream::render::testing {

struct Sphere {
  glm::vec3 center{0.0f};
  float radius = 1.0f;
  uint8_t surface = 0;
};

// Appends an icosphere with 20 * 4^subdivisions triangles, wound counter-clockwise seen from
// outside, to `mesh`.
inline void AppendIcosphere(const Sphere& sphere, int subdivisions, OrderedMesh* mesh) {
  const float t = (1.0f + std::sqrt(5.0f)) / 2.0f;
  std::vector<glm::vec3> unit = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                                 {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                                 {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  for (glm::vec3& v : unit) v = glm::normalize(v);
  std::vector<uint32_t> faces = {0, 11, 5,  0, 5,  1, 0, 1, 7, 0, 7,  10, 0, 10, 11, 1, 5, 9, 5, 11,
                                 4, 11, 10, 2, 10, 7, 6, 7, 1, 8, 3,  9,  4, 3,  4,  2, 3, 2, 6, 3,
                                 6, 8,  3,  8, 9,  4, 9, 5, 2, 4, 11, 6,  2, 10, 8,  6, 7, 9, 8, 1};
  for (int level = 0; level < subdivisions; ++level) {
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> midpoint;
    auto middle = [&](uint32_t a, uint32_t b) {
      const auto key = std::minmax(a, b);
      auto it = midpoint.find(key);
      if (it != midpoint.end()) return it->second;
      unit.push_back(glm::normalize(unit[a] + unit[b]));
      const uint32_t id = uint32_t(unit.size() - 1);
      midpoint.emplace(key, id);
      return id;
    };
    std::vector<uint32_t> finer;
    finer.reserve(4 * faces.size());
    for (size_t f = 0; f < faces.size(); f += 3) {
      const uint32_t a = faces[f], b = faces[f + 1], c = faces[f + 2];
      const uint32_t ab = middle(a, b), bc = middle(b, c), ca = middle(c, a);
      for (uint32_t v : {a, ab, ca, b, bc, ab, c, ca, bc, ab, bc, ca}) finer.push_back(v);
    }
    faces.swap(finer);
  }
  const uint32_t base = uint32_t(mesh->vertex_count());
  for (const glm::vec3& n : unit) {
    const glm::vec3 p = sphere.center + sphere.radius * n;
    mesh->positions.insert(mesh->positions.end(), {p.x, p.y, p.z});
    mesh->normals.insert(mesh->normals.end(), {n.x, n.y, n.z});
  }
  for (size_t f = 0; f < faces.size(); f += 3) {
    // Orient outwards explicitly rather than trusting the table's winding.
    const glm::vec3 a = unit[faces[f]], b = unit[faces[f + 1]], c = unit[faces[f + 2]];
    const bool outward = glm::dot(glm::cross(b - a, c - a), a + b + c) > 0.0f;
    const uint32_t i1 = outward ? faces[f + 1] : faces[f + 2];
    const uint32_t i2 = outward ? faces[f + 2] : faces[f + 1];
    mesh->triangles.insert(mesh->triangles.end(), {base + faces[f], base + i1, base + i2});
    mesh->surface.push_back(sphere.surface);
  }
}

inline OrderedMesh MakeSpheres(const std::vector<Sphere>& spheres, int subdivisions) {
  OrderedMesh mesh;
  for (const Sphere& s : spheres) AppendIcosphere(s, subdivisions, &mesh);
  return mesh;
}

// Reorders the triangles of closed convex shells into a back-to-front order for `camera`.
// Shells come in groups: group_of_surface[s] says which group surface s belongs to, and for this
// camera every group must lie wholly behind the groups with higher numbers (a plane separates
// them with the eye on the nearer side). Within a group the shells are nested, lower surface
// outside. A ray meets one group's shells as: outer front, ..., inner front, inner back, ...,
// outer back, and a convex shell's faces that look away from (or towards) the eye never overlap
// on screen, so drawing back faces outer to inner and then front faces inner to outer, group by
// group from the farthest, is an exact painter's order. "Front" is decided by each face's plane
// and the eye, as the rasterizer sees it.
inline void SortShellsBackToFront(const Camera& camera, const std::vector<int>& group_of_surface,
                                  OrderedMesh* mesh) {
  const size_t n = mesh->triangle_count();
  std::vector<int> key(n);
  for (size_t t = 0; t < n; ++t) {
    glm::vec3 p[3];
    for (int k = 0; k < 3; ++k) {
      const uint32_t v = mesh->triangles[3 * t + k];
      p[k] = {mesh->positions[3 * v], mesh->positions[3 * v + 1], mesh->positions[3 * v + 2]};
    }
    const glm::vec3 outward = glm::cross(p[1] - p[0], p[2] - p[0]);
    const glm::vec3 to_eye =
        camera.projection == Projection::kOrthographic ? -camera.Forward() : camera.eye - p[0];
    const bool front = glm::dot(outward, to_eye) > 0.0f;
    const int s = mesh->surface[t];
    const int group = size_t(s) < group_of_surface.size() ? group_of_surface[size_t(s)] : 0;
    key[t] = 2 * kMaxSurfaces * group + (front ? 2 * kMaxSurfaces - 1 - s : s);
  }
  std::vector<size_t> order(n);
  std::iota(order.begin(), order.end(), size_t(0));
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return key[a] < key[b]; });
  std::vector<uint32_t> triangles(3 * n);
  std::vector<uint8_t> surface(n);
  for (size_t i = 0; i < n; ++i) {
    std::copy_n(mesh->triangles.data() + 3 * order[i], 3, triangles.data() + 3 * i);
    surface[i] = mesh->surface[order[i]];
  }
  mesh->triangles.swap(triangles);
  mesh->surface.swap(surface);
}

// Three nested spheres, deliberately not concentric, coloured by the default palette's first
// three surfaces (blue outside, red, green inside): all in group 0.
inline std::vector<Sphere> ThreeNestedSpheres() {
  return {{{0.0f, 0.0f, 0.0f}, 1.0f, 0},
          {{0.12f, -0.05f, 0.08f}, 0.68f, 1},
          {{0.2f, 0.05f, 0.12f}, 0.36f, 2}};
}

// ThreeNestedSpheres plus a larger fourth sphere (surface 3, yellow) behind them as seen by
// `camera`, up and to the right, so that part of the nest is seen against it. Along any ray the
// nest's colours read the same forwards and backwards (outer, middle, inner, inner, middle,
// outer), so reversing a frame's order barely changes a nest alone; the sphere behind makes a
// wrong order show wherever the two overlap. Its group is 0, the nest's 1. The camera must look
// at the origin.
inline std::vector<Sphere> NestBeforeSphere(const Camera& camera) {
  std::vector<Sphere> spheres = ThreeNestedSpheres();
  const glm::vec3 away = glm::normalize(camera.target - camera.eye);
  spheres.push_back({2.6f * away + 0.6f * camera.Right() + 0.4f * camera.TrueUp(), 1.4f, 3});
  return spheres;
}
inline const std::vector<int> kSphereThenNest = {1, 1, 1, 0};

}  // namespace isostream::render::testing
