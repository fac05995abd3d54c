// Padding to the hierarchy's (2^k+1)^3 cube: k, the data copied to the origin corner, and
// edge replication everywhere else, for grids made of leaves, tiles and background.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <string>

#include "address_space_cap.h"
#include "server/volume/load.h"
#include "server/volume/padding.h"

namespace isostream {
namespace {

TEST(VolumePadding, HierarchyLevelFor) {
  EXPECT_EQ(HierarchyLevelFor({2, 2, 2}), 1);  // the smallest hierarchy, 3^3
  EXPECT_EQ(HierarchyLevelFor({3, 2, 2}), 1);
  EXPECT_EQ(HierarchyLevelFor({2, 4, 2}), 2);
  EXPECT_EQ(HierarchyLevelFor({2, 2, 5}), 2);
  EXPECT_EQ(HierarchyLevelFor({6, 6, 6}), 3);
  EXPECT_EQ(HierarchyLevelFor({9, 9, 9}), 3);
  EXPECT_EQ(HierarchyLevelFor({10, 2, 2}), 4);
  EXPECT_EQ(HierarchyLevelFor({17, 3, 2}), 4);
  EXPECT_EQ(HierarchyLevelFor({129, 300, 2}), 9);
  EXPECT_EQ(HierarchyLevelFor({257, 257, 257}), 8);
  EXPECT_EQ(HierarchyLevelFor({258, 2, 2}), 9);
  EXPECT_EQ(HierarchyLevelFor({513, 513, 513}), 9);
  EXPECT_EQ(HierarchyLevelFor({1025, 1, 1}), 10);
}

// Expects the cube to hold the grid's box samples at the corner and clamped copies elsewhere.
void ExpectPadded(const Volume& v, const PaddedSamples& p) {
  ASSERT_EQ(p.k, HierarchyLevelFor(v.dims));
  ASSERT_EQ(p.n, (1 << p.k) + 1);
  ASSERT_EQ(p.data_dims, v.dims);
  ASSERT_EQ(p.values.size(), p.stored_points());
  if (!p.whole_cube()) {
    for (int a = 0; a < 3; ++a) ASSERT_LE(p.stored(a), p.n);
  }
  auto acc = v.grid->getConstAccessor();
  for (int z = 0; z < p.n; ++z)
    for (int y = 0; y < p.n; ++y)
      for (int x = 0; x < p.n; ++x) {
        const openvdb::Coord source(v.index_min[0] + std::min(x, v.dims[0] - 1),
                                    v.index_min[1] + std::min(y, v.dims[1] - 1),
                                    v.index_min[2] + std::min(z, v.dims[2] - 1));
        ASSERT_EQ(p.at(x, y, z), acc.getValue(source))
            << "cube point " << x << "," << y << "," << z;
      }
}

TEST(VolumePadding, CubeOfRightSizeNeedsNoPadding) {
  absl::StatusOr<VolumePtr> v = LoadVolume("cayley:9");
  ASSERT_TRUE(v.ok()) << v.status();
  absl::StatusOr<PaddedSamples> p = PadToHierarchyDomain(**v);
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_EQ(p->k, 3);
  EXPECT_EQ(p->n, 9);
  EXPECT_EQ(p->at(0, 0, 0), -29.0f);
  EXPECT_EQ(p->at(8, 8, 8), 27.0f);
  EXPECT_EQ(p->at(4, 4, 4), -1.0f);
  ExpectPadded(**v, *p);
}

// A daemon shutting down stops a preparation while it pads (a 769^3 volume pads to a 1025^3
// cube, 4.3 GB written).
TEST(VolumePadding, StopFlagCancels) {
  absl::StatusOr<VolumePtr> v = LoadVolume("noise:11:5");
  ASSERT_TRUE(v.ok()) << v.status();
  std::atomic<bool> stop{true};
  absl::StatusOr<PaddedSamples> p = PadToHierarchyDomain(**v, &stop);
  EXPECT_EQ(p.status().code(), absl::StatusCode::kCancelled) << p.status();
  EXPECT_NE(p.status().message().find("stopped"), std::string::npos) << p.status();
  stop = false;
  EXPECT_TRUE(PadToHierarchyDomain(**v, &stop).ok());
}

TEST(VolumePadding, GeneratedVolumeIsReplicatedAlongEveryAxis) {
  absl::StatusOr<VolumePtr> v = LoadVolume("noise:11:5");  // k = 4, n = 17
  ASSERT_TRUE(v.ok()) << v.status();
  absl::StatusOr<PaddedSamples> p = PadToHierarchyDomain(**v);
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_EQ(p->n, 17);
  // The far corner of the cube repeats the far corner of the data.
  EXPECT_EQ(p->at(16, 16, 16), p->at(10, 10, 10));
  EXPECT_EQ(p->at(16, 3, 5), p->at(10, 3, 5));
  EXPECT_NE(p->at(9, 3, 5), p->at(10, 3, 5));  // inside the data the noise is not constant
  ExpectPadded(**v, *p);
}

// A hand-made grid: box not at the origin, not leaf aligned, partly tiles, partly background.
VolumePtr MixedGrid(const std::array<int, 3>& dims, const openvdb::Coord& index_min) {
  auto grid = openvdb::FloatGrid::create(-7.0f);
  // A fill covering whole leaf cells makes tiles rather than leaves.
  grid->tree().fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(15)), 3.5f, true);
  auto acc = grid->getAccessor();
  int counter = 0;
  for (int z = index_min.z(); z < index_min.z() + dims[2]; z += 2)
    for (int y = index_min.y(); y < index_min.y() + dims[1]; y += 3)
      for (int x = index_min.x(); x < index_min.x() + dims[0]; ++x) {
        if ((x + y + z) % 5 == 0) acc.setValue(openvdb::Coord(x, y, z), 0.25f * ++counter);
      }
  auto v = std::make_shared<Volume>();
  v->name = "mixed";
  v->grid = grid;
  v->dims = dims;
  v->index_min = {index_min.x(), index_min.y(), index_min.z()};
  return v;
}

