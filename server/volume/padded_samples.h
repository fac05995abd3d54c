// The samples the hierarchy is built on: a (2^k+1)^3 cube, as a plain array of the planes it
// stores (stored_planes.h: a thin volume stores the cube's planes deep in the padding once per
// kind). Kept free of OpenVDB so the hierarchy and extractor headers stay light (padding.h says
// how a volume becomes one).
#pragma once

#include <array>
#include <cstddef>
#include <vector>

#include "shared/uninitialized_vector.h"

namespace isostream {

struct PaddedSamples {
  int k = 0;  // cube has n = 2^k + 1 samples per axis
  int n = 0;
  std::array<int, 3> data_dims{0, 0, 0};  // the data box is [0, data_dims - 1] in cube points
  // Empty: every plane is stored (the whole cube). Otherwise per axis the stored cube
  // coordinates, ascending, and for every cube coordinate the index of the stored plane that
  // stands for it (StoredPlanesOf).
  std::array<std::vector<int>, 3> planes, plane_of;
  // The stored points, index (z * stored(1) + y) * stored(0) + x over stored plane indices.
  // Uninitialised on resize: the padding fills every sample in parallel, so the pages are
  // first touched there instead of zeroed on one thread.
  UninitializedVector<float> values;

  bool whole_cube() const { return planes[0].empty(); }
  int stored(int axis) const { return whole_cube() ? n : int(planes[axis].size()); }
  // The stored plane index standing for cube coordinate c on `axis`.
  int stand_in(int axis, int c) const { return whole_cube() ? c : plane_of[axis][size_t(c)]; }
  size_t stored_points() const { return size_t(stored(0)) * stored(1) * stored(2); }

  // The sample at cube point (x, y, z).
  float at(int x, int y, int z) const {
    return values[(static_cast<size_t>(stand_in(2, z)) * stored(1) + stand_in(1, y)) * stored(0) +
                  stand_in(0, x)];
  }
};

}  // namespace isostream
