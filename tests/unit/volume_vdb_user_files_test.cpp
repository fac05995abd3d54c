// OpenVDB files as users bring them (written by OpenVDB itself): fog volumes, active tiles, the
// first grid of a file, an upper-case extension with a grid name, and a grid type this build of
// OpenVDB does not know beside a float grid.
#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/LevelSetUtil.h>

#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "mesh_checks.h"
#include "server/extract/extractor.h"
#include "server/hierarchy/prepared_volume.h"
#include "volume_files.h"

namespace isostream {
namespace {

using volume_files::ExpectSamples;
using volume_files::ScratchPath;
using volume_files::TestGrid;
using volume_files::WriteVdb;

// The mesh of ISO in the file at SPEC, at full resolution.
OrderedMesh ExtractFile(const std::string& spec, float iso, GridToWorld* xf = nullptr) {
  auto prepared =
      PrepareVolume(spec, VolumeLimits{}, HierarchyCacheOptions{}, HierarchyBuildOptions{});
  EXPECT_TRUE(prepared.ok()) << prepared.status();
  if (!prepared.ok()) return {};
  if (xf != nullptr) *xf = prepared->grid_to_world;
  ExtractRequest r;
  r.isovalues = {iso};
  r.eps = 0;
  r.view.eye = {-90.0, 310.0, 170.0};
  auto res = Extract(*prepared->hierarchy, prepared->grid_to_world, r);
  EXPECT_TRUE(res.ok()) << res.status();
  return res.ok() ? std::move(res->mesh) : OrderedMesh{};
}

// OpenVDB's fog volume of a sphere (tools::sdfToFogVolume): 0 outside (inactive, the
// background), rising to 1 over the band inside. Every isovalue in (0, 1) is a closed sphere;
// the grid's active voxels end where the density reaches 0, so the surfaces of low isovalues lie
// between the last active voxel and the background beyond it. The loader took the active box as
// the whole volume: below iso 1/3 the sphere had holes at its six poles, cut where the box ends
// (480, 432 and 288 unmatched half-edges at iso 0.05, 0.1 and 0.2; iso 0.5 was closed).
TEST(VolumeVdbUserFiles, FogVolumeSurfacesAreClosedSpheres) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      /*radius=*/10.0f, openvdb::Vec3f(5, -3, 2), /*voxelSize=*/0.5f, /*halfWidth=*/3.0f);
  openvdb::tools::sdfToFogVolume(*grid);  // fog = -sdf / (3 voxels), sdf in [-1.5, 0]
  grid->setName("density");
  const std::string path = WriteVdb("fog.vdb", {grid});
  for (const float iso : {0.05f, 0.1f, 0.2f, 0.5f}) {
    const OrderedMesh m = ExtractFile(path, iso);
    const std::string what = "fog iso " + std::to_string(iso);
    ASSERT_GT(m.triangle_count(), 0u) << what;
    testing::ExpectWatertight(m, what);
    // The sphere where the distance is -1.5 * iso, within a voxel's diagonal.
    const double radius = 10.0 - 1.5 * iso;
    double worst = 0;
    for (size_t v = 0; v < m.vertex_count(); ++v) {
      const double dx = m.positions[3 * v] - 5, dy = m.positions[3 * v + 1] + 3,
                   dz = m.positions[3 * v + 2] - 2;
      worst = std::max(worst, std::fabs(std::sqrt(dx * dx + dy * dy + dz * dz) - radius));
    }
    EXPECT_LT(worst, 0.5 * std::sqrt(3.0)) << what;
  }
}

