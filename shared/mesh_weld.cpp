#include "shared/mesh_weld.h"

#include <absl/container/flat_hash_map.h>

#include <array>
#include <cstring>

namespace isostream {

size_t WeldIdenticalVertices(OrderedMesh* mesh, const std::vector<uint32_t>& part_first_vertex) {
  using Key = std::array<uint32_t, 6>;  // the position's and the normal's float bits
  struct Kept {
    uint32_t index;  // after welding
    size_t part;
  };
  const size_t n = mesh->vertex_count();
  absl::flat_hash_map<Key, Kept> first;
  first.reserve(n);
  std::vector<uint32_t> to(n);
  size_t kept = 0, part = 0;
  for (size_t v = 0; v < n; ++v) {
    while (part + 1 < part_first_vertex.size() && v >= part_first_vertex[part + 1]) ++part;
    Key key;
    std::memcpy(&key[0], &mesh->positions[3 * v], 3 * sizeof(float));
    std::memcpy(&key[3], &mesh->normals[3 * v], 3 * sizeof(float));
    const auto [at, fresh] = first.try_emplace(key, Kept{uint32_t(kept), part});
    if (!fresh && at->second.part != part) {
      to[v] = at->second.index;
      continue;
    }
    to[v] = uint32_t(kept);
    for (int a = 0; a < 3; ++a) {
      mesh->positions[3 * kept + a] = mesh->positions[3 * v + a];
      mesh->normals[3 * kept + a] = mesh->normals[3 * v + a];
    }
    ++kept;
  }
  for (uint32_t& i : mesh->triangles) i = to[i];
  mesh->positions.resize(3 * kept);
  mesh->normals.resize(3 * kept);
  return n - kept;
}

}  // namespace isostream
