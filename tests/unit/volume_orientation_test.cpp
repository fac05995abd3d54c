// NIfTI orientation: samples stored with axes reversed, swapped or rotated are held on the
// world's axes, each at the world position the file's sform or qform gives it.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "server/volume/orientation.h"
#include "tests/unit/volume_files.h"

namespace isostream {
namespace {

using namespace volume_files;
using Matrix = std::array<std::array<double, 3>, 3>;

// Every file sample v (value: its x-fastest index, float32 samples) is found in the loaded
// volume at the grid point whose world position origin + spacing * p is m * v + offset, and the
// grid's own transform puts it there too.
void ExpectPlaced(const Volume& vol, const std::array<int, 3>& file_dims, const Matrix& m,
                  const std::array<double, 3>& offset, double tolerance = 1e-9) {
  int64_t index = 0;
  for (int k = 0; k < file_dims[2]; ++k)
    for (int j = 0; j < file_dims[1]; ++j)
      for (int i = 0; i < file_dims[0]; ++i, ++index) {
        const int v[3] = {i, j, k};
        int p[3];
        for (int a = 0; a < 3; ++a) {
          double w = offset[a];
          for (int c = 0; c < 3; ++c) w += m[a][c] * v[c];
          const double steps = (w - vol.origin[a]) / vol.spacing[a];
          p[a] = int(std::lround(steps));
          ASSERT_NEAR(steps, p[a], tolerance) << "file sample " << i << "," << j << "," << k;
          ASSERT_GE(p[a], 0);
          ASSERT_LT(p[a], vol.dims[a]);
        }
        ASSERT_EQ(Sample(vol, p[0], p[1], p[2]), StoredValue(Type::kFloat32, index))
            << "file sample " << i << "," << j << "," << k;
        const openvdb::Vec3d g = vol.grid->indexToWorld(openvdb::Coord(
            vol.index_min[0] + p[0], vol.index_min[1] + p[1], vol.index_min[2] + p[2]));
        for (int a = 0; a < 3; ++a) {
          double w = offset[a];
          for (int c = 0; c < 3; ++c) w += m[a][c] * v[c];
          ASSERT_NEAR(g[a], w, tolerance);
        }
      }
}

// File axis i along world -z (step 2), j along +x (1.5), k along -y (3): every axis moved, two
// reversed; dims of 9+ cross a leaf boundary, so reversed leaves must land on whole leaves.
TEST(VolumeOrientation, SformReversedAndSwappedAxes) {
  NiftiFile nf;
  nf.dims = {11, 4, 9};
  nf.sform_code = 2;
  nf.srow = std::array<std::array<float, 3>, 3>{{{0, 1.5f, 0}, {0, 0, -3}, {-2, 0, 0}}};
  nf.sform_offset = {10, 20, 30};
  nf.pixdim = {2, 1.5f, 3};
  absl::StatusOr<VolumePtr> v = WriteAndLoad(nf, "sform_turned.nii");
  ASSERT_TRUE(v.ok()) << v.status();
  const Volume& vol = **v;
  EXPECT_EQ(vol.dims, (std::array<int, 3>{4, 9, 11}));
  EXPECT_EQ(vol.spacing, (std::array<double, 3>{1.5, 3, 2}));
  // The first sample is the file's (0, 0, 8) on y and (10, 0, 0) on z.
  EXPECT_EQ(vol.origin, (std::array<double, 3>{10, 20 - 3 * 8, 30 - 2 * 10}));
  EXPECT_EQ(vol.orientation, "file axes i j k on world -z +x -y");
  const Matrix m{{{0, 1.5, 0}, {0, 0, -3}, {-2, 0, 0}}};
  ExpectPlaced(vol, nf.dims, m, {10, 20, 30});
}

// The qform: a quarter turn about z, and qfac -1 reversing the third axis.
TEST(VolumeOrientation, QformQuarterTurnAndQfac) {
  NiftiFile nf;
  nf.dims = {10, 3, 17};
  nf.qform_code = 1;
  const float h = float(std::sqrt(0.5));
  nf.quatern = {0, 0, h};  // a = cos 45, axis z
  nf.qfac = -1;
  nf.pixdim = {2, 3, 4};
  nf.qoffset = {-5, 6, 7};
  absl::StatusOr<VolumePtr> v = WriteAndLoad(nf, "qform_turned.nii");
  ASSERT_TRUE(v.ok()) << v.status();
  const Volume& vol = **v;
  // R = [[0,-1,0],[1,0,0],[0,0,1]]; columns scaled by 2, 3, -4.
  const Matrix m{{{0, -3, 0}, {2, 0, 0}, {0, 0, -4}}};
  EXPECT_EQ(vol.dims, (std::array<int, 3>{3, 10, 17}));
  const std::array<double, 3> spacing{3, 2, 4};
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(vol.spacing[a], spacing[a], 1e-6);
  EXPECT_EQ(vol.orientation, "file axes i j k on world +y -x -z");
  // The quaternion's float rounding leaves entries of ~1e-7 off the axes.
  ExpectPlaced(vol, nf.dims, m, {-5, 6, 7}, 1e-5);
}

// A half turn whose quaternion's float rounding leaves it just inside the unit sphere (a^2 of
// ~5e-8) is the half turn: normalised, not read as a turn a few hundredths of a degree off it.
TEST(VolumeOrientation, QformHalfTurnRoundedInsideTheUnitSphere) {
  NiftiFile nf;
  nf.qform_code = 1;
  const float h = float(std::sqrt(0.5));
  nf.quatern = {h, h, 0};  // about x + y: x and y swap, z reverses
  absl::StatusOr<VolumePtr> v = WriteAndLoad(nf, "qform_half_turn.nii");
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->orientation, "file axes i j k on world +y +x -z");
  EXPECT_EQ((*v)->dims, (std::array<int, 3>{4, 5, 3}));
}

// A grid rotated 10 degrees about z keeps its samples on the nearest axes, and says so.
TEST(VolumeOrientation, ObliqueGridTakesTheNearestAxesAndSaysSo) {
  NiftiFile nf;
  const double t = 10 * M_PI / 180;
  nf.sform_code = 1;
  nf.srow = std::array<std::array<float, 3>, 3>{{{float(std::cos(t)), float(-std::sin(t)), 0},
                                                 {float(std::sin(t)), float(std::cos(t)), 0},
                                                 {0, 0, 1}}};
  absl::StatusOr<VolumePtr> v = WriteAndLoad(nf, "oblique.nii");
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->dims, nf.dims);
  EXPECT_NE((*v)->orientation.find("rotated 10 degrees"), std::string::npos) << (*v)->orientation;
  ExpectSamples(**v, [](int64_t i) { return float(StoredValue(Type::kFloat32, i)); });
}