// An active tile of density 1 in a fog volume's background of 0 (a voxelized box) is a cube
// at iso 0.5. Its active box held only the 1s: no triangles at all, silently (value range
// [1, 1]). (A grid of no class is its active box:
// OnlyLevelSetsAndFogVolumesGoOnPastTheirActiveBox.)
TEST(VolumeVdbUserFiles, AnActiveTileInABackgroundIsACube) {
  auto grid = openvdb::FloatGrid::create(0.0f);
  grid->setName("box");
  grid->setGridClass(openvdb::GRID_FOG_VOLUME);
  grid->tree().addTile(/*level=*/1, openvdb::Coord(0, 0, 0), 1.0f, /*active=*/true);  // 8^3
  const std::string path = WriteVdb("tile.vdb", {grid});
  const OrderedMesh m = ExtractFile(path, 0.5f);
  ASSERT_GT(m.triangle_count(), 0u) << "an 8^3 tile of 1s in 0s at iso 0.5";
  testing::ExpectWatertight(m, "tile cube");
  // The crossings lie half way between the tile's outer voxels (0, 7) and the background's
  // (-1, 8): the cube spans [-0.5, 7.5] on each axis.
  for (int a = 0; a < 3; ++a) {
    float lo = 1e9f, hi = -1e9f;
    for (size_t v = 0; v < m.vertex_count(); ++v) {
      lo = std::min(lo, m.positions[3 * v + a]);
      hi = std::max(hi, m.positions[3 * v + a]);
    }
    EXPECT_NEAR(lo, -0.5f, 1e-4f) << "axis " << a;
    EXPECT_NEAR(hi, 7.5f, 1e-4f) << "axis " << a;
  }
}

// A grid of another class is its active box, as before (a scan or a simulation saved as VDB):
// one voxel of background around it would add a surface on the box's faces for every isovalue
// between the data and the background, and move a 1024^3 grid past the 1025^3 cube. The same
// voxels as a fog volume go on past their box.
TEST(VolumeVdbUserFiles, OnlyLevelSetsAndFogVolumesGoOnPastTheirActiveBox) {
  auto grid = openvdb::FloatGrid::create(0.0f);
  grid->setName("dense");
  grid->tree().addTile(/*level=*/1, openvdb::Coord(0, 0, 0), 1.0f, /*active=*/true);  // 8^3
  const absl::StatusOr<VolumePtr> v = LoadVolume(WriteVdb("dense.vdb", {grid}));
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->dims, (std::array<int, 3>{8, 8, 8}));
  EXPECT_EQ((*v)->min_value, 1.0f);
  for (const auto grid_class : {openvdb::GRID_FOG_VOLUME, openvdb::GRID_LEVEL_SET}) {
    grid->setGridClass(grid_class);
    const absl::StatusOr<VolumePtr> field = LoadVolume(WriteVdb("field.vdb", {grid}));
    ASSERT_TRUE(field.ok()) << field.status();
    EXPECT_EQ((*field)->dims, (std::array<int, 3>{10, 10, 10}));
    EXPECT_EQ((*field)->min_value, 0.0f);
    EXPECT_EQ((*field)->origin, (std::array<double, 3>{-1, -1, -1}));
  }
}

// The margin never makes a grid the limits refuse: a level set whose active voxels are as wide
// as max_dim loads as wide as they are (it was refused as 4098 wide, dims the user never made).
TEST(VolumeVdbUserFiles, TheMarginYieldsToTheLimits) {
  auto grid = openvdb::FloatGrid::create(3.0f);
  grid->setName("band");
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  for (int x = 0; x < 64; ++x)
    for (int y = 0; y < 2; ++y)
      for (int z = 0; z < 2; ++z) grid->tree().setValue(openvdb::Coord(x, y, z), 0.5f * (x % 4));
  const std::string path = WriteVdb("band.vdb", {grid});
  VolumeLimits limits;
  limits.max_dim = 64;
  const absl::StatusOr<VolumePtr> tight = LoadVolume(path, limits);
  ASSERT_TRUE(tight.ok()) << tight.status();
  EXPECT_EQ((*tight)->dims, (std::array<int, 3>{64, 2, 2}));
  limits.max_dim = 66;
  const absl::StatusOr<VolumePtr> roomy = LoadVolume(path, limits);
  ASSERT_TRUE(roomy.ok()) << roomy.status();
  EXPECT_EQ((*roomy)->dims, (std::array<int, 3>{66, 4, 4}));
}

