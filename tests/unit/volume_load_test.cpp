// LoadVolume from files: round trips through real .vdb, .nii, .nii.gz and raw files written here
// (volume_files.h); volume_load_errors_test.cpp has the inputs it refuses.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <openvdb/io/Stream.h>
#include <unistd.h>

#include <atomic>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "server/volume/load.h"
#include "server/volume/loaders.h"
#include "volume_files.h"

namespace isostream {
namespace {

using namespace volume_files;

TEST(VolumeLoadNifti, EveryTypePlainAndGzip) {
  for (const TypeCase& t : kTypeCases) {
    if (t.nifti_code == 0) continue;
    for (bool gz : {false, true}) {
      NiftiFile nf;
      nf.dims = {6, 5, 9};  // 9 planes: a full slab and a one-plane slab
      nf.datatype = t.nifti_code;
      nf.bitpix = static_cast<int16_t>(8 * t.bytes);
      nf.pixdim = {0.5f, -2.0f, 1.25f};  // a negative pixdim is an orientation flip
      const std::string path =
          ScratchPath(std::string("type_") + t.name + (gz ? ".nii.gz" : ".nii"));
      const auto bytes = Concat(nf.Header(), Samples(t.type, nf.dims, false));
      if (gz) {
        WriteGz(path, bytes);
      } else {
        WriteBytes(path, bytes);
      }
      absl::StatusOr<VolumePtr> v = LoadVolume(path);
      ASSERT_TRUE(v.ok()) << v.status();
      EXPECT_EQ((*v)->name, path);
      EXPECT_EQ((*v)->dims, nf.dims);
      EXPECT_EQ((*v)->spacing, (std::array<double, 3>{0.5, 2.0, 1.25}));
      EXPECT_EQ((*v)->origin, (std::array<double, 3>{0, 0, 0}));
      ExpectSamples(**v, [&](int64_t i) { return static_cast<float>(StoredValue(t.type, i)); });
    }
  }
}

TEST(VolumeLoadNifti, ScalingOffsetOriginAndFourthDim) {
  NiftiFile nf;
  nf.dims = {4, 3, 2};
  nf.datatype = 4;  // int16
  nf.bitpix = 16;
  nf.slope = 0.5f;
  nf.inter = -3.0f;
  nf.vox_offset = 416;  // an extension-sized gap to skip
  nf.dim0 = 4;
  nf.dim4 = 1;
  nf.sform_code = 1;
  nf.sform_offset = {-10.5f, 2.0f, 7.25f};
  nf.qform_code = 1;
  nf.qoffset = {99, 99, 99};  // sform wins over qform
  const std::string path = ScratchPath("scaled.nii.gz");
  WriteGz(path, Concat(nf.Header(), Samples(Type::kInt16, nf.dims, false)));
  absl::StatusOr<VolumePtr> v = LoadVolume(path);
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->origin, (std::array<double, 3>{-10.5, 2.0, 7.25}));
  ExpectSamples(
      **v, [](int64_t i) { return static_cast<float>(StoredValue(Type::kInt16, i) * 0.5 - 3.0); });
  // The grid's transform agrees with origin and spacing.
  const openvdb::Vec3d p = (*v)->grid->indexToWorld(openvdb::Coord(1, 2, 1));
  EXPECT_DOUBLE_EQ(p.x(), -9.5);
  EXPECT_DOUBLE_EQ(p.y(), 4.0);
  EXPECT_DOUBLE_EQ(p.z(), 8.25);

  nf.sform_code = 0;  // now the qform offset applies
  nf.qoffset = {1, 2, 3};
  v = WriteAndLoad(nf, "qform.nii", Type::kInt16);
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->origin, (std::array<double, 3>{1, 2, 3}));
}