// A file as stored (the common case) is not rebuilt and has no note.
TEST(VolumeOrientation, AxisAlignedFileIsAsStored) {
  NiftiFile nf;
  nf.sform_code = 1;
  nf.pixdim = {0.5f, 2, 3};
  absl::StatusOr<VolumePtr> v = WriteAndLoad(nf, "aligned.nii");
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->orientation, "");
  EXPECT_EQ((*v)->index_min, (std::array<int, 3>{0, 0, 0}));
  EXPECT_EQ((*v)->spacing, (std::array<double, 3>{0.5, 2, 3}));
}

// An sform without a usable matrix (only its offset filled in) falls back to the qform's
// rotation, or to pixdim's steps with the sform's offset.
TEST(VolumeOrientation, UnusableSformFallsBack) {
  NiftiFile nf;
  nf.sform_code = 1;
  nf.srow = std::array<std::array<float, 3>, 3>{};
  nf.sform_offset = {1, 2, 3};
  nf.pixdim = {2, 2, 2};
  absl::StatusOr<VolumePtr> v = WriteAndLoad(nf, "zero_sform.nii");
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->spacing, (std::array<double, 3>{2, 2, 2}));
  EXPECT_EQ((*v)->origin, (std::array<double, 3>{1, 2, 3}));
  // Said, since the writer meant the sform (it was silent).
  EXPECT_EQ((*v)->orientation,
            "the sform is unusable (the voxel-to-world matrix has a zero or overflowing column); "
            "placed by pixdim's steps at the header's offset");

  nf.qform_code = 1;
  nf.qfac = -1;
  nf.qoffset = {4, 5, 6};
  v = WriteAndLoad(nf, "zero_sform_qform.nii");
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->orientation,
            "file axes i j k on world +x +y -z; the sform is unusable (the voxel-to-world matrix "
            "has a zero or overflowing column); placed by the qform");
  EXPECT_EQ((*v)->origin, (std::array<double, 3>{4, 5, 6 - 2.0 * (nf.dims[2] - 1)}));
  // A well-formed file says nothing.
  NiftiFile plain;
  v = WriteAndLoad(plain, "plain.nii");
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->orientation, "");
}

