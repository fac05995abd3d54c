// A small NIfTI-1 writer for the integration tests: float32 samples placed by an sform.
#pragma once

#include <array>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

namespace isostream::testing {

// A NIfTI-1 file of float32 samples (x fastest) placed in the world by its sform: spacing
// `spacing` per axis, sample (0, 0, 0) at `origin`. Values: squared distance from the centre in
// index units scaled to [-1, 1] per axis (a sphere for isovalue 1).
inline void WriteNifti(const std::string& path, std::array<int, 3> dims,
                       std::array<float, 3> spacing, std::array<float, 3> origin) {
  std::vector<unsigned char> out(352, 0);
  auto put = [&](size_t at, const auto& v) { std::memcpy(out.data() + at, &v, sizeof(v)); };
  put(0, int32_t{348});
  const int16_t dim[8] = {3, int16_t(dims[0]), int16_t(dims[1]), int16_t(dims[2]), 1, 1, 1, 1};
  for (int i = 0; i < 8; ++i) put(40 + 2 * i, dim[i]);
  put(70, int16_t{16});  // float32
  put(72, int16_t{32});
  const float pixdim[8] = {1, spacing[0], spacing[1], spacing[2], 1, 1, 1, 1};
  for (int i = 0; i < 8; ++i) put(76 + 4 * i, pixdim[i]);
  put(108, 352.0f);      // vox_offset
  put(112, 1.0f);        // scl_slope
  put(254, int16_t{1});  // sform_code
  for (int r = 0; r < 3; ++r) {
    float row[4] = {0, 0, 0, origin[r]};
    row[r] = spacing[r];
    for (int c = 0; c < 4; ++c) put(280 + 16 * r + 4 * c, row[c]);
  }
  std::memcpy(out.data() + 344, "n+1\0", 4);
  for (int k = 0; k < dims[2]; ++k)
    for (int j = 0; j < dims[1]; ++j)
      for (int i = 0; i < dims[0]; ++i) {
        const int idx[3] = {i, j, k};
        float v = 0;
        for (int a = 0; a < 3; ++a) {
          const float t = 2.0f * float(idx[a]) / float(dims[a] - 1) - 1.0f;
          v += t * t;
        }
        const size_t at = out.size();
        out.resize(at + 4);
        std::memcpy(out.data() + at, &v, 4);
      }
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(out.data()), std::streamsize(out.size()));
}

}  // namespace isostream::testing