// The data of a .nii start at 352 at the earliest (nifti1_io reads a smaller vox_offset so):
// read as given, 348-351 took samples from the extension bytes.
TEST(VolumeLoadNifti, VoxOffsetBelow352ReadsFrom352) {
  const NiftiFile nf;
  const std::vector<unsigned char> file =
      Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false));
  for (const float given : {0.0f, 348.0f, 351.0f}) {
    SCOPED_TRACE(given);
    std::vector<unsigned char> bytes = file;
    PutAt<float>(bytes, 108, given, false);
    const std::string path = ScratchPath("vox_offset.nii");
    WriteBytes(path, bytes);
    absl::StatusOr<VolumePtr> v = LoadVolume(path);
    ASSERT_TRUE(v.ok()) << v.status();
    ExpectSamples(**v, [](int64_t i) { return float(StoredValue(Type::kFloat32, i)); });
    EXPECT_EQ((*v)->grid->getName(), "vox_offset.nii");  // the file's name, not its path
  }
  std::vector<unsigned char> bytes = file;
  PutAt<float>(bytes, 108, -4.0f, false);
  const std::string path = ScratchPath("vox_offset.nii");
  WriteBytes(path, bytes);
  absl::StatusOr<VolumePtr> v = LoadVolume(path);
  ASSERT_FALSE(v.ok());
  EXPECT_NE(v.status().message().find("vox_offset -4 is not a byte offset"), std::string::npos)
      << v.status();
  // One that is not a number is no offset either (taken as one, the read began past any file),
  // and one past any file this loader reads is said to be so.
  for (const auto& [given, why] : {std::pair{NAN, " is not a byte offset"},
                                   std::pair{2e9f, " is past any file this loader reads"}}) {
    bytes = file;
    PutAt<float>(bytes, 108, given, false);
    WriteBytes(path, bytes);
    v = LoadVolume(path);
    ASSERT_FALSE(v.ok()) << given;
    EXPECT_EQ(v.status().code(), absl::StatusCode::kInvalidArgument) << v.status();
    EXPECT_NE(v.status().message().find(why), std::string::npos) << v.status();
    EXPECT_NE(v.status().message().find(path + ": vox_offset "), std::string::npos) << v.status();
  }
}

// Scaling that cannot give numbers is a damaged header (it applied the slope and took a NaN
// intercept as 0); a NaN slope is "no scaling", as some writers leave it.
TEST(VolumeLoadNifti, ScalingThatIsNotANumber) {
  NiftiFile nf;
  nf.slope = NAN;
  nf.inter = 5;
  absl::StatusOr<VolumePtr> v = WriteAndLoad(nf, "slope_nan.nii");
  ASSERT_TRUE(v.ok()) << v.status();
  ExpectSamples(**v, [](int64_t i) { return float(StoredValue(Type::kFloat32, i)); });
  for (const auto& [slope, inter] :
       {std::pair{2.0f, NAN}, std::pair{2.0f, INFINITY}, std::pair{INFINITY, 0.0f}}) {
    nf.slope = slope;
    nf.inter = inter;
    v = WriteAndLoad(nf, "scaling.nii");
    ASSERT_FALSE(v.ok());
    EXPECT_NE(v.status().message().find("do not scale samples to numbers"), std::string::npos)
        << v.status();
  }
}

// A 3D volume stored with more dimensions of extent 1 (dim = 5: x, y, z, 1, 1) loads; a second
// time point or component anywhere past the third does not, naming the dims.
TEST(VolumeLoadNifti, DimensionsPastTheThirdOfExtentOne) {
  NiftiFile nf;
  nf.dim0 = 5;
  nf.dim4 = 1;
  std::vector<unsigned char> file = Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false));
  PutAt<int16_t>(file, 50, 1, false);  // dim[5]
  const std::string path = ScratchPath("five_dims.nii");
  WriteBytes(path, file);
  absl::StatusOr<VolumePtr> v = LoadVolume(path);
  ASSERT_TRUE(v.ok()) << v.status();
  ExpectSamples(**v, [](int64_t i) { return float(StoredValue(Type::kFloat32, i)); });
  PutAt<int16_t>(file, 50, 2, false);
  WriteBytes(path, file);
  v = LoadVolume(path);
  ASSERT_FALSE(v.ok());
  EXPECT_NE(v.status().message().find("not a 3D volume (dim = 5, 5, 4, 3, 1, 2)"),
            std::string::npos)
      << v.status();
}

