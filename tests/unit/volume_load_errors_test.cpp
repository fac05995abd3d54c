// LoadVolume's refusals: every malformed, truncated, out-of-range or unsupported input is answered
// with the right status and a message naming the input (files written by volume_files.h).
#include <gtest/gtest.h>
#include <openvdb/io/Stream.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "server/volume/load.h"
#include "server/volume/volume_spec.h"
#include "volume_files.h"

namespace isostream {
namespace {

using namespace volume_files;

TEST(VolumeLoadErrors, MissingFiles) {
  for (const std::string name : {"missing.nii", "missing.nii.gz", "missing.vdb"}) {
    ExpectError(LoadVolume(ScratchPath(name)), absl::StatusCode::kNotFound, name);
  }
  ExpectError(LoadVolume("raw:" + ScratchPath("missing.raw") + ":2x2x2:uint8"),
              absl::StatusCode::kNotFound, "missing.raw");
  ExpectError(LoadVolume(ScratchPath("missing.vdb") + "#density"), absl::StatusCode::kNotFound,
              "missing.vdb");
}

TEST(VolumeLoadErrors, NotAVolumeFile) {
  const std::string text = ScratchPath("notes.txt");
  WriteBytes(text, {'h', 'i'});
  ExpectError(LoadVolume(text), absl::StatusCode::kInvalidArgument, "notes.txt");
  // Refused for its name, there or not: no loader reads it either way.
  ExpectError(LoadVolume(ScratchPath("missing.txt")), absl::StatusCode::kInvalidArgument,
              "missing.txt", "unrecognised volume type");
  ExpectError(LoadVolume(ScratchDir() + "/.."), absl::StatusCode::kInvalidArgument, "..");
  const std::string dir = ScratchPath("dir.nii");
  ASSERT_EQ(mkdir(dir.c_str(), 0755), 0);
  ExpectError(LoadVolume(dir), absl::StatusCode::kInvalidArgument, "dir.nii");
}

TEST(VolumeLoadErrors, WrongMagic) {
  NiftiFile nf;
  nf.magic = "n+2";
  std::string path = ScratchPath("bad_magic.nii");
  WriteBytes(path, Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false)));
  ExpectError(LoadVolume(path), absl::StatusCode::kInvalidArgument, "bad_magic.nii", "magic");

  nf = NiftiFile();
  nf.sizeof_hdr = 540;  // NIfTI-2
  path = ScratchPath("nifti2.nii");
  WriteBytes(path, Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false)));
  ExpectError(LoadVolume(path), absl::StatusCode::kInvalidArgument, "nifti2.nii", "sizeof_hdr");

  nf = NiftiFile();
  nf.magic = "ni1";
  path = ScratchPath("pair.nii");
  WriteBytes(path, nf.Header());
  ExpectError(
      LoadVolume(path), absl::StatusCode::kInvalidArgument, "pair.nii",
      "NIfTI-1 header/image pair (.hdr/.img) is not supported; convert to a single .nii file");

  path = ScratchPath("garbage.vdb");
  WriteBytes(path, std::vector<unsigned char>(200, 0x42));
  ExpectError(LoadVolume(path), absl::StatusCode::kInvalidArgument, "garbage.vdb", "magic");
}

// Each fault the structure walk knows, from the header to a leaf's value chunk, is refused before
// OpenVDB reads the file (it would allocate what a count claims, loop on it, or overflow a
// buffer): DataLoss naming the byte and the fault.
// A name in the file reaches the message escaped: a transform named "Z\n[FAKE]..." wrote a
// line of its own into the daemon's log, and escape sequences reached the terminal.
TEST(VolumeLoadErrors, NamesFromTheFileArePrintedEscaped) {
  std::vector<unsigned char> bytes = ReadBytes(WriteVdb("inject.vdb", {TestGrid("density", 1.0f)}));
  const std::string map = "ScaleTranslateMap", forged = "Z\n[FAKE]\x1b[31mpwn!";
  ASSERT_EQ(forged.size(), map.size());
  const auto at = std::search(bytes.begin(), bytes.end(), map.begin(), map.end());
  ASSERT_NE(at, bytes.end());
  std::copy(forged.begin(), forged.end(), at);
  const std::string path = ScratchPath("inject.vdb");
  WriteBytes(path, bytes);
  const absl::StatusOr<VolumePtr> v = LoadVolume(path);
  ASSERT_FALSE(v.ok());
  const std::string message(v.status().message());
  EXPECT_NE(message.find("Z\\x0a[FAKE]\\x1b[31mpwn!"), std::string::npos) << message;
  EXPECT_EQ(message.find_first_of("\n\x1b"), std::string::npos) << message;
}

