// NIfTI-1 headers at the edges of what the loader takes (load_nifti.cpp): dim[0] is at most 7
// (nifti1.h), so an eighth dimension is not a 3D volume even if every extent past the third is 1.
#include <gtest/gtest.h>

#include "tests/unit/volume_files.h"

namespace isostream {
namespace {

using namespace volume_files;

TEST(VolumeLoadNifti, DimZeroPastSevenIsRefused) {
  NiftiFile nf;
  nf.dim0 = 7;
  std::vector<unsigned char> file = Concat(nf.Header(), Samples(Type::kFloat32, nf.dims, false));
  for (int i = 5; i <= 7; ++i) PutAt<int16_t>(file, 40 + 2 * i, 1, false);  // dim[5..7]
  const std::string path = ScratchPath("seven_dims.nii");
  WriteBytes(path, file);
  absl::StatusOr<VolumePtr> v = LoadVolume(path);
  ASSERT_TRUE(v.ok()) << v.status();   // seven dimensions, the last four of extent 1
  PutAt<int16_t>(file, 40, 8, false);  // dim[0] = 8: no such header
  WriteBytes(path, file);
  ExpectError(LoadVolume(path), absl::StatusCode::kInvalidArgument, "seven_dims.nii",
              "not a 3D volume (dim = 8, 5, 4, 3, 1, 1, 1, 1)");
}

}  // namespace
}  // namespace isostream