TEST(VolumeLoadNifti, BigEndian) {
  for (const auto& [datatype, type] :
       {std::pair<int16_t, Type>{4, Type::kInt16}, std::pair<int16_t, Type>{64, Type::kFloat64}}) {
    NiftiFile nf;
    nf.big_endian = true;
    nf.dims = {3, 7, 4};
    nf.datatype = datatype;
    nf.bitpix = datatype == 4 ? 16 : 64;
    nf.slope = 2.0f;
    nf.inter = 1.0f;
    nf.pixdim = {3, 3, 3};
    const std::string path = ScratchPath("big_endian_" + std::to_string(datatype) + ".nii");
    WriteBytes(path, Concat(nf.Header(), Samples(type, nf.dims, true)));
    absl::StatusOr<VolumePtr> v = LoadVolume(path);
    ASSERT_TRUE(v.ok()) << v.status();
    EXPECT_EQ((*v)->spacing, (std::array<double, 3>{3, 3, 3}));
    ExpectSamples(**v, [type = type](int64_t i) {
      return static_cast<float>(StoredValue(type, i) * 2.0 + 1.0);
    });
  }
}

// xyzt_units' spatial bits name the unit (time units in the bits above do not change it); a
// rotated file (sform off the axes, turned by Reorient) keeps it.
TEST(VolumeLoadNifti, SpatialUnitsGiveMetersPerUnit) {
  const std::pair<unsigned char, double> cases[] = {
      {0, 0}, {1, 1}, {2, 1e-3}, {3, 1e-6}, {2 | 8, 1e-3}, {3 | 16, 1e-6}, {8, 0}, {5, 0}, {7, 0}};
  for (const auto& [units, meters] : cases) {
    for (const bool turned : {false, true}) {
      NiftiFile nf;
      nf.xyzt_units = units;
      if (turned) {  // file axis i on world -y, j on +x
        nf.sform_code = 1;
        nf.srow = std::array<std::array<float, 3>, 3>{{{0, 1, 0}, {-1, 0, 0}, {0, 0, 1}}};
      }
      absl::StatusOr<VolumePtr> v =
          WriteAndLoad(nf, "units_" + std::to_string(units) + (turned ? "_turned" : "") + ".nii");
      ASSERT_TRUE(v.ok()) << v.status();
      EXPECT_EQ((*v)->meters_per_unit, meters) << int(units);
      EXPECT_EQ((*v)->orientation.empty(), !turned);
    }
  }
}

// ------------------------------------------------------------------------------------------------
// raw

TEST(VolumeLoadRaw, EveryTypeBothByteOrders) {
  const std::array<int, 3> dims{7, 3, 10};
  for (const TypeCase& t : kTypeCases) {
    for (const char* order : {"", ":le", ":be"}) {
      const bool be = std::strcmp(order, ":be") == 0;
      const std::string path = ScratchPath(std::string("raw_") + t.name + (be ? "_be" : "_le"));
      WriteBytes(path, Samples(t.type, dims, be));
      const std::string spec = "raw:" + path + ":7x3x10:" + t.name + order;
      absl::StatusOr<VolumePtr> v = LoadVolume(spec);
      ASSERT_TRUE(v.ok()) << v.status();
      EXPECT_EQ((*v)->name, spec);
      EXPECT_EQ((*v)->dims, dims);
      EXPECT_EQ((*v)->spacing, (std::array<double, 3>{1, 1, 1}));
      ExpectSamples(**v, [&](int64_t i) { return static_cast<float>(StoredValue(t.type, i)); });
    }
  }
}