TEST(VolumeLoadErrors, DamagedVdbFraming) {
  const std::vector<unsigned char> good =
      ReadBytes(WriteVdb("framing.vdb", {TestGrid("density", 1.0f)}));
  // Offset of the 4-byte length field in front of string `s` (its first occurrence).
  auto length_of = [&](const std::string& s) {
    const auto at = std::search(good.begin(), good.end(), s.begin(), s.end());
    EXPECT_NE(at, good.end()) << s;
    return size_t(at - good.begin()) - 4;
  };
  auto patched = [&](const std::string& name, size_t at, uint32_t value) {
    std::vector<unsigned char> bytes = good;
    PutAt<uint32_t>(bytes, at, value, false);
    const std::string path = ScratchPath(name);
    WriteBytes(path, bytes);
    return path;
  };
  struct Case {
    const char* name;
    size_t at;
    uint32_t value;
    const char* says;
    size_t reported_at;  // where the message says the fault is (root counts: both at the first)
  };
  const size_t map = length_of("ScaleTranslateMap");
  const size_t root_tiles = map + 4 + 17 + 6 * 24 + 4 + 4;
  // The descriptor: unique name, type, an empty instance parent name, then the grid, block and
  // end offsets; the grid starts with its compression flags, and its metadata names it again.
  const size_t offsets = length_of("Tree_float_5_4_3") + 4 + 16 + 4;
  int64_t grid_pos = 0, block_pos = 0;
  std::memcpy(&grid_pos, good.data() + offsets, 8);
  std::memcpy(&block_pos, good.data() + offsets + 8, 8);
  const std::string density = "density";
  const size_t name_meta =
      size_t(std::search(good.begin() + grid_pos, good.end(), density.begin(), density.end()) -
             good.begin());
  uint32_t leaf_mask = 0;
  std::memcpy(&leaf_mask, good.data() + block_pos, 4);
  const size_t grid_count = length_of("density") - 4;
  uint32_t first_child_x = 0;  // the root's first child's origin follows its two counts
  std::memcpy(&first_child_x, good.data() + root_tiles + 8, 4);
  const Case cases[] = {
      {"uuid.vdb", 24, 0x7a7a7a7au, "file UUID is malformed", 0},
      {"offset_flag.vdb", 20, 2, "grid offset flag is 2", 0},
      {"compression.vdb", size_t(grid_pos), 0xff, "compression flags 255", 0},
      {"map_type.vdb", map + 4, 0x6c616358u, "unknown transform 'XcaleTranslateMap'", map},
      {"buffers.vdb", map + 4 + 17 + 6 * 24, 2, "has 2 buffers", 0},
      {"name_meta.vdb", name_meta, 0x736e6578u, "'density' in its descriptor and 'xensity'",
       grid_count},
      {"leaf_mask.vdb", size_t(block_pos), leaf_mask ^ 1u, "leaf mask differs from its topology",
       0},
      {"string_length.vdb", length_of("file_compression"), 0x7f000000u, "metadata name claims", 0},
      {"value_size.vdb", length_of("file_bbox_max") + 4 + 13 + 4 + 5, 0x7f000000u,
       "'file_bbox_max' (vec3i) claims", 0},
      {"typed_size.vdb", length_of("file_bbox_max") + 4 + 13 + 4 + 5, 16, "its type 12", 0},
      {"metadata_count.vdb", length_of("file_bbox_max") - 4, 0x01000000u, "claims 16777216", 0},
      {"grid_name.vdb", length_of("density"), 0xffffffffu, "grid name claims", 0},
      {"transform.vdb", map, 0x7f000000u, "transform type claims", 0},
      {"root_tiles.vdb", root_tiles, 0x10000000u, "root claims 268435456 tiles", 0},
      {"root_children.vdb", root_tiles + 4, 3, "and 3 children", root_tiles},
      // One bit off a multiple of 4096: OpenVDB would never find the child, and its samples
      // read as the background (the file loaded, its range quietly smaller).
      {"root_origin.vdb", root_tiles + 8, first_child_x + 1, "is not a multiple of 4096", 0},
      {"grid_count.vdb", grid_count, 0x10000000u, "grid count 268435456 does not fit the file", 0},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string path = patched(c.name, c.at, c.value);
    ExpectError(LoadVolume(path), absl::StatusCode::kDataLoss, c.name, c.says);
    ExpectError(LoadVolume(path), absl::StatusCode::kDataLoss,
                "byte " + std::to_string(c.reported_at ? c.reported_at : c.at) + ":");
  }
  // 64-bit fields: a grid's end past the file, and the first leaf's value chunk size (after its
  // 64-byte mask and flag byte) made raw and wrong, or one byte off its Blosc header's.
  int64_t chunk = 0;
  std::memcpy(&chunk, good.data() + block_pos + 65, 8);
  const struct {
    const char* name;
    size_t at;
    int64_t value;
    const char* says;
    size_t reported_at;
  } wide[] = {
      {"end_pos.vdb", offsets + 16, int64_t(good.size()) + 1, "lie outside the file", offsets},
      {"raw_chunk.vdb", size_t(block_pos) + 65, -1000, "holds a raw chunk sized -1000", 0},
      {"blosc_chunk.vdb", size_t(block_pos) + 65, chunk + 1, "Blosc chunk of another size", 0},
      // The values said to start 8 bytes after the topology does end.
      {"topology_end.vdb", offsets + 8, block_pos + 8, "topology ends 8 bytes before its values",
       size_t(block_pos)},
  };
  for (const auto& c : wide) {
    SCOPED_TRACE(c.name);
    std::vector<unsigned char> bytes = good;
    PutAt<int64_t>(bytes, c.at, c.value, false);
    const std::string path = ScratchPath(c.name);
    WriteBytes(path, bytes);
    ExpectError(LoadVolume(path), absl::StatusCode::kDataLoss, c.name, c.says);
    ExpectError(LoadVolume(path), absl::StatusCode::kDataLoss,
                "byte " + std::to_string(c.reported_at ? c.reported_at : c.at) + ":");
  }
  // A sound file this build does not read: an old format version.
  ExpectError(LoadVolume(patched("old.vdb", 8, 221)), absl::StatusCode::kInvalidArgument, "old.vdb",
              "file format version 221");
}

