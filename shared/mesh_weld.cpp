#include "shared/mesh_weld.h"

#include <absl/container/flat_hash_map.h>

#include <array>
#include <cstring>

namespace isostream {

size_t WeldIdenticalVertices(OrderedMesh* mesh, const std::vector<uint32_t>& part_first_vertex) {
  using Key = std::array<uint32_t, 6>;  // the position's and the normal's float bits
  struct Seen {
    uint32_t part;  // of the last such vertex
    // Twice in one part: two vertices quantized alike, so no later copy tells which it is.
    bool ambiguous;
    bool kept;
    uint32_t index;  // of the kept one, after welding
  };
  const size_t n = mesh->vertex_count();
  const auto key_of = [&](size_t v) {
    Key key;
    std::memcpy(&key[0], &mesh->positions[3 * v], 3 * sizeof(float));
    std::memcpy(&key[3], &mesh->normals[3 * v], 3 * sizeof(float));
    return key;
  };
  std::vector<uint32_t> part_of(n);
  for (size_t v = 0, part = 0; v < n; ++v) {
    while (part + 1 < part_first_vertex.size() && v >= part_first_vertex[part + 1]) ++part;
    part_of[v] = uint32_t(part);
  }
  absl::flat_hash_map<Key, Seen> seen;
  seen.reserve(n);
  for (size_t v = 0; v < n; ++v) {
    const auto [at, fresh] = seen.try_emplace(key_of(v), Seen{part_of[v], false, false, 0});
    if (!fresh && at->second.part == part_of[v]) at->second.ambiguous = true;
    at->second.part = part_of[v];
  }
  // Unambiguous values occur at most once a part: every occurrence after the first is a copy
  // of it from a later part.
  std::vector<uint32_t> to(n);
  size_t kept = 0;
  for (size_t v = 0; v < n; ++v) {
    Seen& s = seen.find(key_of(v))->second;
    if (s.kept && !s.ambiguous) {
      to[v] = s.index;
      continue;
    }
    s.kept = true;
    s.index = uint32_t(kept);
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