// A daemon shutting down stops a preparation in the middle of reading a big file: raw and
// NIfTI samples are read slab by slab, each after a look at the stop flag (PrepareVolume passes
// the daemon's).
TEST(VolumeLoadFiles, StopFlagCancelsRawAndNiftiReads) {
  NiftiFile nf;
  nf.dims = {6, 5, 9};
  nf.datatype = 16;  // float32
  nf.bitpix = 32;
  const std::string nii = ScratchPath("stopped.nii"), raw = ScratchPath("stopped.raw");
  WriteBytes(nii, Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false)));
  WriteBytes(raw, Samples(Type::kFloat32, nf.dims, false));
  for (const std::string& spec : {nii, "raw:" + raw + ":6x5x9:float32"}) {
    std::atomic<bool> stop{true};
    ExpectError(LoadVolume(spec, VolumeLimits{}, &stop), absl::StatusCode::kCancelled,
                spec == nii ? nii : raw, "stopped");
    stop = false;
    EXPECT_TRUE(LoadVolume(spec, VolumeLimits{}, &stop).ok()) << spec;
  }
}

// Samples are any bytes: a plain file whose first two are gzip's magic (1f 8b: the first
// float here, 0.744...) is read as it is; it was taken for gzip and refused as corrupt. A raw
// file is compressed only when its name ends in .gz (found by a reviewing helper).
TEST(VolumeLoadRaw, APlainFileStartingLikeGzipIsReadPlainly) {
  std::vector<unsigned char> bytes = Samples(Type::kFloat32, {4, 4, 4}, false);
  const unsigned char magic[4] = {0x1f, 0x8b, 0x3e, 0x3f};
  std::memcpy(bytes.data(), magic, 4);
  float first = 0;
  std::memcpy(&first, magic, 4);
  const std::string path = ScratchPath("gzmagic.raw");
  WriteBytes(path, bytes);
  absl::StatusOr<VolumePtr> v = LoadVolume("raw:" + path + ":4x4x4:float32");
  ASSERT_TRUE(v.ok()) << v.status();
  ExpectSamples(**v, [&](int64_t i) {
    return i == 0 ? first : static_cast<float>(StoredValue(Type::kFloat32, i));
  });
  WriteGz(path + ".gz", bytes);  // named so, it is gunzipped
  absl::StatusOr<VolumePtr> gz = LoadVolume("raw:" + path + ".gz:4x4x4:float32");
  ASSERT_TRUE(gz.ok()) << gz.status();
  EXPECT_EQ((*gz)->min_value, (*v)->min_value);
}

TEST(VolumeLoadRaw, PathMayContainColons) {
  const std::string dir = ScratchPath("a:b");
  ASSERT_EQ(mkdir(dir.c_str(), 0755), 0);
  const std::string path = dir + "/c:d.raw";
  WriteBytes(path, Samples(Type::kUint8, {2, 2, 2}, false));
  absl::StatusOr<VolumePtr> v = LoadVolume("raw:" + path + ":2x2x2:uint8:le");
  ASSERT_TRUE(v.ok()) << v.status();
  ExpectSamples(**v, [](int64_t i) { return static_cast<float>(StoredValue(Type::kUint8, i)); });
}

TEST(VolumeLoadVdb, FirstFloatGridAndNamedGrid) {
  auto ints = openvdb::Int32Grid::create(5);
  ints->setName("labels");
  ints->tree().setValue(openvdb::Coord(0), 1);
  const std::string path =
      WriteVdb("two_grids.vdb", {ints, TestGrid("density", 1.0f), TestGrid("temperature", -0.5f)});
  for (const auto& [spec, scale] : {std::pair<std::string, float>{path, 1.0f},
                                    std::pair<std::string, float>{path + "#temperature", -0.5f}}) {
    absl::StatusOr<VolumePtr> v = LoadVolume(spec);
    ASSERT_TRUE(v.ok()) << v.status();
    const Volume& vol = **v;
    EXPECT_EQ(vol.name, spec);
    EXPECT_EQ(vol.index_min, (std::array<int, 3>{-3, 5, 7}));
    EXPECT_EQ(vol.dims, (std::array<int, 3>{10, 9, 12}));
    EXPECT_EQ(vol.spacing, (std::array<double, 3>{0.5, 0.25, 2.0}));
    EXPECT_EQ(vol.origin, (std::array<double, 3>{1 - 1.5, 2 + 1.25, 3 + 14.0}));
    ExpectSamples(vol, [&](int64_t index) {
      const int i = static_cast<int>(index % 10) - 3, j = static_cast<int>(index / 10 % 9) + 5,
                k = static_cast<int>(index / 90) + 7;
      if (i == 0 && j == 6 && k == 8) return 123.0f;
      return scale * (i * 3 + j * 5 - k * 7);
    });
  }
  // A grid name may hold '#': everything after the first ".vdb#" names the grid.
  const std::string hashed = WriteVdb("hashed.vdb", {TestGrid("heat#2", 2.0f)});
  absl::StatusOr<VolumePtr> v = LoadVolume(hashed + "#heat#2");
  ASSERT_TRUE(v.ok()) << v.status();
  // What the file holds is named, to choose from.
  ExpectError(LoadVolume(hashed + "#heat"), absl::StatusCode::kNotFound,
              "no grid named 'heat'; it holds 'heat#2' (Tree_float_5_4_3)");
}