// Files whose grids OpenVDB would find or read other than the walk did: a grid that does not
// start right after its descriptor (io::Stream reads it from there), an instance of a grid of
// another type, a float and an int grid of one name (OpenVDB reads the first of a name), and a
// stream-written non-float grid (read whole at open).
TEST(VolumeLoadErrors, GridsTheWalkDoesNotVouchFor) {
  openvdb::initialize();
  // Gap: 12 bytes inserted after the descriptor, its three offsets moved past them.
  std::vector<unsigned char> bytes =
      ReadBytes(WriteVdb("gap_source.vdb", {TestGrid("density", 1.0f)}));
  const std::string type = "Tree_float_5_4_3";
  const size_t offsets =
      size_t(std::search(bytes.begin(), bytes.end(), type.begin(), type.end()) - bytes.begin()) +
      type.size() + 4;
  int64_t pos[3];
  std::memcpy(pos, bytes.data() + offsets, sizeof(pos));
  for (int64_t& p : pos) p += 12;
  std::memcpy(bytes.data() + offsets, pos, sizeof(pos));
  bytes.insert(bytes.begin() + int64_t(offsets) + 24, 12, 0);
  const std::string gap = ScratchPath("gap.vdb");
  WriteBytes(gap, bytes);
  ExpectError(LoadVolume(gap), absl::StatusCode::kDataLoss, "gap.vdb",
              "does not start right after its descriptor");

  // Instance: "instancegrid" shares "parentgrid"'s tree; its parent field is pointed at an int
  // grid's name of the same length.
  auto parent = TestGrid("parentgrid", 1.0f);
  auto instance = parent->copyGrid();
  instance->setName("instancegrid");
  auto ints = openvdb::Int32Grid::create(0);
  ints->setName("intgrid___");
  ints->tree().setValue(openvdb::Coord(0), 1);
  bytes = ReadBytes(WriteVdb("instance_source.vdb", {parent, instance, ints}));
  const std::string inst = "instancegrid", par = "parentgrid";
  const auto inst_at = std::search(bytes.begin(), bytes.end(), inst.begin(), inst.end());
  const auto par_at = std::search(inst_at, bytes.end(), par.begin(), par.end());
  ASSERT_NE(par_at, bytes.end());
  std::memcpy(&*par_at, "intgrid___", 10);
  const std::string wrong_parent = ScratchPath("wrong_parent.vdb");
  WriteBytes(wrong_parent, bytes);
  ExpectError(LoadVolume(wrong_parent + "#instancegrid"), absl::StatusCode::kDataLoss,
              "wrong_parent.vdb", "is an instance of no grid of its type");

  auto same = openvdb::Int32Grid::create(0);
  same->setName("a");
  same->tree().setValue(openvdb::Coord(0), 1);
  ExpectError(LoadVolume(WriteVdb("same_name.vdb", {same, TestGrid("a", 1.0f)})),
              absl::StatusCode::kInvalidArgument, "same_name.vdb", "both named 'a'");

  const std::string stream = ScratchPath("int_stream.vdb");
  {
    std::ofstream out(stream, std::ios::binary);
    openvdb::io::Stream(out).write({ints});
  }
  ExpectError(LoadVolume(stream), absl::StatusCode::kInvalidArgument, "int_stream.vdb",
              "holds no float grid");
  // A stream of several grids is read whole at open, whichever grid was asked for.
  const std::string two = ScratchPath("two_stream.vdb");
  {
    std::ofstream out(two, std::ios::binary);
    openvdb::io::Stream(out).write({TestGrid("a", 1.0f), TestGrid("b", 2.0f)});
  }
  ExpectError(LoadVolume(two + "#b"), absl::StatusCode::kInvalidArgument, "two_stream.vdb",
              "several grids written without grid offsets");
}

// A file of no grids is named as empty; one without a float grid lists what it holds, the
// first eight grids of them.
TEST(VolumeLoadErrors, WhatAFileWithoutAFloatGridHolds) {
  ExpectError(LoadVolume(WriteVdb("no_grids.vdb", {})), absl::StatusCode::kDataLoss, "no_grids.vdb",
              "holds no grids (an empty or truncated file)");
  openvdb::GridPtrVec ints;
  for (int i = 0; i < 9; ++i) {
    auto g = openvdb::Int32Grid::create(0);
    g->setName("g" + std::to_string(i));
    g->tree().setValue(openvdb::Coord(i), 1);
    ints.push_back(g);
  }
  const absl::StatusOr<VolumePtr> v = LoadVolume(WriteVdb("nine_ints.vdb", ints));
  ExpectError(v, absl::StatusCode::kInvalidArgument, "nine_ints.vdb",
              ": no float grid; it holds 'g0' (Tree_int32_5_4_3), 'g1' (Tree_int32_5_4_3)");
  const std::string message(v.status().message());
  EXPECT_NE(message.find("'g7' (Tree_int32_5_4_3), ..."), std::string::npos) << message;
  EXPECT_EQ(message.find("'g8'"), std::string::npos) << message;
}

TEST(VolumeLoadErrors, TruncatedData) {
  NiftiFile nf;
  const auto full = Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false));
  const std::vector<unsigned char> cut(full.begin(), full.end() - 5);
  std::string path = ScratchPath("short.nii");
  WriteBytes(path, cut);
  ExpectError(LoadVolume(path), absl::StatusCode::kDataLoss, "short.nii", "truncated");
  path = ScratchPath("short.nii.gz");
  WriteGz(path, cut);
  ExpectError(LoadVolume(path), absl::StatusCode::kDataLoss, "short.nii.gz", "truncated");

  // A gzip stream cut in the middle, not just short data inside a whole stream.
  WriteGz(ScratchPath("whole.nii.gz"), full);
  std::vector<unsigned char> gz = ReadBytes(ScratchPath("whole.nii.gz"));
  gz.resize(gz.size() / 2);
  path = ScratchPath("cut_stream.nii.gz");
  WriteBytes(path, gz);
  ExpectError(LoadVolume(path), absl::StatusCode::kDataLoss, "cut_stream.nii.gz");
  {
    // The path once: zlib's message repeated it ("x.gz: corrupt ...: x.gz: unexpected end").
    const std::string message(LoadVolume(path).status().message());
    EXPECT_EQ(message.find(path), message.rfind(path)) << message;
  }

  path = ScratchPath("short_header.nii");
  WriteBytes(path, std::vector<unsigned char>(full.begin(), full.begin() + 200));
  ExpectError(LoadVolume(path), absl::StatusCode::kDataLoss, "short_header.nii", "header");

  path = ScratchPath("short.raw");
  WriteBytes(path, Samples(Type::kUint16, {4, 4, 3}, false));
  ExpectError(LoadVolume("raw:" + path + ":4x4x4:uint16"), absl::StatusCode::kDataLoss, "short.raw",
              "truncated");

  const std::string vdb = WriteVdb("whole.vdb", {TestGrid("density", 1.0f)});
  std::vector<unsigned char> bytes = ReadBytes(vdb);
  // OpenVDB itself misses a tail of 1-7 bytes (the last voxels read as garbage).
  // 8 bytes: the magic alone, no grids.
  for (size_t keep :
       {size_t{8}, bytes.size() / 2, bytes.size() - 10, bytes.size() - 7, bytes.size() - 1}) {
    path = ScratchPath("short_" + std::to_string(keep) + ".vdb");
    WriteBytes(path, std::vector<unsigned char>(bytes.begin(), bytes.begin() + keep));
    ExpectError(LoadVolume(path), absl::StatusCode::kDataLoss, path);
  }
}

