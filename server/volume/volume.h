// Volume: a scalar field held in an OpenVDB float grid, with the facts every later stage
// needs without touching OpenVDB (dims, world transform, value range).
#pragma once

#include <openvdb/openvdb.h>

#include <array>
#include <cstdint>
#include <memory>
#include <string>

namespace isostream {

struct Volume {
  std::string name;  // catalogue name or the spec it was loaded from
  // Samples live at grid index coordinates index_min + (i, j, k), 0 <= i < dims[0], ...
  // The grid's transform maps index space to world space, where OpenVDB can represent it
  // (MakeIndexToWorld); spacing and origin below are the authority.
  openvdb::FloatGrid::Ptr grid;
  std::array<int, 3> index_min{0, 0, 0};
  std::array<int, 3> dims{0, 0, 0};
  std::array<double, 3> spacing{1, 1, 1};  // world units per index step, per axis
  std::array<double, 3> origin{0, 0, 0};   // world position of sample (0, 0, 0)
  float min_value = 0;                     // over all samples (finite by construction)
  float max_value = 0;
  // How the file's axes were turned onto the world's (orientation.h); empty when as stored.
  std::string orientation;
  // Meters per world unit where the file says (NIfTI's xyzt_units), else 0 (raw and .vdb files
  // and the generators carry no unit). glTF's unit is the meter: .glb files scale by it.
  double meters_per_unit = 0;

  int64_t voxel_count() const { return int64_t{dims[0]} * dims[1] * dims[2]; }
};

using VolumePtr = std::shared_ptr<const Volume>;

// Limits a loader enforces before allocating anything. Both the CLI and the daemon set them.
// max_voxels also bounds the points the hierarchy stores (a long side pads to a cube, of which a
// thin volume stores only its data's planes and stand-ins for the rest: stored_planes.h).
struct VolumeLimits {
  int max_dim = 4097;                                // samples per axis (the cube's largest side)
  int64_t max_voxels = int64_t{1025} * 1025 * 1025;  // samples in all
};

}  // namespace isostream
