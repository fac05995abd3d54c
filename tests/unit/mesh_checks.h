// Checks on extracted meshes shared by the extractor's tests.
#pragma once

#include <gtest/gtest.h>

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <tuple>

#include "shared/ordered_mesh.h"

namespace isostream::testing {

// Every edge of a surface is shared by exactly two of its triangles, with opposite
// directions (consistently oriented, closed).
inline void ExpectWatertight(const OrderedMesh& m, const std::string& what) {
  std::map<std::tuple<int, uint32_t, uint32_t>, int> directed;
  for (size_t t = 0; t < m.triangle_count(); ++t)
    for (int e = 0; e < 3; ++e) {
      const uint32_t a = m.triangles[3 * t + e], b = m.triangles[3 * t + (e + 1) % 3];
      ++directed[{m.surface[t], a, b}];
    }
  size_t bad = 0;
  for (const auto& [edge, count] : directed) {
    const auto& [s, a, b] = edge;
    auto back = directed.find({s, b, a});
    if (count != 1 || back == directed.end() || back->second != 1) ++bad;
  }
  EXPECT_EQ(bad, 0u) << what << ": " << bad << " of " << directed.size() << " half-edges unmatched";
}

}  // namespace isostream::testing