TEST(VolumeLoadErrors, RawFileLargerThanSpec) {
  const std::string path = ScratchPath("long.raw");
  WriteBytes(path, Samples(Type::kUint8, {4, 4, 5}, false));
  ExpectError(LoadVolume("raw:" + path + ":4x4x4:uint8"), absl::StatusCode::kInvalidArgument,
              "long.raw");
}

// A compressed raw file's size is known only once read: surplus samples are refused all the
// same (they mean wrong dims or type, which would load as plausible garbage).
TEST(VolumeLoadErrors, GzipRawFileLargerThanSpec) {
  const std::string path = ScratchPath("long.raw.gz");
  WriteGz(path, Samples(Type::kUint8, {4, 4, 5}, false));
  ExpectError(LoadVolume("raw:" + path + ":4x4x4:uint8"), absl::StatusCode::kInvalidArgument,
              "long.raw.gz", "more than the 64 bytes");
  absl::StatusOr<VolumePtr> exact = LoadVolume("raw:" + path + ":4x4x5:uint8");
  ASSERT_TRUE(exact.ok()) << exact.status();
  // The suffix in any case, as NIfTI's ".nii.gz" is: ".GZ" was read as plain bytes.
  const std::string upper = ScratchPath("upper.raw.GZ");
  WriteGz(upper, Samples(Type::kUint8, {4, 4, 5}, false));
  absl::StatusOr<VolumePtr> from_upper = LoadVolume("raw:" + upper + ":4x4x5:uint8");
  ASSERT_TRUE(from_upper.ok()) << from_upper.status();
  const auto a = (*exact)->grid->getConstAccessor(), b = (*from_upper)->grid->getConstAccessor();
  for (int z = 0; z < 5; ++z)
    for (int y = 0; y < 4; ++y)
      for (int x = 0; x < 4; ++x) {
        const auto& m = (*exact)->index_min;
        const openvdb::Coord ijk(m[0] + x, m[1] + y, m[2] + z);
        ASSERT_EQ(a.getValue(ijk), b.getValue(ijk)) << ijk;
      }
}

TEST(VolumeLoadErrors, DimsBelowTwo) {
  NiftiFile nf;
  nf.dims = {4, 1, 4};
  const std::string path = ScratchPath("flat.nii");
  WriteBytes(path, Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false)));
  ExpectError(LoadVolume(path), absl::StatusCode::kInvalidArgument, "flat.nii", "4x1x4");

  const std::string raw = ScratchPath("flat.raw");
  WriteBytes(raw, Samples(Type::kUint8, {1, 4, 4}, false));
  ExpectError(LoadVolume("raw:" + raw + ":1x4x4:uint8"), absl::StatusCode::kInvalidArgument,
              "flat.raw");

  auto grid = openvdb::FloatGrid::create();
  grid->tree().setValue(openvdb::Coord(0, 0, 0), 1.0f);
  grid->tree().setValue(openvdb::Coord(3, 0, 3), 1.0f);
  const std::string vdb = WriteVdb("flat.vdb", {grid});
  ExpectError(LoadVolume(vdb), absl::StatusCode::kInvalidArgument, "flat.vdb");

  const std::string empty = WriteVdb("empty.vdb", {openvdb::FloatGrid::create()});
  ExpectError(LoadVolume(empty), absl::StatusCode::kInvalidArgument, "empty.vdb", "no active");

  nf = NiftiFile();
  nf.dim0 = 4;
  nf.dim4 = 2;  // a time series
  const std::string series = ScratchPath("series.nii");
  WriteBytes(series, Concat(nf.Header(), Samples(Type::kFloat32, {5, 4, 6}, false)));
  ExpectError(LoadVolume(series), absl::StatusCode::kInvalidArgument, "series.nii", "3D");

  // A 2D image is not a volume, whatever its header holds past its two dimensions.
  nf = NiftiFile();
  nf.dim0 = 2;
  const std::string image = ScratchPath("image.nii");
  WriteBytes(image, Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false)));
  ExpectError(LoadVolume(image), absl::StatusCode::kInvalidArgument, "image.nii",
              "not a 3D volume (dim = 2, 5, 4)");
}