// An sform or qform whose offset is not a number (or infinite) is passed over as a damaged
// matrix is, and said: it was placed at 0 silently.
TEST(VolumeOrientation, NonFiniteOffsetsAreSaid) {
  for (const float bad : {NAN, INFINITY}) {
    SCOPED_TRACE(bad);
    NiftiFile nf;
    nf.sform_code = 1;
    nf.pixdim = {2, 2, 2};
    nf.sform_offset = {1, bad, 3};
    absl::StatusOr<VolumePtr> v = WriteAndLoad(nf, "bad_sform_offset.nii");
    ASSERT_TRUE(v.ok()) << v.status();
    EXPECT_EQ((*v)->origin, (std::array<double, 3>{0, 0, 0}));
    EXPECT_EQ((*v)->orientation,
              "the sform is unusable (its offset is not a finite number); placed by pixdim's "
              "steps at the header's offset");
    nf.qform_code = 1;
    nf.qoffset = {bad, 5, 6};
    v = WriteAndLoad(nf, "bad_qform_offset.nii");
    ASSERT_TRUE(v.ok()) << v.status();
    EXPECT_EQ((*v)->origin, (std::array<double, 3>{0, 0, 0}));
    EXPECT_EQ((*v)->orientation,
              "the sform is unusable (its offset is not a finite number); the qform is unusable "
              "(its offset is not a finite number); placed by pixdim's steps at the header's "
              "offset");
    // A good sform does not need the qform.
    nf.sform_offset = {1, 2, 3};
    v = WriteAndLoad(nf, "good_sform_bad_qform.nii");
    ASSERT_TRUE(v.ok()) << v.status();
    EXPECT_EQ((*v)->origin, (std::array<double, 3>{1, 2, 3}));
    EXPECT_EQ((*v)->orientation, "");
  }
}

TEST(VolumeOrientation, NearestAxesRefusesSingularAndNonFiniteMatrices) {
  const std::array<int, 3> dims{2, 2, 2};
  EXPECT_FALSE(NearestAxes(Matrix{{{1, 0, 0}, {0, 1, 0}, {0, 0, 0}}}, {0, 0, 0}, dims).ok());
  EXPECT_FALSE(NearestAxes(Matrix{{{1, 1, 0}, {0, 0, 0}, {0, 0, 1}}}, {0, 0, 0}, dims).ok());
  EXPECT_FALSE(NearestAxes(Matrix{{{NAN, 0, 0}, {0, 1, 0}, {0, 0, 1}}}, {0, 0, 0}, dims).ok());
  // Columns whose largest entries share a row: the permutation is chosen as a whole.
  absl::StatusOr<Orientation> o =
      NearestAxes(Matrix{{{1, 0.9, 0}, {0.2, -0.6, 0}, {0, 0, 1}}}, {0, 0, 0}, dims);
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->source, (std::array<int, 3>{0, 1, 2}));
  EXPECT_EQ(o->flip, (std::array<bool, 3>{false, true, false}));
}

