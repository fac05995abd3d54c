// LoadVolume on damaged files: every header byte of a small NIfTI file, and every byte of a
// small OpenVDB file's framing, overwritten in turn. Whatever a byte becomes, the loader returns either a
// volume within the limits, all of whose samples are finite, or an error with a message; it
// never crashes, hangs or allocates past the limits (the suite runs under a few seconds).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
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
          ASSERT_TRUE(std::isfinite(Sample(v, i, j, k))) << what << " at " << i << "," << j << ","
                                                         << k;
  }
};

std::vector<unsigned char> Replacements(unsigned char original) {
  return {0x00, 0xff, 0x7f, 0x80, static_cast<unsigned char>(original ^ 0x01),
          static_cast<unsigned char>(original ^ 0x40)};
}

TEST(VolumeLoadMutation, EveryNiftiHeaderByte) {
  NiftiFile nf;
  nf.vox_offset = 360;  // an extension block too
  const std::vector<unsigned char> good = Concat(nf.Header(), Samples(Type::kFloat32, nf.dims,
                                                                      false));
  const std::string path = ScratchPath("mutated.nii");
  Outcomes outcomes;
  for (size_t at = 0; at < 360; ++at)
    for (unsigned char b : Replacements(good[at])) {
      if (b == good[at]) continue;
      std::vector<unsigned char> bytes = good;
      bytes[at] = b;
      WriteBytes(path, bytes);
      outcomes.Check(LoadVolume(path, kLimits), "byte " + std::to_string(at) + " = " +
                                                    std::to_string(b));
    }
  // Most of the header is unused (description, intent, ...): those loads must succeed.
  EXPECT_GT(outcomes.loaded, 1000);
  EXPECT_GT(outcomes.refused, 50);
}

// The framing CheckVdbStructure guards: everything OpenVDB reads before the first root child's
// node masks (header, file metadata, grid descriptor, grid metadata, transform, root counts).
// Damage inside node data below the root is not covered: OpenVDB's tree reader can write out
// of bounds on it (a flipped child-mask bit did, in this test's first version).
TEST(VolumeLoadMutation, EveryVdbFramingByte) {
  const std::string original = WriteVdb("mutation_source.vdb", {TestGrid("density", 1.0f)});
  const std::vector<unsigned char> good = ReadBytes(original);
  // TestGrid's transform is a ScaleTranslateMap (six double vectors); the tree follows it: a
  // buffer count, the background, and the root's tile and child counts.
  const std::string map = "ScaleTranslateMap";
  const auto found = std::search(good.begin(), good.end(), map.begin(), map.end());
  ASSERT_NE(found, good.end());
  const size_t framing_end = size_t(found - good.begin()) + map.size() + 6 * 24 + 4 + 4 + 8;
  ASSERT_LT(framing_end, good.size());
  const std::string path = ScratchPath("mutated.vdb");
  Outcomes outcomes;
  for (size_t at = 0; at < framing_end; ++at)
    for (unsigned char b : Replacements(good[at])) {
      if (b == good[at]) continue;
      std::vector<unsigned char> bytes = good;
      bytes[at] = b;
      WriteBytes(path, bytes);
      outcomes.Check(LoadVolume(path, kLimits), "byte " + std::to_string(at) + " = " +
                                                    std::to_string(b));
    }
  // The UUID's hex digits, library versions and metadata values load; lengths, counts,
  // offsets and type names do not.
  EXPECT_GT(outcomes.loaded, 300);
  EXPECT_GT(outcomes.refused, 1000);
}

}  // namespace
}  // namespace isostream
