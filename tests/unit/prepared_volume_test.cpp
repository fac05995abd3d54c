// PrepareVolume: the facts of the loaded volume, its samples in the hierarchy (equal to the
// grid's, read directly), and the grid itself released once the hierarchy holds them.
#include "server/hierarchy/prepared_volume.h"

#include <gtest/gtest.h>

#include "server/volume/load.h"

namespace isostream {
namespace {

TEST(PrepareVolume, KeepsTheFactsAndTheSamplesAndReleasesTheGrid) {
  for (const char* spec : {"cayley:17", "buckyball:20"}) {  // 2^k + 1 and padded
    auto loaded = LoadVolume(spec);
    ASSERT_TRUE(loaded.ok()) << loaded.status();
    auto prepared = PrepareVolume(spec, VolumeLimits{}, HierarchyCacheOptions{},
                                  HierarchyBuildOptions{});
    ASSERT_TRUE(prepared.ok()) << prepared.status();
    const Volume& v = **loaded;
    const Volume& p = *prepared->volume;
    EXPECT_EQ(p.grid, nullptr) << spec;
    EXPECT_EQ(p.dims, v.dims);
    EXPECT_EQ(p.spacing, v.spacing);
    EXPECT_EQ(p.origin, v.origin);
    EXPECT_EQ(p.min_value, v.min_value);
    EXPECT_EQ(p.max_value, v.max_value);
    const auto accessor = v.grid->getConstAccessor();
    for (int z = 0; z < v.dims[2]; ++z)
      for (int y = 0; y < v.dims[1]; ++y)
        for (int x = 0; x < v.dims[0]; ++x)
          ASSERT_EQ(prepared->hierarchy->sample(x, y, z),
                    accessor.getValue(openvdb::Coord(v.index_min[0] + x, v.index_min[1] + y,
                                                     v.index_min[2] + z)))
              << spec << " at " << x << "," << y << "," << z;
  }
}

}  // namespace
}  // namespace isostream