// An OpenVDB grid whose transform reverses and swaps axes loads turned onto the world's axes,
// tiles and background gaps inside its box included; a rotated one is refused.
TEST(VolumeOrientation, VdbReversedAndSwappedAxes) {
  auto grid = openvdb::FloatGrid::create(-2.0f);
  grid->setName("turned");
  // Index x steps world -y by 0.5, y steps world +x by 2, z steps world -z by 1.5.
  openvdb::Mat4d m = openvdb::Mat4d::identity();
  m.setRow(0, openvdb::Vec4d(0, -0.5, 0, 0));
  m.setRow(1, openvdb::Vec4d(2, 0, 0, 0));
  m.setRow(2, openvdb::Vec4d(0, 0, -1.5, 0));
  m.setRow(3, openvdb::Vec4d(7, 8, 9, 1));
  grid->setTransform(openvdb::math::Transform::createLinearTransform(m));
  auto acc = grid->getAccessor();
  for (int k = -3; k < 6; ++k)
    for (int j = 5; j < 14; ++j)
      for (int i = -11; i < 2; ++i)
        acc.setValue(openvdb::Coord(i, j, k), float(i * 100 + j * 10 + k));
  // Tiles of 8^3 filling 16^3 at (-32, 16, -8).
  grid->tree().fill(openvdb::CoordBBox(openvdb::Coord(-32, 16, -8), openvdb::Coord(-17, 31, 7)),
                    4.0f, true);
  grid->tree().setValue(openvdb::Coord(5, 5, 5), 9.0f);  // the box reaches x = 5: background gap
  const std::string path = WriteVdb("turned.vdb", {grid});
  absl::StatusOr<VolumePtr> v = LoadVolume(path);
  ASSERT_TRUE(v.ok()) << v.status();
  const Volume& vol = **v;
  EXPECT_EQ(vol.orientation, "file axes i j k on world -y +x -z");
  const openvdb::CoordBBox box(openvdb::Coord(-32, 5, -8), openvdb::Coord(5, 31, 7));
  EXPECT_EQ(vol.dims, (std::array<int, 3>{box.dim().y(), box.dim().x(), box.dim().z()}));
  EXPECT_EQ(vol.spacing, (std::array<double, 3>{2, 0.5, 1.5}));
  const openvdb::FloatGrid::ConstAccessor source = grid->getConstAccessor();
  for (auto it = box.begin(); it; ++it) {
    const openvdb::Vec3d w = grid->indexToWorld(*it);
    int p[3];
    for (int a = 0; a < 3; ++a) {
      const double steps = (w[a] - vol.origin[a]) / vol.spacing[a];
      p[a] = int(std::lround(steps));
      ASSERT_NEAR(steps, p[a], 1e-9) << *it;
      ASSERT_GE(p[a], 0);
      ASSERT_LT(p[a], vol.dims[a]);
    }
    ASSERT_EQ(Sample(vol, p[0], p[1], p[2]), source.getValue(*it)) << *it;
  }
  EXPECT_EQ(vol.min_value, -1100 + 50 - 3);
  EXPECT_EQ(vol.max_value, 100 + 130 + 5);

  auto rotated = openvdb::FloatGrid::create(0.0f);
  rotated->tree().setValue(openvdb::Coord(1, 2, 3), 1.0f);
  rotated->tree().setValue(openvdb::Coord(2, 3, 4), 2.0f);
  rotated->transform().preRotate(0.3, openvdb::math::Z_AXIS);
  ExpectError(LoadVolume(WriteVdb("rotated_turned.vdb", {rotated})),
              absl::StatusCode::kInvalidArgument, "rotated_turned.vdb", "rotated 17.2 degrees");
}

