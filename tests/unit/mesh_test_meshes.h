// Test helpers for the mesh codecs and writers: small synthetic OrderedMeshes with known
// structure, a distinctive triangle order, and per-corner comparison that ignores how a codec
// renumbers vertices.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "shared/ordered_mesh.h"

namespace isostream::testing {

// An n x n grid of quads (2 n^2 triangles) on a gently curved sheet over [0, n]^2, with unit
// normals. Triangles come out row by row (grid order).
inline OrderedMesh MakeGrid(int n, uint8_t surface = 0) {
  OrderedMesh mesh;
  const int side = n + 1;
  for (int j = 0; j < side; ++j) {
    for (int i = 0; i < side; ++i) {
      const float x = static_cast<float>(i), y = static_cast<float>(j);
      const float z = 0.1f * n * std::sin(0.2f * x) * std::cos(0.15f * y);
      const float dzdx = 0.02f * n * std::cos(0.2f * x) * std::cos(0.15f * y);
      const float dzdy = -0.015f * n * std::sin(0.2f * x) * std::sin(0.15f * y);
      const float length = std::sqrt(dzdx * dzdx + dzdy * dzdy + 1.0f);
      mesh.positions.insert(mesh.positions.end(), {x, y, z});
      mesh.normals.insert(mesh.normals.end(), {-dzdx / length, -dzdy / length, 1.0f / length});
    }
  }
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const uint32_t a = j * side + i, b = a + 1, c = a + side, d = c + 1;
      mesh.triangles.insert(mesh.triangles.end(), {a, b, c, b, d, c});
      mesh.surface.insert(mesh.surface.end(), {surface, surface});
    }
  }
  return mesh;
}

// A UV sphere of radius `radius` centred at `center` with about `target_triangles` triangles,
// unit normals, in latitude-band order.
inline OrderedMesh MakeSphere(size_t target_triangles, float radius = 1.0f,
                              const float center[3] = nullptr, uint8_t surface = 0) {
  const int bands = std::max(3, static_cast<int>(std::sqrt(target_triangles / 2.0)));
  const int segments = bands;
  const float origin[3] = {center ? center[0] : 0.0f, center ? center[1] : 0.0f,
                           center ? center[2] : 0.0f};
  OrderedMesh mesh;
  const double pi = std::acos(-1.0);
  for (int b = 0; b <= bands; ++b) {
    const double theta = pi * b / bands;
    for (int s = 0; s < segments; ++s) {
      const double phi = 2.0 * pi * s / segments;
      const float n[3] = {static_cast<float>(std::sin(theta) * std::cos(phi)),
                          static_cast<float>(std::sin(theta) * std::sin(phi)),
                          static_cast<float>(std::cos(theta))};
      for (int k = 0; k < 3; ++k) mesh.positions.push_back(origin[k] + radius * n[k]);
      mesh.normals.insert(mesh.normals.end(), n, n + 3);
    }
  }
  for (int b = 0; b < bands; ++b) {
    for (int s = 0; s < segments; ++s) {
      const uint32_t a = b * segments + s, c = b * segments + (s + 1) % segments;
      const uint32_t d = a + segments, e = c + segments;
      // skip the degenerate triangles at the poles
      if (b > 0) {
        mesh.triangles.insert(mesh.triangles.end(), {a, c, d});
        mesh.surface.push_back(surface);
      }
      if (b < bands - 1) {
        mesh.triangles.insert(mesh.triangles.end(), {c, e, d});
        mesh.surface.push_back(surface);
      }
    }
  }
  return mesh;
}

// Reorders triangles by `order` (order[i] = old index of new triangle i).
inline OrderedMesh PermuteTriangles(const OrderedMesh& mesh, const std::vector<size_t>& order) {
  OrderedMesh out = mesh;
  for (size_t t = 0; t < order.size(); ++t) {
    std::copy_n(&mesh.triangles[3 * order[t]], 3, &out.triangles[3 * t]);
    out.surface[t] = mesh.surface[order[t]];
  }
  return out;
}