TEST(VolumeLoadErrors, DimsAboveLimits) {
  VolumeLimits limits;
  limits.max_dim = 8;
  limits.max_voxels = 300;

  NiftiFile nf;
  nf.dims = {9, 2, 2};
  std::string path = ScratchPath("wide.nii");
  WriteBytes(path, Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false)));
  ExpectError(LoadVolume(path, limits), absl::StatusCode::kResourceExhausted, "wide.nii");

  nf.dims = {8, 8, 8};  // each axis fine, 512 samples too many
  path = ScratchPath("many.nii");
  WriteBytes(path, Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false)));
  ExpectError(LoadVolume(path, limits), absl::StatusCode::kResourceExhausted, "many.nii");

  // Refused from the header alone: the data for 30000^3 samples is not there to read.
  nf.dims = {30000, 30000, 30000};
  path = ScratchPath("huge.nii");
  WriteBytes(path, nf.Header());
  ExpectError(LoadVolume(path), absl::StatusCode::kResourceExhausted, "huge.nii");

  ExpectError(LoadVolume("raw:" + ScratchPath("nothing.raw") + ":5000x2x2:uint8"),
              absl::StatusCode::kResourceExhausted, "nothing.raw");

  const std::string vdb = WriteVdb("big.vdb", {TestGrid("density", 1.0f)});  // 10x9x12
  ExpectError(LoadVolume(vdb, limits), absl::StatusCode::kResourceExhausted, "big.vdb");
  // Voxels 2^31 apart: the box's extent overflows 32-bit coordinates, and is still too big.
  auto spread = openvdb::FloatGrid::create(0.0f);
  spread->setName("spread");
  spread->tree().setValue(openvdb::Coord(-(1 << 30)), 1.0f);
  spread->tree().setValue(openvdb::Coord(1 << 30), 2.0f);
  ExpectError(LoadVolume(WriteVdb("spread.vdb", {spread})), absl::StatusCode::kResourceExhausted,
              "spread.vdb", "2147483649");

  ExpectError(LoadVolume("sphere:9", limits), absl::StatusCode::kResourceExhausted, "sphere:9");
  ExpectError(LoadVolume("noise:7", limits), absl::StatusCode::kResourceExhausted, "noise:7");
  EXPECT_TRUE(LoadVolume("noise:6", limits).ok());
}

// OpenVDB allocates every node a file names before the active box can be checked: a tree
// whose nodes would take more than twice the memory of the largest volume within the limits is
// refused by the structure walk. Inactive voxels far apart add nodes (~300 KB each here) but
// leave the active box alone, so only the node budget can refuse these.
TEST(VolumeLoadErrors, TreesLargerThanTheLimitsNeed) {
  VolumeLimits limits;
  limits.max_dim = 64;  // a budget of ~8 MB: 20 scattered nodes fit, 40 do not
  for (const int scattered : {20, 40}) {
    SCOPED_TRACE(scattered);
    auto grid = TestGrid("density", 1.0f);  // active box 10x9x12
    for (int i = 1; i <= scattered; ++i)
      grid->tree().setValueOff(openvdb::Coord(i * 4096, 0, 0), 0.5f);
    const std::string path = WriteVdb("scattered" + std::to_string(scattered) + ".vdb", {grid});
    EXPECT_TRUE(LoadVolume(path).ok());  // the default limits' budget is ~16 GB
    const absl::StatusOr<VolumePtr> v = LoadVolume(path, limits);
    if (scattered == 20) {
      ASSERT_TRUE(v.ok()) << v.status();
      EXPECT_EQ((*v)->dims, (std::array<int, 3>{10, 9, 12}));
    } else {
      ExpectError(v, absl::StatusCode::kResourceExhausted, "scattered40.vdb",
                  "tree would take more than 7 MB");
    }
  }
}

// The node budget bounds the active box by max_voxels as well as per axis: a long thin box meets
// few nodes though its sides are long. With 256 samples per axis and 2,000 in all the budget is
// ~60 MB (~300 MB by the sides alone): 300 scattered nodes (~90 MB) are refused under it and
// read when max_voxels allows the whole 256^3 box.
TEST(VolumeLoadErrors, TheNodeBudgetCountsTheVoxelLimitToo) {
  auto grid = TestGrid("density", 1.0f);  // active box 10x9x12
  for (int i = 1; i <= 300; ++i) grid->tree().setValueOff(openvdb::Coord(i * 4096, 0, 0), 0.5f);
  const std::string path = WriteVdb("scattered300.vdb", {grid});
  VolumeLimits limits;
  limits.max_dim = 256;
  limits.max_voxels = 2000;
  ExpectError(LoadVolume(path, limits), absl::StatusCode::kResourceExhausted, "scattered300.vdb",
              "limits of 256 samples per axis and 2000 in all");
  limits.max_voxels = 256 * 256 * 256;
  const absl::StatusOr<VolumePtr> v = LoadVolume(path, limits);
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->dims, (std::array<int, 3>{10, 9, 12}));
}

