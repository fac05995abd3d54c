// OrderedMesh: the one mesh type the extractor, the frame codec, the writers, the client and
// the tests share. Triangles are stored in draw order: for the view they were extracted for,
// drawing them first to last with alpha blending is a valid back-to-front (painter's) order.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace isostream {

inline constexpr int kMaxSurfaces = 16;

struct OrderedMesh {
  std::vector<float> positions;     // 3 per vertex, world units
  std::vector<float> normals;       // 3 per vertex, unit length (zero if undefined)
  std::vector<uint32_t> triangles;  // 3 vertex indices per triangle, in draw order
  std::vector<uint8_t> surface;     // per triangle: index of its isovalue in the request

  size_t vertex_count() const { return positions.size() / 3; }
  size_t triangle_count() const { return surface.size(); }
  bool empty() const { return surface.empty(); }
  void clear() {
    positions.clear();
    normals.clear();
    triangles.clear();
    surface.clear();
  }
};

}  // namespace isostream