// Turning keeps a sparse grid sparse (tiles move as tiles, gaps stay gaps: making leaves of the
// whole box took 785 MB for these two voxels), and works at the ends of the index range (a box
// ending near INT_MAX overflowed the loop over its leaves and never ended).
TEST(VolumeOrientation, VdbSparseAndAtTheEndsOfTheIndexRange) {
  auto sparse = openvdb::FloatGrid::create(0.0f);
  sparse->tree().setValue(openvdb::Coord(0, 0, 0), 1.0f);
  sparse->tree().setValue(openvdb::Coord(511, 511, 511), 2.0f);
  // An inactive 128^3 tile of another value than the background, inside the box.
  sparse->tree().addTile(2, openvdb::Coord(128, 0, 256), 3.0f, false);
  openvdb::Mat4d m = openvdb::Mat4d::identity();
  m.setRow(0, openvdb::Vec4d(-1, 0, 0, 0));
  sparse->setTransform(openvdb::math::Transform::createLinearTransform(m));
  absl::StatusOr<VolumePtr> v = LoadVolume(WriteVdb("sparse_turned.vdb", {sparse}));
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->grid->tree().leafCount(), 2u);
  EXPECT_EQ(Sample(**v, 511, 0, 0), 1.0f);  // world x = 0 is the last sample along x
  EXPECT_EQ(Sample(**v, 0, 511, 511), 2.0f);
  EXPECT_EQ(Sample(**v, 511 - 130, 5, 300), 3.0f);  // inside the tile, x reversed

  const int top = std::numeric_limits<int>::max();
  for (const int last : {top, top - 1}) {
    SCOPED_TRACE(last);
    auto edge = openvdb::FloatGrid::create(0.0f);
    edge->tree().setValue(openvdb::Coord(last, 0, 0), 5.0f);
    edge->tree().setValue(openvdb::Coord(last - 30, 1, 1), 6.0f);
    edge->tree().addTile(1, openvdb::Coord((last - 20) & ~7, 0, 0), 7.0f, true);
    openvdb::Mat4d e = openvdb::Mat4d::identity();
    e.setRow(0, openvdb::Vec4d(-1, 0, 0, 0));
    e.setRow(3, openvdb::Vec4d(double(top), 0, 0, 1));
    edge->setTransform(openvdb::math::Transform::createLinearTransform(e));
    v = LoadVolume(WriteVdb("edge_turned.vdb", {edge}));
    ASSERT_TRUE(v.ok()) << v.status();
    EXPECT_EQ((*v)->dims, (std::array<int, 3>{31, 8, 8}));  // the tile is 8 deep
    EXPECT_EQ(Sample(**v, 0, 0, 0), 5.0f);
    EXPECT_EQ(Sample(**v, 30, 1, 1), 6.0f);
    EXPECT_EQ(Sample(**v, last - ((last - 20) & ~7), 0, 0), 7.0f);  // the tile's first voxel
  }
}

// Damaged orientation fields fall through to the next source (sform, qform, pixdim), and a
// pixdim is refused only where it is used.
TEST(VolumeOrientation, DamagedFieldsFallThrough) {
  NiftiFile nf;
  nf.qform_code = 1;
  nf.quatern = {NAN, 0, 0};
  nf.pixdim = {2, 2, 2};
  nf.qoffset = {100, 200, 300};
  absl::StatusOr<VolumePtr> v = WriteAndLoad(nf, "nan_quatern.nii");
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->spacing, (std::array<double, 3>{2, 2, 2}));
  EXPECT_EQ((*v)->origin, (std::array<double, 3>{100, 200, 300}));  // the qform's offset stands
  EXPECT_EQ((*v)->orientation,
            "the qform is unusable (its quaternion is not finite); placed by pixdim's steps at "
            "the header's offset");

  nf = NiftiFile();
  nf.sform_code = 1;
  nf.srow = std::array<std::array<float, 3>, 3>{{{0, 3, 0}, {4, 0, 0}, {0, 0, 5}}};
  nf.pixdim = {NAN, 1, 1};  // unused: the sform gives the steps
  v = WriteAndLoad(nf, "nan_pixdim_sform.nii");
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->spacing, (std::array<double, 3>{3, 4, 5}));
  nf.sform_code = 0;  // now pixdim gives them
  ExpectError(WriteAndLoad(nf, "nan_pixdim.nii"), absl::StatusCode::kInvalidArgument,
              "nan_pixdim.nii", "pixdim[1]");
}

// The world box is checked on the world's axes: a swapped file far from the origin whose world
// x steps by 1 loads (the box was once checked again with the file's axes' steps, naming an x
// spacing of 0.05 no world axis has).
TEST(VolumeOrientation, WorldBoxCheckedOnTheWorldAxes) {
  NiftiFile nf;
  nf.dims = {20, 20, 4};
  nf.sform_code = 1;
  nf.srow = std::array<std::array<float, 3>, 3>{{{0, 1, 0}, {0.05f, 0, 0}, {0, 0, 1}}};
  nf.sform_offset = {1e5f, 0, 0};
  absl::StatusOr<VolumePtr> v = WriteAndLoad(nf, "swap_far.nii");
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->origin[0], 1e5);
  EXPECT_NEAR((*v)->spacing[1], 0.05, 1e-8);
}

}  // namespace
}  // namespace isostream