TEST(VolumeLoadErrors, UnsupportedTypes) {
  NiftiFile nf;
  nf.datatype = 32;  // complex64
  nf.bitpix = 64;
  std::string path = ScratchPath("complex.nii");
  WriteBytes(path, Concat(nf.Header(), std::vector<unsigned char>(5 * 4 * 3 * 8, 0)));
  ExpectError(LoadVolume(path), absl::StatusCode::kInvalidArgument, "complex.nii", "datatype");

  nf.datatype = 16;
  nf.bitpix = 16;  // disagrees with float32
  path = ScratchPath("bitpix.nii");
  WriteBytes(path, Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false)));
  ExpectError(LoadVolume(path), absl::StatusCode::kInvalidArgument, "bitpix.nii", "bitpix");

  path = ScratchPath("any.raw");
  WriteBytes(path, std::vector<unsigned char>(64, 0));
  ExpectError(LoadVolume("raw:" + path + ":2x2x2:int64"), absl::StatusCode::kInvalidArgument,
              "any.raw", "int64");

  auto vectors = openvdb::Vec3SGrid::create();
  vectors->setName("velocity");
  vectors->tree().setValue(openvdb::Coord(0), openvdb::Vec3s(1, 2, 3));
  const std::string vdb = WriteVdb("vectors.vdb", {vectors});
  ExpectError(LoadVolume(vdb), absl::StatusCode::kInvalidArgument, "vectors.vdb", "float grid");
  ExpectError(LoadVolume(vdb + "#velocity"), absl::StatusCode::kInvalidArgument, "vectors.vdb",
              "vec3s");
  ExpectError(LoadVolume(vdb + "#pressure"), absl::StatusCode::kNotFound, "vectors.vdb",
              "pressure");

  auto rotated = TestGrid("density", 1.0f);
  rotated->transform().preRotate(0.3, openvdb::math::Z_AXIS);
  const std::string rotated_path = WriteVdb("rotated.vdb", {rotated});
  ExpectError(LoadVolume(rotated_path), absl::StatusCode::kInvalidArgument, "rotated.vdb",
              "axis-aligned");
  // However little: half a degree is not axis-aligned either.
  auto tilted = openvdb::FloatGrid::create(0.0f);
  tilted->tree().setValue(openvdb::Coord(1, 2, 3), 1.0f);
  tilted->tree().setValue(openvdb::Coord(2, 3, 4), 2.0f);
  tilted->transform().preRotate(0.5 * M_PI / 180, openvdb::math::Z_AXIS);
  ExpectError(LoadVolume(WriteVdb("tilted.vdb", {tilted})), absl::StatusCode::kInvalidArgument,
              "tilted.vdb",
              "only axis-aligned transforms are supported (this one is rotated 0.5 degrees off "
              "the axes)");
}

TEST(VolumeLoadErrors, NonFiniteSamples) {
  const std::array<int, 3> dims{4, 3, 10};
  std::vector<float> values(4 * 3 * 10, 1.0f);
  values[(9 * 3 + 1) * 4 + 2] = std::numeric_limits<float>::quiet_NaN();  // (2, 1, 9)
  values[(9 * 3 + 2) * 4 + 0] = std::numeric_limits<float>::infinity();  // later in x-fastest order
  std::vector<unsigned char> bytes;
  for (float v : values) Put(bytes, v, false);
  std::string path = ScratchPath("nan.raw");
  WriteBytes(path, bytes);
  ExpectError(LoadVolume("raw:" + path + ":4x3x10:float32"), absl::StatusCode::kInvalidArgument,
              "nan.raw", "NaN sample at index (2, 1, 9)");
  // Rows of whole 8-sample leaf rows take the vector path: the same first offender, and the
  // same range as a direct scan when all are finite.
  std::vector<float> wide(17 * 9 * 9);
  for (size_t i = 0; i < wide.size(); ++i) wide[i] = float(std::sin(0.37 * double(i))) * 3.0f;
  std::vector<unsigned char> wide_bytes;
  for (float v : wide) Put(wide_bytes, v, false);
  path = ScratchPath("wide.raw");
  WriteBytes(path, wide_bytes);
  auto fine = LoadVolume("raw:" + path + ":17x9x9:float32");
  ASSERT_TRUE(fine.ok()) << fine.status();
  EXPECT_EQ((*fine)->min_value, *std::min_element(wide.begin(), wide.end()));
  EXPECT_EQ((*fine)->max_value, *std::max_element(wide.begin(), wide.end()));
  wide[(4 * 9 + 3) * 17 + 11] = std::numeric_limits<float>::quiet_NaN();  // (11, 3, 4)
  wide[(8 * 9 + 8) * 17 + 3] = -std::numeric_limits<float>::infinity();   // later
  wide_bytes.clear();
  for (float v : wide) Put(wide_bytes, v, false);
  WriteBytes(path, wide_bytes);
  ExpectError(LoadVolume("raw:" + path + ":17x9x9:float32"), absl::StatusCode::kInvalidArgument,
              "wide.raw", "NaN sample at index (11, 3, 4)");
  wide[(4 * 9 + 3) * 17 + 11] = 0.0f;
  wide_bytes.clear();
  for (float v : wide) Put(wide_bytes, v, false);
  WriteBytes(path, wide_bytes);
  ExpectError(LoadVolume("raw:" + path + ":17x9x9:float32"), absl::StatusCode::kInvalidArgument,
              "wide.raw", "Inf sample at index (3, 8, 8)");
  // A float64 sample past the float range is said to be one (the file has no Inf in it).
  std::vector<unsigned char> doubles;
  for (int i = 0; i < 27; ++i) Put(doubles, i == 5 ? 6.9e300 : 0.5, false);
  const std::string huge = ScratchPath("huge64.raw");
  WriteBytes(huge, doubles);
  ExpectError(LoadVolume("raw:" + huge + ":3x3x3:float64"), absl::StatusCode::kInvalidArgument,
              "huge64.raw",
              "Inf sample at index (2, 1, 0) (or a float64 sample past the float "
              "range, +-3.4e38, where samples are held)");

  NiftiFile nf;
  nf.dims = dims;
  nf.datatype = 64;
  nf.bitpix = 64;
  std::vector<unsigned char> data;
  for (int i = 0; i < 120; ++i) Put(data, i == 17 ? -HUGE_VAL : 0.5, false);  // (1, 1, 1)
  path = ScratchPath("inf.nii.gz");
  WriteGz(path, Concat(nf.Header(), data));
  ExpectError(LoadVolume(path), absl::StatusCode::kInvalidArgument, "inf.nii.gz",
              "Inf sample at index (1, 1, 1)");

  // A finite float64 beyond float range is not representable either.
  data.clear();
  for (int i = 0; i < 120; ++i) Put(data, i == 5 ? 1e300 : 0.5, false);
  path = ScratchPath("overflow.nii");
  WriteBytes(path, Concat(nf.Header(), data));
  ExpectError(LoadVolume(path), absl::StatusCode::kInvalidArgument, "overflow.nii", "(1, 1, 0)");
  // Finite stored values that the header's scaling takes past the float range: named as such.
  NiftiFile scaled;
  scaled.dims = dims;
  scaled.datatype = 2;  // uint8
  scaled.bitpix = 8;
  scaled.slope = 1e38f;
  std::vector<unsigned char> bytes8(120, 0);
  bytes8[7] = 200;  // (3, 1, 0)
  path = ScratchPath("scaled.nii");
  WriteBytes(path, Concat(scaled.Header(), bytes8));
  ExpectError(LoadVolume(path), absl::StatusCode::kInvalidArgument, "scaled.nii",
              "Inf sample at index (3, 1, 0) (samples scaled by scl_slope 1e+38, scl_inter 0)");

  auto grid = TestGrid("density", 1.0f);
  grid->tree().setValue(openvdb::Coord(4, 10, 12), std::numeric_limits<float>::infinity());
  grid->tree().setValue(openvdb::Coord(-2, 10, 12), std::numeric_limits<float>::quiet_NaN());
  const std::string vdb = WriteVdb("nan.vdb", {grid});
  // Box starts at (-3, 5, 7): the NaN is (1, 5, 5), before the Inf at (7, 5, 5), though the two
  // lie in different leaves.
  ExpectError(LoadVolume(vdb), absl::StatusCode::kInvalidArgument, "nan.vdb",
              "NaN sample at index (1, 5, 5)");
  grid->tree().setValue(openvdb::Coord(-2, 10, 12), 0.0f);
  const std::string inf_vdb = WriteVdb("inf.vdb", {grid});
  ExpectError(LoadVolume(inf_vdb), absl::StatusCode::kInvalidArgument, "inf.vdb",
              "Inf sample at index (7, 5, 5)");
}