// A catalogue file replaced by renaming a new one over its name, between the loader's opening
// it and OpenVDB's reading it: the structure check and every read must see the file opened
// (reopening by name would read the new file, and a damaged one unchecked).
TEST(VolumeLoadVdb, ReadsTheFileItOpenedWhenItsNameIsReplaced) {
  for (const int grids : {1, 2}) {  // one grid: read through a stream; two: by name
    SCOPED_TRACE(grids);
    const std::string path = ScratchPath("replaced" + std::to_string(grids) + ".vdb");
    auto write = [&](const std::string& to, float scale) {
      openvdb::GridPtrVec v;
      v.push_back(TestGrid("density", scale));
      if (grids == 2) v.push_back(TestGrid("other", -scale));
      std::rename(WriteVdb("staged.vdb", v).c_str(), to.c_str());
    };
    write(path, 1.0f);
    const int fd = open(path.c_str(), O_RDONLY | O_CLOEXEC);
    ASSERT_GE(fd, 0);
    for (const bool damaged : {false, true}) {
      write(path, 2.0f);
      if (damaged) {
        std::vector<unsigned char> bytes = ReadBytes(path);
        bytes.resize(bytes.size() * 2 / 3);
        WriteBytes(path + ".new", bytes);
        std::rename((path + ".new").c_str(), path.c_str());
        ExpectError(LoadVolume(path), absl::StatusCode::kDataLoss, "corrupt OpenVDB file");
      }
      absl::StatusOr<VolumePtr> v = LoadVdbOpenFile(fd, path, path, "density", VolumeLimits{});
      ASSERT_TRUE(v.ok()) << v.status();
      EXPECT_EQ((*v)->dims, (std::array<int, 3>{10, 9, 12}));
      EXPECT_EQ(Sample(**v, 9, 8, 11), 6 * 3 + 13 * 5 - 18 * 7);  // scale 1: the opened file
    }
    close(fd);
  }
}

TEST(VolumeLoadVdb, TilesAndBackgroundInsideTheBox) {
  auto grid = openvdb::FloatGrid::create(-2.0f);
  grid->setName("tiles");
  grid->tree().fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(15)), 4.0f, true);
  grid->tree().setValue(openvdb::Coord(20, 3, 3), 9.0f);  // box x extends to 20: background gap
  const std::string path = WriteVdb("tiles.vdb", {grid});
  absl::StatusOr<VolumePtr> v = LoadVolume(path);
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->dims, (std::array<int, 3>{21, 16, 16}));
  EXPECT_EQ((*v)->min_value, -2.0f);
  EXPECT_EQ((*v)->max_value, 9.0f);
  EXPECT_EQ(Sample(**v, 3, 3, 3), 4.0f);
  EXPECT_EQ(Sample(**v, 18, 3, 3), -2.0f);
  EXPECT_EQ(Sample(**v, 20, 3, 3), 9.0f);
}

