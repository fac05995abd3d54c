// The three-level block tables against bisection done on real coordinates.
#include "server/hierarchy/block_tables.h"

#include <gtest/gtest.h>

#include <glm/geometric.hpp>

namespace isostream {
namespace {

using Points = std::array<glm::ivec3, 4>;

int64_t SixVolume(const Points& v) {
  const glm::i64vec3 a(v[1] - v[0]), b(v[2] - v[0]), c(v[3] - v[0]);
  const int64_t d =
      a.x * (b.y * c.z - b.z * c.y) - a.y * (b.x * c.z - b.z * c.x) + a.z * (b.x * c.y - b.y * c.x);
  return d < 0 ? -d : d;
}

// Every Kuhn-level class (level 0 mod 3), bisected three times with real coordinates through
// the reference child maps, gives at each heap position the class and vertices the block table
// names through its 10 local points.
TEST(BlockTables, PositionsMatchBisectionOnCoordinates) {
  const ReferenceTets& tets = ReferenceTets::Get();
  const BlockTables& blocks = BlockTables::Get();
  int roots = 0;
  for (const TetClass cls : tets.kuhn_classes()) {
    const int c = cls.value;
    ++roots;
    const BlockNode* nodes = blocks[cls];
    // Scale 8 keeps three levels of midpoints integral.
    std::array<glm::ivec3, kBlockPoints> local;
    for (int i = 0; i < 4; ++i) local[i] = tets[cls].vertex[i] * 8;
    for (int e = 0; e < 6; ++e)
      local[4 + e] = (local[kBlockEdge[e][0]] + local[kBlockEdge[e][1]]) / 2;
    std::array<Points, kBlockNodes> pos;
    std::array<TetClass, kBlockNodes> pos_cls;
    for (int i = 0; i < 4; ++i) pos[1][i] = local[i];
    pos_cls[1] = cls;
    int64_t finest_volume = 0;
    for (int p = 1; p < kBlockNodes; ++p) {
      ASSERT_EQ(nodes[p].cls, pos_cls[p]) << "class " << c << " position " << p;
      uint16_t corners = 0;
      for (int i = 0; i < 4; ++i) {
        ASSERT_EQ(local[nodes[p].corner[i]], pos[p][i]) << "class " << c << " position " << p;
        corners |= uint16_t(1u << nodes[p].corner[i]);
      }
      EXPECT_EQ(nodes[p].corners, corners);
      if (p >= kBlockNodes / 2) {
        EXPECT_EQ(blocks.leaf_corners(cls)[p - kBlockNodes / 2], corners);
        finest_volume += SixVolume(pos[p]);
        continue;
      }
      const ReferenceTet& rt = tets[pos_cls[p]];
      std::array<glm::ivec3, 5> points = {pos[p][0], pos[p][1], pos[p][2], pos[p][3],
                                          (pos[p][0] + pos[p][3]) / 2};
      EXPECT_EQ(local[nodes[p].refinement], points[kRefinementPoint]);
      for (int ch = 0; ch < 2; ++ch) {
        pos_cls[2 * p + ch] = rt.child[ch];
        for (int i = 0; i < 4; ++i) pos[2 * p + ch][i] = points[rt.child_point[ch][i]];
      }
    }
    // The finest eight tile the root and use all 10 points.
    EXPECT_EQ(finest_volume, SixVolume(pos[1])) << "class " << c;
    unsigned used = 0;
    for (int j = 0; j < kBlockNodes / 2; ++j) used |= blocks.leaf_corners(cls)[j];
    EXPECT_EQ(used, (1u << kBlockPoints) - 1) << "class " << c;
  }
  EXPECT_EQ(roots, 24);
}

}  // namespace
}  // namespace isostream