inline OrderedMesh Shuffled(const OrderedMesh& mesh, uint32_t seed) {
  std::vector<size_t> order(mesh.triangle_count());
  std::iota(order.begin(), order.end(), size_t{0});
  std::shuffle(order.begin(), order.end(), std::mt19937(seed));
  return PermuteTriangles(mesh, order);
}

// Back to front along +`axis`: the kind of order the server produces for a view down that axis.
inline OrderedMesh SortedByDepth(const OrderedMesh& mesh, int axis) {
  std::vector<float> depth(mesh.triangle_count());
  for (size_t t = 0; t < depth.size(); ++t) {
    for (int c = 0; c < 3; ++c) depth[t] += mesh.positions[3 * mesh.triangles[3 * t + c] + axis];
  }
  std::vector<size_t> order(depth.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return depth[a] < depth[b]; });
  return PermuteTriangles(mesh, order);
}

// Concatenates meshes, offsetting indices: the result draws a's triangles, then b's.
inline OrderedMesh Concatenate(const OrderedMesh& a, const OrderedMesh& b) {
  OrderedMesh out = a;
  const uint32_t offset = static_cast<uint32_t>(a.vertex_count());
  out.positions.insert(out.positions.end(), b.positions.begin(), b.positions.end());
  out.normals.insert(out.normals.end(), b.normals.begin(), b.normals.end());
  for (uint32_t index : b.triangles) out.triangles.push_back(index + offset);
  out.surface.insert(out.surface.end(), b.surface.begin(), b.surface.end());
  return out;
}

// Expects `actual` to have the same triangles as expected[first, first + count) in the same
// order: same surface per triangle and, corner by corner, positions within
// `position_tolerance` per coordinate and normals within `normal_tolerance` (Euclidean).
// Vertex numbering may differ.
inline void ExpectSameTrianglesInOrder(const OrderedMesh& expected, size_t first, size_t count,
                                       const OrderedMesh& actual, size_t actual_first,
                                       float position_tolerance, float normal_tolerance) {
  ASSERT_GE(actual.triangle_count(), actual_first + count);
  ASSERT_EQ(actual.normals.size(), actual.positions.size());
  int reported = 0;
  for (size_t t = 0; t < count && reported < 5; ++t) {
    const size_t te = first + t, ta = actual_first + t;
    if (expected.surface[te] != actual.surface[ta]) {
      ADD_FAILURE() << "triangle " << t << " surface " << int{actual.surface[ta]} << ", expected "
                    << int{expected.surface[te]};
      ++reported;
      continue;
    }
    for (int c = 0; c < 3; ++c) {
      const uint32_t ve = expected.triangles[3 * te + c], va = actual.triangles[3 * ta + c];
      float position_error = 0.0f, normal_error_sq = 0.0f;
      for (int k = 0; k < 3; ++k) {
        position_error = std::max(position_error, std::fabs(expected.positions[3 * ve + k] -
                                                            actual.positions[3 * va + k]));
        const float expected_normal =
            expected.normals.empty() ? 0.0f : expected.normals[3 * ve + k];
        const float d = expected_normal - actual.normals[3 * va + k];
        normal_error_sq += d * d;
      }
      if (position_error > position_tolerance || std::sqrt(normal_error_sq) > normal_tolerance) {
        ADD_FAILURE() << "triangle " << t << " corner " << c << ": position error "
                      << position_error << " (tolerance " << position_tolerance
                      << "), normal error " << std::sqrt(normal_error_sq) << " (tolerance "
                      << normal_tolerance << ")";
        ++reported;
        break;
      }
    }
  }
}

// A fresh directory under the test temp dir, removed with the object.
class ScratchDir {
 public:
  ScratchDir() {
    std::string pattern = ::testing::TempDir() + "/isostream_mesh_XXXXXX";
    path_ = mkdtemp(pattern.data()) ? pattern : std::string();
    EXPECT_FALSE(path_.empty());
  }
  ~ScratchDir() {
    std::error_code ignored;
    if (!path_.empty()) std::filesystem::remove_all(path_, ignored);
  }
  std::string File(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

}  // namespace isostream::testing
