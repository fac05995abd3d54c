// WeldIdenticalVertices: what fetch does to a streamed frame's seams.
#include "shared/mesh_weld.h"

#include <gtest/gtest.h>

#include <vector>

namespace isostream {
namespace {

// A mesh whose vertex i sits at the x given as place[i] (normals all +z), and triangles as given.
OrderedMesh Mesh(const std::vector<float>& place, const std::vector<uint32_t>& triangles) {
  OrderedMesh m;
  for (float x : place) {
    m.positions.insert(m.positions.end(), {x, 0.0f, 0.0f});
    m.normals.insert(m.normals.end(), {0.0f, 0.0f, 1.0f});
  }
  m.triangles = triangles;
  m.surface.assign(triangles.size() / 3, 0);
  return m;
}

std::vector<float> Places(const OrderedMesh& m) {
  std::vector<float> x;
  for (size_t v = 0; v < m.vertex_count(); ++v) x.push_back(m.positions[3 * v]);
  return x;
}

TEST(MeshWeld, CopiesOfAnEarlierPartsVerticesBecomeThem) {
  // Part 0: vertices 0-2; part 1: vertices 3-5, where 3 and 4 copy 2 and 1.
  OrderedMesh m = Mesh({0, 1, 2, 2, 1, 5}, {0, 1, 2, 3, 4, 5});
  EXPECT_EQ(WeldIdenticalVertices(&m, {0, 3}), 2u);
  EXPECT_EQ(Places(m), (std::vector<float>{0, 1, 2, 5}));
  EXPECT_EQ(m.triangles, (std::vector<uint32_t>{0, 1, 2, 2, 1, 3}));
  // A normal that differs keeps vertices apart.
  m = Mesh({0, 1, 2, 2, 1, 5}, {0, 1, 2, 3, 4, 5});
  m.normals[3 * 3 + 2] = -1.0f;
  EXPECT_EQ(WeldIdenticalVertices(&m, {0, 3}), 1u);
  EXPECT_EQ(m.triangles, (std::vector<uint32_t>{0, 1, 2, 3, 1, 4}));
}

TEST(MeshWeld, VerticesAlikeWithinAPartStayApart) {
  // Part 0 holds two vertices at 1 (quantized alike): they stay two.
  OrderedMesh m = Mesh({0, 1, 1}, {0, 1, 2});
  EXPECT_EQ(WeldIdenticalVertices(&m, {0}), 0u);
  EXPECT_EQ(m.triangles, (std::vector<uint32_t>{0, 1, 2}));
  // A later part's copy of either cannot be told apart, so it is welded to neither (welding it
  // to the first made edges used once or three times).
  m = Mesh({0, 1, 1, 1, 7, 8}, {0, 1, 2, 3, 4, 5});
  EXPECT_EQ(WeldIdenticalVertices(&m, {0, 3}), 0u);
  EXPECT_EQ(m.triangles, (std::vector<uint32_t>{0, 1, 2, 3, 4, 5}));
  // Nor are two copies alike in a later part of one earlier vertex (both welded to it made a
  // triangle with a repeated corner).
  m = Mesh({0, 1, 2, 1, 1, 9}, {0, 1, 2, 3, 4, 5});
  EXPECT_EQ(WeldIdenticalVertices(&m, {0, 3}), 0u);
  for (size_t t = 0; t < m.triangle_count(); ++t) {
    const uint32_t* c = &m.triangles[3 * t];
    EXPECT_TRUE(c[0] != c[1] && c[1] != c[2] && c[0] != c[2]) << t;
  }
}

TEST(MeshWeld, ThreePartsShareOneVertex) {
  // Vertex at 4 in parts 0, 1 and 2: one vertex, every triangle pointing at it.
  OrderedMesh m = Mesh({4, 1, 2, 4, 5, 6, 4, 7, 8}, {0, 1, 2, 3, 4, 5, 6, 7, 8});
  EXPECT_EQ(WeldIdenticalVertices(&m, {0, 3, 6}), 2u);
  EXPECT_EQ(Places(m), (std::vector<float>{4, 1, 2, 5, 6, 7, 8}));
  EXPECT_EQ(m.triangles, (std::vector<uint32_t>{0, 1, 2, 0, 3, 4, 0, 5, 6}));
}

// Normals move with their vertices: the kept vertices' normals, in the same order, and no more.
TEST(MeshWeld, NormalsFollowTheKeptVertices) {
  OrderedMesh m = Mesh({0, 1, 2, 2, 1, 5}, {0, 1, 2, 3, 4, 5});
  m.normals[3 * 5 + 2] = -1.0f;  // vertex 5, kept as vertex 3
  EXPECT_EQ(WeldIdenticalVertices(&m, {0, 3}), 2u);
  EXPECT_EQ(m.normals, (std::vector<float>{0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, -1}));
}

}  // namespace
}  // namespace isostream
