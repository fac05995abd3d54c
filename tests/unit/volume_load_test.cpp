// LoadVolume from files: round trips through real .vdb, .nii, .nii.gz and raw files written here,
// and every malformed input answered with the right status and a message naming the input.
#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/math/Maps.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "server/volume/load.h"

namespace isostream {
namespace {

// ------------------------------------------------------------------------------------------------
// Files

// One scratch directory per test process, removed when the process's tests finish.
std::string* scratch_dir = nullptr;

class ScratchCleanup : public ::testing::Environment {
 public:
  void TearDown() override {
    if (scratch_dir != nullptr) std::filesystem::remove_all(*scratch_dir);
  }
};
::testing::Environment* const kScratchCleanup =
    ::testing::AddGlobalTestEnvironment(new ScratchCleanup);

const std::string& ScratchDir() {
  if (scratch_dir == nullptr) {
    std::string pattern = ::testing::TempDir() + "/isostream_volume_XXXXXX";
    EXPECT_NE(mkdtemp(pattern.data()), nullptr) << pattern;
    scratch_dir = new std::string(pattern);
  }
  return *scratch_dir;
}

std::string ScratchPath(const std::string& name) { return ScratchDir() + "/" + name; }

void WriteBytes(const std::string& path, const std::vector<unsigned char>& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << path;
}

void WriteGz(const std::string& path, const std::vector<unsigned char>& bytes) {
  gzFile f = gzopen(path.c_str(), "wb");
  ASSERT_NE(f, nullptr) << path;
  ASSERT_EQ(gzwrite(f, bytes.data(), static_cast<unsigned>(bytes.size())),
            static_cast<int>(bytes.size()));
  ASSERT_EQ(gzclose(f), Z_OK);
}

std::vector<unsigned char> ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<unsigned char>(std::istreambuf_iterator<char>(in), {});
}

// Appends V in the given byte order.
template <typename T>
void Put(std::vector<unsigned char>& out, T v, bool big_endian) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  for (size_t i = 0; i < sizeof(T); ++i) out.push_back(b[big_endian ? sizeof(T) - 1 - i : i]);
}

template <typename T>
void PutAt(std::vector<unsigned char>& out, size_t offset, T v, bool big_endian) {
  std::vector<unsigned char> tmp;
  Put(tmp, v, big_endian);
  std::copy(tmp.begin(), tmp.end(), out.begin() + offset);
}

// ------------------------------------------------------------------------------------------------
// Sample types: a stored value per index that fits every type, and its float after scaling.

enum class Type { kUint8, kInt8, kUint16, kInt16, kUint32, kInt32, kFloat32, kFloat64 };

struct TypeCase {
  Type type;
  const char* name;
  int bytes;
  int16_t nifti_code;  // 0: not a NIfTI-1 type this loader accepts
};

const TypeCase kTypeCases[] = {
    {Type::kUint8, "uint8", 1, 2},      {Type::kInt8, "int8", 1, 0},
    {Type::kUint16, "uint16", 2, 512},  {Type::kInt16, "int16", 2, 4},
    {Type::kUint32, "uint32", 4, 0},    {Type::kInt32, "int32", 4, 8},
    {Type::kFloat32, "float32", 4, 16}, {Type::kFloat64, "float64", 8, 64},
};

// Distinct-ish values that use each type's range (negative where signed, large where wide).
double StoredValue(Type type, int64_t index) {
  switch (type) {
    case Type::kUint8:
      return static_cast<double>((index * 37 + 11) % 256);
    case Type::kInt8:
      return static_cast<double>((index * 37 + 11) % 256 - 128);
    case Type::kUint16:
      return static_cast<double>((index * 4099 + 7) % 65536);
    case Type::kInt16:
      return static_cast<double>((index * 4099 + 7) % 65536 - 32768);
    case Type::kUint32:
      return static_cast<double>((index * 2654435761u) % 4294967296u);
    case Type::kInt32:
      return static_cast<double>((index * 97 + 1) % 20001 - 10000) * 1000;
    case Type::kFloat32:
      return static_cast<double>(static_cast<float>(std::sin(index * 0.37) * 1e3));
    case Type::kFloat64:
      return std::cos(index * 0.11) * 1e-3 + index;
  }
  return 0;
}

