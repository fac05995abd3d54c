// Private to server/volume: turning a file's sample axes onto the world's. A volume is held on
// an axis-aligned grid with positive spacing (GridToWorld), while a file may store its samples
// with axes reversed, swapped or rotated (a NIfTI sform or qform, an OpenVDB transform). The
// nearest signed permutation of the axes is found from the file's voxel-to-world matrix, and
// the grid is turned in place onto the world's axes, so a surface is never drawn mirrored.
#pragma once

#include <array>
#include <string>

#include "server/volume/volume.h"
#include "shared/status.h"

namespace isostream {

struct Orientation {
  // World axis a takes the file's axis source[a], read backwards where flip[a].
  std::array<int, 3> source{0, 1, 2};
  std::array<bool, 3> flip{false, false, false};
  std::array<int, 3> dims{0, 0, 0};        // along the world's axes
  std::array<double, 3> spacing{1, 1, 1};  // length of one step along world axis a
  std::array<double, 3> origin{0, 0, 0};   // world position of the volume's first sample
  // The largest angle between a file axis and the world axis it is put on: 0 unless the file's
  // grid is rotated off the world's axes, where positions are then approximate.
  double off_axis_degrees = 0;
  // Why the file's own choice of placement was passed over, if it was (a NIfTI sform or qform
  // that is set but unusable): "the sform is unusable (...); placed by the qform".
  std::string fallback;

  bool identity() const;
  // For Volume::orientation: "" for the identity, else e.g. "file axes i j k on world -x +z +y";
  // then the fallback, if any.
  std::string Describe() const;
};

// The orientation of `dims` samples whose file index v lies at world position m * v + offset
// (m[row][column]; column i is the world step of file axis i). InvalidArgument when m is not
// finite or singular.
absl::StatusOr<Orientation> NearestAxes(const std::array<std::array<double, 3>, 3>& m,
                                        const std::array<double, 3>& offset,
                                        const std::array<int, 3>& dims);

// The volume with its grid rebuilt along the world's axes (o from NearestAxes for its dims):
// each OpenVDB leaf stays one leaf, since a reversed index i becomes -1 - i, so a leaf's 8^3
// block maps onto another whole leaf (and a tile's cube onto an aligned cube), and each leaf is
// turned in place: the grid itself is turned. `volume` (any index_min) must not be shared.
VolumePtr Reorient(VolumePtr volume, const Orientation& o);

}  // namespace isostream