TEST(VolumePadding, TilesLeavesAndBackgroundAtAnOffset) {
  VolumePtr v = MixedGrid({13, 6, 21}, openvdb::Coord(-5, 3, -9));  // k = 5, n = 33
  size_t tiles = 0;
  for (auto it = v->grid->tree().cbeginValueOn(); it; ++it) tiles += !it.isVoxelValue();
  ASSERT_GT(tiles, 0u) << "the test grid should contain tiles";
  absl::StatusOr<PaddedSamples> p = PadToHierarchyDomain(*v);
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_EQ(p->n, 33);
  EXPECT_EQ(p->at(0, 0, 0), -7.0f);   // (-5, 3, -9) is background
  EXPECT_EQ(p->at(12, 5, 20), 3.5f);  // (7, 8, 11) lies in the filled tile region
  ExpectPadded(*v, *p);
}

TEST(VolumePadding, ThinAxis) {
  VolumePtr v = MixedGrid({2, 40, 3}, openvdb::Coord(14, -20, 0));  // k = 6, n = 65
  absl::StatusOr<PaddedSamples> p = PadToHierarchyDomain(*v);
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_EQ(p->n, 65);
  EXPECT_FALSE(p->whole_cube()) << "stand-ins for the planes deep in the padding";
  ExpectPadded(*v, *p);
  absl::StatusOr<PaddedSamples> whole = PadToHierarchyDomain(*v, nullptr, CubePlanes::kAll);
  ASSERT_TRUE(whole.ok()) << whole.status();
  EXPECT_TRUE(whole->whole_cube());
  ExpectPadded(*v, *whole);
}

TEST(VolumePadding, RejectsBadVolumes) {
  VolumePtr thin = MixedGrid({4, 1, 4}, openvdb::Coord(0));
  absl::StatusOr<PaddedSamples> p = PadToHierarchyDomain(*thin);
  EXPECT_EQ(p.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(p.status().message().find("mixed"), std::string::npos) << p.status();

  Volume no_grid;
  no_grid.name = "empty";
  no_grid.dims = {4, 4, 4};
  EXPECT_EQ(PadToHierarchyDomain(no_grid).status().code(), absl::StatusCode::kInvalidArgument);

  // 2^12 + 2 samples would need k = 13; refused before anything is allocated.
  VolumePtr huge = MixedGrid({4098, 2, 2}, openvdb::Coord(0));
  p = PadToHierarchyDomain(*huge);
  EXPECT_EQ(p.status().code(), absl::StatusCode::kResourceExhausted) << p.status();
  EXPECT_NE(p.status().message().find("mixed"), std::string::npos) << p.status();
}

// A cube the process cannot allocate is a ResourceExhausted status that says which cube and
// how many bytes (it said only "out of memory": a 2049x2x2 volume needed a 32 GiB cube). Run
// in a child process whose address space is capped 32 MB above what it already uses; the
// 300x2x2 volume pads to a 513^3 cube of 515 MiB when every plane is stored.
void PadUnderAddressSpaceCap(const Volume& volume) {
  testing::CapAddressSpaceAbove(rlim_t{32} << 20);
  const auto padded = PadToHierarchyDomain(volume, nullptr, CubePlanes::kAll);
  const std::string message(padded.status().message());
  std::fprintf(stderr, "%s\n", message.c_str());
  std::_Exit(!padded.ok() && padded.status().code() == absl::StatusCode::kResourceExhausted ? 0
                                                                                            : 1);
}

TEST(VolumePaddingDeathTest, OutOfMemorySaysTheCubeAndItsSize) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  VolumePtr v = MixedGrid({300, 2, 2}, openvdb::Coord(0));
  EXPECT_EXIT(PadUnderAddressSpaceCap(*v), ::testing::ExitedWithCode(0),
              "out of memory for the 513\\^3 cube \\(515 MiB\\)");
}

}  // namespace
}  // namespace isostream