// A sample of the box outside every leaf is the tile's or the background's value: a value that
// is not finite there is refused as one in a leaf is.
TEST(VolumeLoadErrors, NonFiniteValuesOutsideTheLeaves) {
  // Two leaf-sized constant regions (tiles, no leaves), x 8..15 between them the background's.
  auto tiles = [](float background) {
    auto grid = openvdb::FloatGrid::create(background);
    grid->tree().fill(openvdb::CoordBBox({0, 0, 0}, {7, 7, 7}), 1.0f);
    grid->tree().fill(openvdb::CoordBBox({16, 0, 0}, {23, 7, 7}), 2.0f);
    return grid;
  };
  ExpectError(LoadVolume(WriteVdb("inf_background.vdb", {tiles(INFINITY)})),
              absl::StatusCode::kInvalidArgument, "inf_background.vdb",
              "Inf sample at index (8, 0, 0)");
  // A finite one there is a sample like any other, in the volume's range too.
  const absl::StatusOr<VolumePtr> v = LoadVolume(WriteVdb("finite_background.vdb", {tiles(7.0f)}));
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->dims, (std::array<int, 3>{24, 8, 8}));
  EXPECT_EQ((*v)->min_value, 1.0f);
  EXPECT_EQ((*v)->max_value, 7.0f);
}

TEST(VolumeLoadErrors, BadGeneratorSpecs) {
  ExpectError(LoadVolume("teapot:64"), absl::StatusCode::kNotFound, "teapot");
  for (const std::string spec :
       {"cayley:1", "cayley:0", "sphere:-3", "shells:abc", "shells:", "buckyball", "cayley:8:3",
        "noise:8:x", "noise:8:-1", "noise:8:99999999999", "sphere:4x"}) {
    if (spec == "buckyball") continue;  // a bare word is a file name, covered below
    ExpectError(LoadVolume(spec), absl::StatusCode::kInvalidArgument, spec);
  }
  ExpectError(LoadVolume("cayley:1026"), absl::StatusCode::kResourceExhausted, "cayley:1026");
  ExpectError(LoadVolume("cayley:99999999999999999999"), absl::StatusCode::kInvalidArgument,
              "cayley:99999999999999999999");
  // A name with no known extension, not a missing file: the generators are listed.
  ExpectError(LoadVolume("buckyball"), absl::StatusCode::kInvalidArgument, "buckyball",
              "or a generator NAME:N (cayley, buckyball");
  ExpectError(LoadVolume(""), absl::StatusCode::kInvalidArgument, "empty");
}

TEST(VolumeLoadErrors, MalformedRawSpecs) {
  const std::string path = ScratchPath("ok.raw");
  WriteBytes(path, Samples(Type::kUint8, {2, 2, 2}, false));
  for (const std::string tail : {"", ":2x2x2", ":2x2:uint8", ":2x2x2x2:uint8", ":axbxc:uint8",
                                 ":2x2x:uint8", ":2x2x2:uint8:middle", ":-2x2x2:uint8"}) {
    const auto result = LoadVolume("raw:" + path + tail);
    ASSERT_FALSE(result.ok()) << tail;
    EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument) << result.status();
    EXPECT_NE(result.status().message().find("ok.raw"), std::string::npos) << result.status();
  }
  ExpectError(LoadVolume("raw::2x2x2:uint8"), absl::StatusCode::kInvalidArgument, "raw::2x2x2");
  ASSERT_TRUE(LoadVolume("raw:" + path + ":2x2x2:uint8").ok());  // the file itself is fine
  // A wrong last field after a type is a wrong byte order; with dims before it, a wrong type.
  ExpectError(LoadVolume("raw:" + path + ":2x2x2:uint8:middle"), absl::StatusCode::kInvalidArgument,
              "ok.raw", "byte order 'middle' is not le or be");
  ExpectError(LoadVolume("raw:" + path + ":2x2x2:float"), absl::StatusCode::kInvalidArgument,
              "ok.raw", "unsupported type 'float'");
  ExpectError(LoadVolume("raw:" + path + ":2x2x2:float:be"), absl::StatusCode::kInvalidArgument,
              "ok.raw", "unsupported type 'float'");
  // PATH may hold colons: fields are taken from the right.
  const std::string colons = ScratchPath("a:b:2x2x2:uint8.raw");
  WriteBytes(colons, Samples(Type::kUint16, {2, 2, 2}, true));
  absl::StatusOr<VolumePtr> v = LoadVolume("raw:" + colons + ":2x2x2:uint16:be");
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ((*v)->dims, (std::array<int, 3>{2, 2, 2}));
  ExpectSamples(**v, [](int64_t i) { return float(StoredValue(Type::kUint16, i)); });
}

