// The hierarchy needs a cube of (2^k+1)^3 samples. PadToHierarchyDomain embeds a volume's
// samples at the cube's origin corner (sample (i,j,k) -> cube point (i,j,k)) and fills the rest
// by clamping to the nearest data sample (edge replication).
//
// Why edge replication: the padding must never create a surface that is not in the data.
// A constant fill (e.g. below the minimum) would close every open surface with a wall along the
// data boundary. Replication makes the field constant across the boundary in the normal
// direction, so wavelet coefficients there are zero (no forced refinement) and no new level set
// appears inside the data box; a level set that crosses the data boundary continues into the
// padding as a straight extrusion, which the extractor clips at the data box.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "server/volume/volume.h"
#include "shared/status.h"

namespace isostream {

struct PaddedSamples {
  int k = 0;  // cube has n = 2^k + 1 samples per axis
  int n = 0;
  std::array<int, 3> data_dims{0, 0, 0};  // the data box is [0, data_dims - 1] in cube points
  std::vector<float> values;              // n^3, index (z * n + y) * n + x

  float at(int x, int y, int z) const {
    return values[(static_cast<size_t>(z) * n + y) * n + x];
  }
};

// Smallest k with 2^k + 1 >= max(dims). Dims must be >= 2.
int HierarchyLevelFor(const std::array<int, 3>& dims);

absl::StatusOr<PaddedSamples> PadToHierarchyDomain(const Volume& volume);

}  // namespace isostream
