// LoadVolume on damaged files: every header byte of a small NIfTI file, and bytes all through a
// small OpenVDB file, overwritten in turn. Whatever a byte becomes, the loader returns either a
// volume within the limits, all of whose samples are finite, or an error with a message; it
// never crashes, hangs or allocates past the limits (the suite runs under a few seconds).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "server/volume/load.h"
#include "volume_files.h"

namespace isostream {
namespace {

using namespace volume_files;

// Small limits: a damaged size field must be refused before anything of that size is allocated.
constexpr VolumeLimits kLimits{64, int64_t{64} * 64 * 64};

// What a load of a damaged file may return. Counts the outcomes for the caller's sanity checks.
struct Outcomes {
  int loaded = 0, refused = 0;

  auto checker() {
    return [this](const absl::StatusOr<VolumePtr>& result, const std::string& what) {
      Check(result, what);
    };
  }

  void Check(const absl::StatusOr<VolumePtr>& result, const std::string& what) {
    if (!result.ok()) {
      ++refused;
      EXPECT_FALSE(result.status().message().empty()) << what;
      EXPECT_NE(result.status().code(), absl::StatusCode::kInternal)
          << what << ": " << result.status();
      return;
    }
    ++loaded;
    const Volume& v = **result;
    const auto dims = v.dims;
    ASSERT_TRUE(dims[0] >= 2 && dims[1] >= 2 && dims[2] >= 2) << what;
    ASSERT_LE(std::max({dims[0], dims[1], dims[2]}), kLimits.max_dim) << what;
    for (int k = 0; k < dims[2]; ++k)
      for (int j = 0; j < dims[1]; ++j)
        for (int i = 0; i < dims[0]; ++i)
          ASSERT_TRUE(std::isfinite(Sample(v, i, j, k)))
              << what << " at " << i << "," << j << "," << k;
  }
};

std::vector<unsigned char> Replacements(unsigned char original) {
  return {0x00,
          0xff,
          0x7f,
          0x80,
          static_cast<unsigned char>(original ^ 0x01),
          static_cast<unsigned char>(original ^ 0x40)};
}

// Writes `good` to `path` with byte `at` overwritten by each of its replacements in turn, and
// hands LoadVolume's answer for each to check(result, what), `what` naming the change.
template <typename Check>
void EachMutation(const std::vector<unsigned char>& good, size_t at, const std::string& path,
                  const Check& check) {
  for (unsigned char b : Replacements(good[at])) {
    if (b == good[at]) continue;
    std::vector<unsigned char> bytes = good;
    bytes[at] = b;
    WriteBytes(path, bytes);
    check(LoadVolume(path, kLimits), "byte " + std::to_string(at) + " = " + std::to_string(b));
  }
}

TEST(VolumeLoadMutation, EveryNiftiHeaderByte) {
  NiftiFile nf;
  nf.vox_offset = 360;  // an extension block too
  const std::vector<unsigned char> good =
      Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false));
  const std::string path = ScratchPath("mutated.nii");
  Outcomes outcomes;
  for (size_t at = 0; at < 360; ++at) EachMutation(good, at, path, outcomes.checker());
  // Most of the header is unused (description, intent, ...): those loads must succeed.
  EXPECT_GT(outcomes.loaded, 1000);
  EXPECT_GT(outcomes.refused, 50);
}