void PutStored(std::vector<unsigned char>& out, Type type, double v, bool big_endian) {
  switch (type) {
    case Type::kUint8:
      return Put(out, static_cast<uint8_t>(v), big_endian);
    case Type::kInt8:
      return Put(out, static_cast<int8_t>(v), big_endian);
    case Type::kUint16:
      return Put(out, static_cast<uint16_t>(v), big_endian);
    case Type::kInt16:
      return Put(out, static_cast<int16_t>(v), big_endian);
    case Type::kUint32:
      return Put(out, static_cast<uint32_t>(v), big_endian);
    case Type::kInt32:
      return Put(out, static_cast<int32_t>(v), big_endian);
    case Type::kFloat32:
      return Put(out, static_cast<float>(v), big_endian);
    case Type::kFloat64:
      return Put(out, v, big_endian);
  }
}

std::vector<unsigned char> Samples(Type type, const std::array<int, 3>& dims, bool big_endian) {
  std::vector<unsigned char> out;
  const int64_t count = int64_t{dims[0]} * dims[1] * dims[2];
  for (int64_t i = 0; i < count; ++i) PutStored(out, type, StoredValue(type, i), big_endian);
  return out;
}

float Sample(const Volume& v, int i, int j, int k) {
  return v.grid->getConstAccessor().getValue(
      openvdb::Coord(v.index_min[0] + i, v.index_min[1] + j, v.index_min[2] + k));
}

// Every sample equals EXPECTED(linear x-fastest index), and min/max agree.
void ExpectSamples(const Volume& v, const std::function<float(int64_t)>& expected) {
  float lo = std::numeric_limits<float>::max(), hi = std::numeric_limits<float>::lowest();
  int64_t index = 0;
  for (int k = 0; k < v.dims[2]; ++k)
    for (int j = 0; j < v.dims[1]; ++j)
      for (int i = 0; i < v.dims[0]; ++i, ++index) {
        const float e = expected(index);
        ASSERT_EQ(Sample(v, i, j, k), e) << v.name << " at " << i << "," << j << "," << k;
        lo = std::min(lo, e);
        hi = std::max(hi, e);
      }
  EXPECT_EQ(v.min_value, lo);
  EXPECT_EQ(v.max_value, hi);
}

// Expects a failure with CODE whose message mentions NEEDLE (the file name or spec).
void ExpectError(const absl::StatusOr<VolumePtr>& result, absl::StatusCode code,
                 const std::string& needle, const std::string& also = "") {
  ASSERT_FALSE(result.ok()) << "expected an error mentioning " << needle;
  EXPECT_EQ(result.status().code(), code) << result.status();
  EXPECT_NE(result.status().message().find(needle), std::string::npos) << result.status();
  if (!also.empty()) {
    EXPECT_NE(result.status().message().find(also), std::string::npos) << result.status();
  }
}

// ------------------------------------------------------------------------------------------------
// NIfTI-1

struct NiftiFile {
  std::array<int, 3> dims{5, 4, 3};
  int16_t dim0 = 3;
  int16_t dim4 = 1;
  int16_t datatype = 16;
  int16_t bitpix = 32;
  std::array<float, 3> pixdim{1, 1, 1};
  float vox_offset = 352;
  float slope = 0;
  float inter = 0;
  int16_t sform_code = 0;
  std::array<float, 3> sform_offset{0, 0, 0};
  int16_t qform_code = 0;
  std::array<float, 3> qoffset{0, 0, 0};
  bool big_endian = false;
  const char* magic = "n+1";
  int32_t sizeof_hdr = 348;

  std::vector<unsigned char> Header() const {
    std::vector<unsigned char> h(static_cast<size_t>(vox_offset), 0);
    const bool be = big_endian;
    PutAt<int32_t>(h, 0, sizeof_hdr, be);
    PutAt<int16_t>(h, 40, dim0, be);
    for (int i = 0; i < 3; ++i) PutAt<int16_t>(h, 42 + 2 * i, static_cast<int16_t>(dims[i]), be);
    PutAt<int16_t>(h, 48, dim4, be);
    PutAt<int16_t>(h, 70, datatype, be);
    PutAt<int16_t>(h, 72, bitpix, be);
    PutAt<float>(h, 76, 1.0f, be);  // pixdim[0]: qfac
    for (int i = 0; i < 3; ++i) PutAt<float>(h, 80 + 4 * i, pixdim[i], be);
    PutAt<float>(h, 108, vox_offset, be);
    PutAt<float>(h, 112, slope, be);
    PutAt<float>(h, 116, inter, be);
    PutAt<int16_t>(h, 252, qform_code, be);
    PutAt<int16_t>(h, 254, sform_code, be);
    for (int i = 0; i < 3; ++i) PutAt<float>(h, 268 + 4 * i, qoffset[i], be);
    for (int i = 0; i < 3; ++i) {
      PutAt<float>(h, 280 + 16 * i + 4 * i, pixdim[i], be);  // srow diagonal
      PutAt<float>(h, 280 + 16 * i + 12, sform_offset[i], be);
    }
    std::memcpy(h.data() + 344, magic, std::strlen(magic) + 1);
    // Bytes between the header and vox_offset (extension flag, extensions) are skipped.
    for (size_t i = 352; i < h.size(); ++i) h[i] = 0xAB;
    return h;
  }
};

