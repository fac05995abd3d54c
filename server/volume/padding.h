// The hierarchy needs a cube of (2^k+1)^3 samples. PadToHierarchyDomain embeds a volume's
// samples at the cube's origin corner (sample (i,j,k) -> cube point (i,j,k)) and fills the rest
// by clamping to the nearest data sample (edge replication). Where that saves at least a quarter
// of the cube, only the planes stored_planes.h chooses are held.
//
// Why edge replication: the padding must never create a surface that is not in the data.
// A constant fill (e.g. below the minimum) would close every open surface with a wall along the
// data boundary. Replication makes the field constant across the boundary in the normal
// direction, so wavelet coefficients there are zero (no forced refinement) and no new level set
// appears inside the data box; a level set that crosses the data boundary continues into the
// padding as a straight extrusion, which the extractor clips at the data box.
#pragma once

#include <array>
#include <atomic>

#include "server/volume/padded_samples.h"
#include "server/volume/volume.h"
#include "shared/status.h"

namespace isostream {

// Smallest k >= 1 with 2^k + 1 >= max(dims). Dims must be >= 2.
int HierarchyLevelFor(const std::array<int, 3>& dims);

enum class CubePlanes {
  kStandIns,  // stand-ins for the planes deep in the padding, where they save a quarter of the cube
  kAll,       // every plane (tests compare the two)
};

// Cancelled between blocks and rows once `stop` (may be null) is set.
absl::StatusOr<PaddedSamples> PadToHierarchyDomain(const Volume& volume,
                                                   const std::atomic<bool>* stop = nullptr,
                                                   CubePlanes planes = CubePlanes::kStandIns);

}  // namespace isostream