// Every byte of a gzip-compressed NIfTI file (gzip header, deflate stream, CRC and length
// trailer): zlib's errors and short streams come back as refusals, never as a volume of
// garbage of the right size or a crash.
TEST(VolumeLoadMutation, EveryByteOfAGzipNifti) {
  NiftiFile nf;
  const std::string source = ScratchPath("source.nii.gz");
  WriteGz(source, Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false)));
  const std::vector<unsigned char> good = ReadBytes(source);
  const absl::StatusOr<VolumePtr> reference = LoadVolume(source, kLimits);
  ASSERT_TRUE(reference.ok()) << reference.status();
  const std::string path = ScratchPath("mutated.nii.gz");
  Outcomes outcomes;
  for (size_t at = 0; at < good.size(); ++at)
    EachMutation(good, at, path, [&](const absl::StatusOr<VolumePtr>& v, const std::string& what) {
      outcomes.Check(v, what);
      // What loads is the file's own data: a damaged stream is never read as other samples.
      if (!v.ok()) return;
      ASSERT_EQ((*v)->dims, (*reference)->dims) << what;
      for (int k = 0; k < nf.dims[2]; ++k)
        for (int j = 0; j < nf.dims[1]; ++j)
          for (int i = 0; i < nf.dims[0]; ++i)
            ASSERT_EQ(Sample(**v, i, j, k), Sample(**reference, i, j, k)) << what;
    });
  // The gzip header's time, flags and OS bytes are not checked by zlib; the rest is covered by
  // the deflate stream's own checks and the CRC.
  EXPECT_GT(outcomes.refused, int(good.size()) * 3);
}

// Every byte of a small OpenVDB file's framing (header, metadata, grid descriptor, transform,
// root counts) and bytes spread through its node topology and leaf values. OpenVDB alone
// allocates and loops on damaged counts there, and writes past its buffers on a damaged chunk
// size (a flipped child-mask bit misaligned one): CheckVdbStructure must catch all of it.
TEST(VolumeLoadMutation, BytesThroughAVdbFile) {
  const std::string original = WriteVdb("mutation_source.vdb", {TestGrid("density", 1.0f)});
  const std::vector<unsigned char> good = ReadBytes(original);
  auto find = [&](const std::string& s) {
    const auto at = std::search(good.begin(), good.end(), s.begin(), s.end());
    EXPECT_NE(at, good.end()) << s;
    return size_t(at - good.begin());
  };
  // The descriptor's grid type is followed by an empty instance parent name and the grid,
  // block and end offsets; TestGrid's transform (six double vectors) by the buffer count, the
  // background and the root's two counts.
  const size_t type_at = find("Tree_float_5_4_3");
  int64_t block_pos = 0;
  std::memcpy(&block_pos, good.data() + type_at + 16 + 4 + 8, 8);
  const size_t framing_end = find("ScaleTranslateMap") + 17 + 6 * 24 + 4 + 4 + 8;
  ASSERT_LT(framing_end, size_t(block_pos));
  ASSERT_LT(size_t(block_pos), good.size());
  const std::string path = ScratchPath("mutated.vdb");
  Outcomes outcomes;
  auto mutate = [&](size_t at) { EachMutation(good, at, path, outcomes.checker()); };
  for (size_t at = 0; at < framing_end; ++at) mutate(at);
  for (size_t at = framing_end; at < size_t(block_pos); at += 41) mutate(at);  // node masks
  for (size_t at = size_t(block_pos); at < good.size(); at += 5) mutate(at);   // leaf values
  EXPECT_GT(outcomes.loaded, 300);
  EXPECT_GT(outcomes.refused, 1000);
}

// A file of two grids goes through OpenVDB's other reader (io::File: descriptors by offset,
// metadata of every grid, then the chosen grid by name): bytes spread through the whole file,
// both grids' descriptors, metadata and trees.
TEST(VolumeLoadMutation, BytesThroughATwoGridVdbFile) {
  auto labels = openvdb::Int32Grid::create(0);
  labels->setName("labels");
  labels->tree().fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(9)), 3, true);
  const std::vector<unsigned char> good =
      ReadBytes(WriteVdb("two_source.vdb", {labels, TestGrid("density", 1.0f)}));
  const std::string path = ScratchPath("mutated_two.vdb");
  Outcomes outcomes;
  for (size_t at = 0; at < good.size(); at += at < 1024 ? 3 : 53)
    EachMutation(good, at, path, outcomes.checker());
  EXPECT_GT(outcomes.loaded, 100);
  EXPECT_GT(outcomes.refused, 500);
}

}  // namespace
}  // namespace isostream