std::vector<unsigned char> Concat(std::vector<unsigned char> a,
                                  const std::vector<unsigned char>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

// Writes nf's header and samples of `type` to the scratch file `name`, and loads it.
absl::StatusOr<VolumePtr> WriteAndLoad(const NiftiFile& nf, const std::string& name,
                                       Type type = Type::kFloat32) {
  const std::string path = ScratchPath(name);
  WriteBytes(path, Concat(nf.Header(), Samples(type, nf.dims, false)));
  return LoadVolume(path);
}

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

TEST(VolumeLoadRaw, PathMayContainColons) {
  const std::string dir = ScratchPath("a:b");
  ASSERT_EQ(mkdir(dir.c_str(), 0755), 0);
  const std::string path = dir + "/c:d.raw";
  WriteBytes(path, Samples(Type::kUint8, {2, 2, 2}, false));
  absl::StatusOr<VolumePtr> v = LoadVolume("raw:" + path + ":2x2x2:uint8:le");
  ASSERT_TRUE(v.ok()) << v.status();
  ExpectSamples(**v, [](int64_t i) { return static_cast<float>(StoredValue(Type::kUint8, i)); });
}

// ------------------------------------------------------------------------------------------------
// OpenVDB

std::string WriteVdb(const std::string& name, const openvdb::GridPtrVec& grids) {
  openvdb::initialize();
  const std::string path = ScratchPath(name);
  openvdb::io::File file(path);
  file.write(grids);
  file.close();
  return path;
}

// A float grid over [index_min, index_min + dims) with a non-uniform transform, where the box
// has leaves, one inactive voxel and one tile-sized constant region.
openvdb::FloatGrid::Ptr TestGrid(const std::string& name, float scale) {
  auto grid = openvdb::FloatGrid::create(0.0f);
  grid->setName(name);
  grid->setTransform(openvdb::math::Transform::Ptr(
      new openvdb::math::Transform(std::make_shared<openvdb::math::ScaleTranslateMap>(
          openvdb::Vec3d(0.5, 0.25, 2.0), openvdb::Vec3d(1, 2, 3)))));
  auto acc = grid->getAccessor();
  for (int k = 7; k < 7 + 12; ++k)
    for (int j = 5; j < 5 + 9; ++j)
      for (int i = -3; i < -3 + 10; ++i)
        acc.setValue(openvdb::Coord(i, j, k), scale * (i * 3 + j * 5 - k * 7));
  acc.setValueOff(openvdb::Coord(0, 6, 8), 123.0f);  // inactive, inside the box: still a sample
  return grid;
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
  ExpectError(LoadVolume(hashed + "#heat"), absl::StatusCode::kNotFound, "no grid named 'heat'");
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

// ------------------------------------------------------------------------------------------------
// Bad inputs

TEST(VolumeLoadErrors, MissingFiles) {
  for (const std::string name : {"missing.nii", "missing.nii.gz", "missing.vdb", "missing.txt"}) {
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
  ExpectError(LoadVolume(path), absl::StatusCode::kInvalidArgument, "pair.nii");

  path = ScratchPath("garbage.vdb");
  WriteBytes(path, std::vector<unsigned char>(200, 0x42));
  ExpectError(LoadVolume(path), absl::StatusCode::kInvalidArgument, "garbage.vdb", "magic");
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

  ExpectError(LoadVolume("raw:" + ScratchPath("nothing.raw") + ":2000x2x2:uint8"),
              absl::StatusCode::kResourceExhausted, "nothing.raw");

  const std::string vdb = WriteVdb("big.vdb", {TestGrid("density", 1.0f)});  // 10x9x12
  ExpectError(LoadVolume(vdb, limits), absl::StatusCode::kResourceExhausted, "big.vdb");

  ExpectError(LoadVolume("sphere:9", limits), absl::StatusCode::kResourceExhausted, "sphere:9");
  ExpectError(LoadVolume("noise:7", limits), absl::StatusCode::kResourceExhausted, "noise:7");
  EXPECT_TRUE(LoadVolume("noise:6", limits).ok());
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
  ExpectError(LoadVolume("buckyball"), absl::StatusCode::kNotFound, "buckyball");
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

}  // namespace
}  // namespace isostream