// The files OpenVDB writes in its other ways pass the framing check (vdb_structure.h) and load
// the same samples: half-float storage, an instance sharing its parent's tree, file-level
// metadata of several types, uncompressed and zip-compressed data, and a stream written without
// grid offsets.
TEST(VolumeLoadVdb, EveryWayOfWritingLoads) {
  auto expect_test_grid = [](const std::string& spec, float tolerance) {
    SCOPED_TRACE(spec);
    absl::StatusOr<VolumePtr> v = LoadVolume(spec);
    ASSERT_TRUE(v.ok()) << v.status();
    EXPECT_EQ((*v)->dims, (std::array<int, 3>{10, 9, 12}));
    EXPECT_NEAR(Sample(**v, 9, 8, 11), 6 * 3 + 13 * 5 - 18 * 7, tolerance);
  };
  auto half = TestGrid("half", 1.0f);
  half->setSaveFloatAsHalf(true);
  expect_test_grid(WriteVdb("half.vdb", {half}), 0.25f);

  // Tiles at the root (outside the active box: a tile of the root is 4096^3 voxels) and inside
  // an internal node, beside the leaves.
  auto tiled = TestGrid("tiled", 1.0f);
  tiled->tree().addTile(3, openvdb::Coord(1 << 20), 5.0f, false);
  tiled->tree().addTile(2, openvdb::Coord(-(1 << 16)), 6.0f, false);
  ASSERT_EQ(tiled->tree().root().getTableSize(), tiled->tree().root().childCount() + 1);
  expect_test_grid(WriteVdb("tiled.vdb", {tiled}), 0);

  auto parent = TestGrid("parent", 1.0f);
  auto instance = parent->copyGrid();  // shares the tree: written as an instance
  instance->setName("instance");
  expect_test_grid(WriteVdb("instance.vdb", {parent, instance}) + "#instance", 0);

  openvdb::MetaMap meta;
  meta.insertMeta("author", openvdb::StringMetadata("isostream tests"));
  meta.insertMeta("flag", openvdb::BoolMetadata(true));
  meta.insertMeta("frame", openvdb::Int64Metadata(42));
  meta.insertMeta("matrix", openvdb::Mat4DMetadata(openvdb::Mat4d::identity()));
  meta.insertMeta("empty", openvdb::StringMetadata(""));
  for (const uint32_t compression :
       {uint32_t{openvdb::io::COMPRESS_NONE}, uint32_t{openvdb::io::COMPRESS_ACTIVE_MASK},
        uint32_t{openvdb::io::COMPRESS_ZIP} | uint32_t{openvdb::io::COMPRESS_ACTIVE_MASK}})
    for (const bool as_half : {false, true}) {
      const std::string path =
          ScratchPath("meta_" + std::to_string(compression) + (as_half ? "_half" : "") + ".vdb");
      auto grid = TestGrid("density", 1.0f);
      grid->setSaveFloatAsHalf(as_half);
      openvdb::io::File file(path);
      file.setCompression(compression);
      file.write({grid}, meta);
      file.close();
      expect_test_grid(path, as_half ? 0.25f : 0);
    }

  // Grids of 7 and of 49 leaves: OpenVDB pads their delayed-load metadata's 49-127 byte parts
  // to 128 bytes before compressing them.
  for (const int leaves : {7, 49}) {
    auto row = openvdb::FloatGrid::create(0.0f);
    row->setName("row");
    for (int i = 0; i < leaves; ++i)
      row->tree().setValue(openvdb::Coord(8 * i, i % 2, i % 2), 1.0f);
    absl::StatusOr<VolumePtr> v =
        LoadVolume(WriteVdb("row" + std::to_string(leaves) + ".vdb", {row}));
    ASSERT_TRUE(v.ok()) << leaves << " leaves: " << v.status();
    EXPECT_EQ((*v)->dims[0], 8 * (leaves - 1) + 1);
  }

  // A frustum transform on another grid, and names longer than 64 KiB.
  auto frustum = openvdb::Vec3SGrid::create();
  frustum->setName("velocity");
  frustum->setTransform(openvdb::math::Transform::createFrustumTransform(
      openvdb::BBoxd(openvdb::Vec3d(0), openvdb::Vec3d(16)), 0.5, 10.0, 1.0));
  frustum->tree().setValue(openvdb::Coord(1), openvdb::Vec3s(1, 2, 3));
  expect_test_grid(WriteVdb("frustum_beside.vdb", {frustum, TestGrid("density", 1.0f)}), 0);
  const std::string long_name(70000, 'n');
  auto named = TestGrid(long_name, 1.0f);
  named->insertMeta(std::string(70000, 'm'), openvdb::Int32Metadata(1));
  expect_test_grid(WriteVdb("long_names.vdb", {named}), 0);

  const std::string stream_path = ScratchPath("stream.vdb");
  {
    std::ofstream out(stream_path, std::ios::binary);
    openvdb::io::Stream(out).write({TestGrid("density", 1.0f)});
  }
  expect_test_grid(stream_path, 0);
}

