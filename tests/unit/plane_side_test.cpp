// The extractor's separating-plane test on packed grid points: the signed sum of a point's
// coordinates, taken with one multiply per sign (FieldSum), equals the direct sum for every
// axis subset over the whole coordinate range of k <= 12 (0..4096), corners included.
#include <gtest/gtest.h>

#include <cstdint>
#include <random>

#include "server/extract/tree_node.h"

namespace isostream {
namespace {

using extract_internal::FieldSum;
using extract_internal::FieldSumMultiplier;
using extract_internal::Pack;

TEST(PlaneSide, FieldSumEqualsTheDirectSumOfTheChosenCoordinates) {
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> coord(0, 4096);
  for (int trial = 0; trial < 20000; ++trial) {
    glm::ivec3 p(coord(rng), coord(rng), coord(rng));
    if (trial < 8) p = glm::ivec3(trial & 1, (trial >> 1) & 1, (trial >> 2) & 1) * 4096;
    for (unsigned axes = 0; axes < 8; ++axes) {
      int64_t want = 0;
      for (int a = 0; a < 3; ++a)
        if ((axes >> a) & 1) want += p[a];
      ASSERT_EQ(FieldSum(Pack(p), FieldSumMultiplier(axes)), want)
          << p.x << " " << p.y << " " << p.z << " axes " << axes;
    }
  }
}

}  // namespace
}  // namespace isostream
