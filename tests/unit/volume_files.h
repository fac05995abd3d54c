// Files for the volume loader's tests (volume_load_test.cpp, volume_load_errors_test.cpp):
// a scratch directory, samples of every stored type, NIfTI headers and OpenVDB grids written
// here, and the checks both suites make of what LoadVolume returns.
#pragma once

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
#include <optional>
#include <string>
#include <vector>

#include "server/volume/load.h"

namespace isostream::volume_files {

// ------------------------------------------------------------------------------------------------
// Files

// One scratch directory per test process, removed when the process's tests finish.
inline std::string* scratch_dir = nullptr;

class ScratchCleanup : public ::testing::Environment {
 public:
  void TearDown() override {
    if (scratch_dir != nullptr) std::filesystem::remove_all(*scratch_dir);
  }
};
inline ::testing::Environment* const kScratchCleanup =
    ::testing::AddGlobalTestEnvironment(new ScratchCleanup);

inline const std::string& ScratchDir() {
  if (scratch_dir == nullptr) {
    std::string pattern = ::testing::TempDir() + "/isostream_volume_XXXXXX";
    EXPECT_NE(mkdtemp(pattern.data()), nullptr) << pattern;
    scratch_dir = new std::string(pattern);
  }
  return *scratch_dir;
}

inline std::string ScratchPath(const std::string& name) { return ScratchDir() + "/" + name; }

inline void WriteBytes(const std::string& path, const std::vector<unsigned char>& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << path;
}

inline void WriteGz(const std::string& path, const std::vector<unsigned char>& bytes) {
  gzFile f = gzopen(path.c_str(), "wb");
  ASSERT_NE(f, nullptr) << path;
  ASSERT_EQ(gzwrite(f, bytes.data(), static_cast<unsigned>(bytes.size())),
            static_cast<int>(bytes.size()));
  ASSERT_EQ(gzclose(f), Z_OK);
}

inline std::vector<unsigned char> ReadBytes(const std::string& path) {
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

inline const TypeCase kTypeCases[] = {
    {Type::kUint8, "uint8", 1, 2},      {Type::kInt8, "int8", 1, 0},
    {Type::kUint16, "uint16", 2, 512},  {Type::kInt16, "int16", 2, 4},
    {Type::kUint32, "uint32", 4, 0},    {Type::kInt32, "int32", 4, 8},
    {Type::kFloat32, "float32", 4, 16}, {Type::kFloat64, "float64", 8, 64},
};

// Distinct-ish values that use each type's range (negative where signed, large where wide).
inline double StoredValue(Type type, int64_t index) {
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

inline void PutStored(std::vector<unsigned char>& out, Type type, double v, bool big_endian) {
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

inline std::vector<unsigned char> Samples(Type type, const std::array<int, 3>& dims,
                                          bool big_endian) {
  std::vector<unsigned char> out;
  const int64_t count = int64_t{dims[0]} * dims[1] * dims[2];
  for (int64_t i = 0; i < count; ++i) PutStored(out, type, StoredValue(type, i), big_endian);
  return out;
}

inline float Sample(const Volume& v, int i, int j, int k) {
  return v.grid->getConstAccessor().getValue(
      openvdb::Coord(v.index_min[0] + i, v.index_min[1] + j, v.index_min[2] + k));
}

// Every sample equals EXPECTED(linear x-fastest index), and min/max agree.
inline void ExpectSamples(const Volume& v, const std::function<float(int64_t)>& expected) {
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
inline void ExpectError(const absl::StatusOr<VolumePtr>& result, absl::StatusCode code,
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
  unsigned char xyzt_units = 0;
  int16_t sform_code = 0;
  std::array<float, 3> sform_offset{0, 0, 0};
  int16_t qform_code = 0;
  std::array<float, 3> qoffset{0, 0, 0};
  std::array<float, 3> quatern{0, 0, 0};  // b, c, d
  float qfac = 1;                         // pixdim[0]
  // The sform's 3x3 part ([row][column]), when set; else pixdim on its diagonal.
  std::optional<std::array<std::array<float, 3>, 3>> srow;
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
    PutAt<float>(h, 76, qfac, be);  // pixdim[0]
    for (int i = 0; i < 3; ++i) PutAt<float>(h, 80 + 4 * i, pixdim[i], be);
    PutAt<float>(h, 108, vox_offset, be);
    PutAt<float>(h, 112, slope, be);
    PutAt<float>(h, 116, inter, be);
    h[123] = xyzt_units;
    PutAt<int16_t>(h, 252, qform_code, be);
    PutAt<int16_t>(h, 254, sform_code, be);
    for (int i = 0; i < 3; ++i) PutAt<float>(h, 256 + 4 * i, quatern[i], be);
    for (int i = 0; i < 3; ++i) PutAt<float>(h, 268 + 4 * i, qoffset[i], be);
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c)
        PutAt<float>(h, 280 + 16 * r + 4 * c, srow ? (*srow)[r][c] : r == c ? pixdim[r] : 0, be);
      PutAt<float>(h, 280 + 16 * r + 12, sform_offset[r], be);
    }
    std::memcpy(h.data() + 344, magic, std::strlen(magic) + 1);
    // Bytes between the header and vox_offset (extension flag, extensions) are skipped.
    for (size_t i = 352; i < h.size(); ++i) h[i] = 0xAB;
    return h;
  }
};

inline std::vector<unsigned char> Concat(std::vector<unsigned char> a,
                                         const std::vector<unsigned char>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

// Writes nf's header and samples of `type` to the scratch file `name`, and loads it.
inline absl::StatusOr<VolumePtr> WriteAndLoad(const NiftiFile& nf, const std::string& name,
                                              Type type = Type::kFloat32) {
  const std::string path = ScratchPath(name);
  WriteBytes(path, Concat(nf.Header(), Samples(type, nf.dims, false)));
  return LoadVolume(path);
}

// ------------------------------------------------------------------------------------------------
// OpenVDB

inline std::string WriteVdb(const std::string& name, const openvdb::GridPtrVec& grids) {
  openvdb::initialize();
  const std::string path = ScratchPath(name);
  openvdb::io::File file(path);
  file.write(grids);
  file.close();
  return path;
}

// A float grid over [index_min, index_min + dims) with a non-uniform transform, where the box
// has leaves, one inactive voxel and one tile-sized constant region.
inline openvdb::FloatGrid::Ptr TestGrid(const std::string& name, float scale) {
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

}  // namespace isostream::volume_files
