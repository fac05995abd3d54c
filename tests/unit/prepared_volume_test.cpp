// PrepareVolume: the facts of the loaded volume, its samples in the hierarchy (equal to the
// grid's, read directly), the grid itself released once the hierarchy holds them, and giving
// up when told to stop.
#include "server/hierarchy/prepared_volume.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdio>
#include <string>

#include "server/hierarchy/hierarchy.h"
#include "server/volume/load.h"
#include "server/volume/padding.h"

namespace isostream {
namespace {

TEST(PrepareVolume, KeepsTheFactsAndTheSamplesAndReleasesTheGrid) {
  for (const char* spec : {"cayley:17", "buckyball:20"}) {  // 2^k + 1 and padded
    auto loaded = LoadVolume(spec);
    ASSERT_TRUE(loaded.ok()) << loaded.status();
    auto prepared =
        PrepareVolume(spec, VolumeLimits{}, HierarchyCacheOptions{}, HierarchyBuildOptions{});
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
                    accessor.getValue(
                        openvdb::Coord(v.index_min[0] + x, v.index_min[1] + y, v.index_min[2] + z)))
              << spec << " at " << x << "," << y << "," << z;
  }
}

// max_voxels bounds the points a volume is held in, not only its samples: a 33x2x2 volume of 132
// samples pads to a 33^3 cube, of which it stores 33x14x14 planes (stand-ins for the rest of the
// padding; it was prepared at any max_voxels its samples fitted).
TEST(PrepareVolume, MaxVoxelsBoundsThePaddedCube) {
  VolumeLimits limits;
  limits.max_voxels = 33 * 14 * 14 - 1;
  const std::string path = ::testing::TempDir() + "/thin_33x2x2.raw";
  {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    ASSERT_NE(f, nullptr);
    for (int i = 0; i < 33 * 2 * 2; ++i) std::fputc(i % 7, f);
    std::fclose(f);
  }
  const std::string spec = "raw:" + path + ":33x2x2:uint8";
  ASSERT_TRUE(LoadVolume(spec, limits).ok());
  const auto prepared = PrepareVolume(spec, limits, HierarchyCacheOptions{}, {});
  EXPECT_EQ(prepared.status().code(), absl::StatusCode::kResourceExhausted) << prepared.status();
  EXPECT_NE(prepared.status().message().find("held as 6468 points of a 33^3 cube"),
            std::string::npos)
      << prepared.status();
  limits.max_voxels = 33 * 14 * 14;
  EXPECT_TRUE(PrepareVolume(spec, limits, HierarchyCacheOptions{}, {}).ok());
}

// A stop flag that is set (a daemon shutting down) ends the generator's sampling, the
// hierarchy build and so the whole preparation with CANCELLED; one that is clear changes
// nothing.
TEST(PrepareVolume, GivesUpWhenToldToStop) {
  std::atomic<bool> stop{true};
  HierarchyBuildOptions build;
  build.stop = &stop;
  const auto generated = LoadVolume("cayley:17", VolumeLimits{}, &stop);
  EXPECT_EQ(generated.status().code(), absl::StatusCode::kCancelled) << generated.status();
  auto loaded = LoadVolume("cayley:17");
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  auto padded = PadToHierarchyDomain(**loaded);
  ASSERT_TRUE(padded.ok()) << padded.status();
  const auto built = BuildHierarchy(std::move(*padded), build);
  EXPECT_EQ(built.status().code(), absl::StatusCode::kCancelled) << built.status();
  const auto prepared = PrepareVolume("cayley:17", VolumeLimits{}, HierarchyCacheOptions{}, build);
  EXPECT_EQ(prepared.status().code(), absl::StatusCode::kCancelled) << prepared.status();

  stop = false;
  const auto whole = PrepareVolume("cayley:17", VolumeLimits{}, HierarchyCacheOptions{}, build);
  ASSERT_TRUE(whole.ok()) << whole.status();
  EXPECT_EQ(
      whole->hierarchy->sample(3, 5, 7),
      (*loaded)->grid->getConstAccessor().getValue(openvdb::Coord(
          (*loaded)->index_min[0] + 3, (*loaded)->index_min[1] + 5, (*loaded)->index_min[2] + 7)));
}

}  // namespace
}  // namespace isostream