// The spec alone: its parts, read without opening a file, and its own mistakes refused as
// LoadVolume refuses them, where a missing or damaged file is left to loading.
// Relative names with a colon: "word:..." naming a volume file is that file, found or not (a
// missing "scan:2024.nii.gz" was an unknown generator 'scan', a usage error); a generator spec
// stays one when a file of its name is in the directory (a stray file "cayley:9" made the spec
// "cayley:9" an unrecognised volume type).
TEST(VolumeSpec, WordColonNamesAreFilesByTheirExtension) {
  const std::filesystem::path before = std::filesystem::current_path();
  std::filesystem::current_path(ScratchDir());
  for (const std::string file : {"scan:2024.nii.gz", "scan:2024.nii", "ab:1.vdb"}) {
    const absl::StatusOr<VolumeSpec> parsed = ParseVolumeSpec(file);
    ASSERT_TRUE(parsed.ok()) << file << ": " << parsed.status();
    EXPECT_NE(parsed->source, VolumeSource::kGenerator) << file;
    EXPECT_EQ(parsed->path, file);
    EXPECT_EQ(LoadVolume(file).status().code(), absl::StatusCode::kNotFound) << file;
  }
  const absl::StatusOr<VolumeSpec> grid = ParseVolumeSpec("ab:1.vdb#density");
  ASSERT_TRUE(grid.ok()) << grid.status();
  EXPECT_EQ(grid->source, VolumeSource::kVdbFile);
  EXPECT_EQ(grid->path, "ab:1.vdb");
  WriteBytes("cayley:9", {'x'});
  const absl::StatusOr<VolumeSpec> generator = ParseVolumeSpec("cayley:9");
  EXPECT_TRUE(LoadVolume("cayley:9").ok());
  std::filesystem::remove("cayley:9");
  std::filesystem::current_path(before);
  ASSERT_TRUE(generator.ok()) << generator.status();
  EXPECT_EQ(generator->source, VolumeSource::kGenerator);
}

TEST(VolumeSpec, ParsedAloneAndRefusedAsLoadVolumeRefusesIt) {
  absl::StatusOr<VolumeSpec> noise = ParseVolumeSpec("noise:9:7");
  ASSERT_TRUE(noise.ok()) << noise.status();
  EXPECT_EQ(noise->source, VolumeSource::kGenerator);
  EXPECT_EQ(noise->generator, "noise");
  EXPECT_EQ(noise->n, 9);
  EXPECT_EQ(noise->seed, 7u);
  const absl::StatusOr<VolumeSpec> raw =
      ParseVolumeSpec("raw:" + ScratchPath("missing.raw") + ":3x4x5:int16:be");
  ASSERT_TRUE(raw.ok()) << raw.status();
  EXPECT_EQ(raw->source, VolumeSource::kRawFile);
  EXPECT_EQ(raw->path, ScratchPath("missing.raw"));
  EXPECT_EQ(raw->dims, (std::array<int, 3>{3, 4, 5}));
  EXPECT_EQ(raw->sample_type, "int16");
  EXPECT_TRUE(raw->big_endian);
  const absl::StatusOr<VolumeSpec> vdb = ParseVolumeSpec(ScratchPath("missing.vdb") + "#density");
  ASSERT_TRUE(vdb.ok()) << vdb.status();
  EXPECT_EQ(vdb->source, VolumeSource::kVdbFile);
  EXPECT_EQ(vdb->path, ScratchPath("missing.vdb"));
  EXPECT_EQ(vdb->grid_name, "density");
  const std::string damaged = ScratchPath("spec_damaged.nii");
  WriteBytes(damaged, {'h', 'i'});
  for (const std::string& file : {damaged, ScratchPath("missing.nii.gz")}) {
    const absl::StatusOr<VolumeSpec> nifti = ParseVolumeSpec(file);
    ASSERT_TRUE(nifti.ok()) << nifti.status();
    EXPECT_EQ(nifti->source, VolumeSource::kNiftiFile);
    EXPECT_FALSE(LoadVolume(file).ok()) << file;
  }

  VolumeLimits limits;
  limits.max_dim = 8;
  const std::string ok_raw = ScratchPath("spec_ok.raw");
  WriteBytes(ok_raw, Samples(Type::kUint8, {2, 2, 2}, false));
  for (const std::string& spec : std::vector<std::string>{
           "", "teapot:9", "cayley:1", "cayley:x", "cayley:8:3", "noise:8:-1", "cayley:9",
           "raw:" + ok_raw + ":2x2:uint8", "raw:" + ok_raw + ":2x2x2:float",
           "raw:" + ok_raw + ":2x2x2:uint8:middle", "raw:" + ok_raw + ":9x2x2:uint8",
           "raw::2x2x2:uint8", ScratchPath("spec_notes.txt"), "buckyball"}) {
    const absl::StatusOr<VolumeSpec> parsed = ParseVolumeSpec(spec, limits);
    const absl::StatusOr<VolumePtr> loaded = LoadVolume(spec, limits);
    ASSERT_FALSE(parsed.ok()) << spec;
    ASSERT_FALSE(loaded.ok()) << spec;
    EXPECT_EQ(parsed.status(), loaded.status()) << spec;
  }
}

}  // namespace
}  // namespace isostream