// A level set's offset surface inside its narrow band (iso 1.4 of a band of +-1.5) is a closed
// sphere too: the band's outermost active voxels stop short of it at the poles, where the
// background (+1.5) lies beyond. It had 480 open edges.
TEST(VolumeVdbUserFiles, LevelSetOffsetInsideTheBandIsClosed) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      10.0f, openvdb::Vec3f(5, -3, 2), 0.5f, 3.0f);
  grid->setName("surface");
  const std::string path = WriteVdb("level_set.vdb", {grid});
  for (const float iso : {0.0f, 1.0f, 1.4f}) {
    const OrderedMesh m = ExtractFile(path, iso);
    ASSERT_GT(m.triangle_count(), 0u) << iso;
    testing::ExpectWatertight(m, "level set iso " + std::to_string(iso));
  }
}

// Without a grid name the first float grid by name loads, as OpenVDB lists a file's grids (its
// API keeps no file order): 'density' of a file written as ['temperature', 'density']. The
// README said "the first", which read as the file's first.
TEST(VolumeVdbUserFiles, WithoutAGridNameTheFirstFloatGridByNameLoads) {
  const std::string path =
      WriteVdb("order.vdb", {TestGrid("temperature", -0.5f), TestGrid("density", 1.0f)});
  const absl::StatusOr<VolumePtr> v = LoadVolume(path);
  ASSERT_TRUE(v.ok()) << v.status();
  ExpectSamples(**v, [&](int64_t index) {
    const int i = static_cast<int>(index % 10) - 3, j = static_cast<int>(index / 10 % 9) + 5,
              k = static_cast<int>(index / 90) + 7;
    if (i == 0 && j == 6 && k == 8) return 123.0f;
    return 1.0f * (i * 3 + j * 5 - k * 7);  // density's
  });
}

// "X.VDB" loads (the extension is matched without case), and so must "X.VDB#GRID": the grid
// name was split off at ".vdb#" only, so it was "an unrecognised volume type".
TEST(VolumeVdbUserFiles, UpperCaseExtensionWithAGridName) {
  const std::string path = WriteVdb("UPPER.VDB", {TestGrid("density", 1.0f)});
  const absl::StatusOr<VolumePtr> whole = LoadVolume(path);
  ASSERT_TRUE(whole.ok()) << whole.status();
  const absl::StatusOr<VolumePtr> named = LoadVolume(path + "#density");
  ASSERT_TRUE(named.ok()) << named.status();
  EXPECT_EQ((*named)->dims, (*whole)->dims);
}

// A sound file holding a float grid and a grid of a type this OpenVDB has not registered (a
// newer library's type, or a custom tree configuration) was "corrupt or truncated" (DATA_LOSS),
// whichever grid was asked for. OpenVDB opens all of a file's grids at once, so none can be
// read; the error names the type it cannot read, not damage.
TEST(VolumeVdbUserFiles, AGridOfAnUnknownTypeBesideAFloatGrid) {
  using Tree443 = openvdb::tree::Tree4<float, 4, 4, 3>::Type;
  using Grid443 = openvdb::Grid<Tree443>;
  openvdb::initialize();
  Grid443::registerGrid();
  auto custom = Grid443::create(3.0f);
  custom->setName("custom");
  custom->tree().setValue(openvdb::Coord(0), 1.0f);
  const std::string path = WriteVdb("custom_tree.vdb", {custom, TestGrid("density", 1.0f)});
  Grid443::unregisterGrid();  // as a reader that never heard of it
  for (const std::string grid : {"#density", "#custom", ""}) {
    const absl::StatusOr<VolumePtr> v = LoadVolume(path + grid);
    EXPECT_EQ(v.status().code(), absl::StatusCode::kInvalidArgument) << grid << v.status();
    EXPECT_NE(v.status().message().find("holds a grid type this OpenVDB"), std::string::npos)
        << v.status();
    EXPECT_NE(v.status().message().find("Tree_float_4_4_3"), std::string::npos) << v.status();
  }
}

}  // namespace
}  // namespace isostream