// Voxels of 10 microns in metres are real data (OpenVDB's transforms refuse their scale): they
// load with their spacing and origin; a world box past the single-precision range does not.
TEST(VolumeLoadNifti, TinyAndHugeSpacing) {
  NiftiFile nf;
  nf.pixdim = {1e-5f, 1e-5f, 2e-5f};
  nf.sform_code = 1;
  nf.sform_offset = {0.25f, -0.5f, 1e-3f};
  const std::string tiny = ScratchPath("tiny.nii");
  WriteBytes(tiny, Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false)));
  absl::StatusOr<VolumePtr> v = LoadVolume(tiny);
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->spacing, (std::array<double, 3>{double(1e-5f), double(1e-5f), double(2e-5f)}));
  EXPECT_EQ((*v)->origin, (std::array<double, 3>{0.25, -0.5, double(1e-3f)}));

  // Unset (0): unit spacing, as other readers take it. Not a number: a damaged header.
  nf.pixdim = {0, 2, 0};
  v = WriteAndLoad(nf, "unset.nii");
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->spacing, (std::array<double, 3>{1, 2, 1}));
  for (float broken : {std::nanf(""), std::numeric_limits<float>::infinity()}) {
    nf.pixdim = {1, 1, broken};
    ExpectError(WriteAndLoad(nf, "damaged.nii"), absl::StatusCode::kInvalidArgument, "damaged.nii",
                "pixdim[3] (the voxel spacing) is not a finite number");
  }

  nf.pixdim = {3e38f, 3e38f, 3e38f};
  const std::string huge = ScratchPath("huge.nii");
  WriteBytes(huge, Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false)));
  ExpectError(LoadVolume(huge), absl::StatusCode::kInvalidArgument, "huge.nii", "spacing");
  nf.pixdim = {1e29f, 1, 1};  // a valid step, but the box reaches 4e29 then past 1e30
  nf.dims = {12, 4, 3};
  const std::string wide = ScratchPath("wide.nii");
  WriteBytes(wide, Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false)));
  ExpectError(LoadVolume(wide), absl::StatusCode::kInvalidArgument, "wide.nii", "x extent");
}

// Positions are single precision: a box far from the origin loads only while its cells stay
// several float steps wide. An origin of 1e17 with unit spacing once loaded and put every
// vertex at one point.
TEST(VolumeLoadNifti, OriginFarFromZero) {
  NiftiFile nf;
  nf.sform_code = 1;
  nf.pixdim = {12.5f, 12.5f, 12.5f};
  nf.sform_offset = {5e5f, 6e6f, -3e3f};  // geodetic metres: ~25 float steps per cell
  const std::string survey = ScratchPath("survey.nii");
  WriteBytes(survey, Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false)));
  absl::StatusOr<VolumePtr> v = LoadVolume(survey);
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->origin[1], 6e6);

  nf.pixdim = {1, 1, 1};
  nf.sform_offset = {0, 1e17f, 0};
  const std::string far = ScratchPath("far.nii");
  WriteBytes(far, Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false)));
  ExpectError(LoadVolume(far), absl::StatusCode::kInvalidArgument, "far.nii",
              "y spacing 1 at coordinates up to 1e+17 cannot be told apart in single-precision");
}

}  // namespace
}  // namespace isostream
