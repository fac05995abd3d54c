// The samples the hierarchy is built on: a (2^k+1)^3 cube as a plain array. Kept free of
// OpenVDB so the hierarchy and extractor headers stay light (padding.h says how a volume
// becomes one).
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
  // n^3, index (z * n + y) * n + x. Uninitialised on resize: the padding fills every sample
  // in parallel, so the pages are first touched there instead of zeroed on one thread.
  UninitializedVector<float> values;

  float at(int x, int y, int z) const {
    return values[(static_cast<size_t>(z) * n + y) * n + x];
  }
};

}  // namespace isostream
