// Hierarchy: the data the adaptive extractor reads. Samples on the (2^k+1)^3 cube and, at every
// grid point, the saturated error bound eta of the diamond centred there (Gerstner §3).
//
// Contract (proved in hierarchy.cpp, tested in tests/unit/hierarchy_test.cpp):
//  * Closure: eta(child diamond) <= eta(parent diamond), so "refine T iff eta(x_ref(T)) >= eps"
//    never leaves a hanging node, for every eps.
//  * Bound: for a tetrahedron T of the hierarchy with refinement vertex x, the linear
//    interpolant of the samples at T's corners differs from the full-resolution piecewise-linear
//    field f_full by at most eta(x) anywhere in T (data units). So an adaptive mesh whose leaves
//    all have eta < eps approximates f_full within eps, and the range of f_full over T lies in
//    [min corner value - eta(x), max corner value + eta(x)] (used for culling).
#pragma once

#include <array>
#include <cstddef>
#include <functional>
#include <memory>
#include <vector>

#include "server/volume/padded_samples.h"
#include "shared/status.h"
#include "shared/uninitialized_vector.h"

namespace isostream {

class Hierarchy {
 public:
  int k() const { return k_; }
  int n() const { return n_; }  // points per axis, 2^k + 1
  const std::array<int, 3>& data_dims() const { return data_dims_; }

  size_t index(int x, int y, int z) const { return (static_cast<size_t>(z) * n_ + y) * n_ + x; }
  const float* samples() const { return samples_.data(); }
  const float* eta() const { return eta_.data(); }
  float sample(int x, int y, int z) const { return samples_[index(x, y, z)]; }
  float eta(int x, int y, int z) const { return eta_[index(x, y, z)]; }
  size_t point_count() const { return samples_.size(); }

  // Memory the hierarchy adds on top of the samples (eta), and in all.
  size_t eta_bytes() const { return eta_.size() * sizeof(float); }
  size_t total_bytes() const { return eta_bytes() + samples_.size() * sizeof(float); }

 private:
  friend class HierarchyBuilder;
  friend absl::StatusOr<std::shared_ptr<const Hierarchy>> AssembleHierarchy(PaddedSamples samples,
                                                                            UninitializedVector<float> eta);
  int k_ = 0;
  int n_ = 0;
  std::array<int, 3> data_dims_{0, 0, 0};
  std::vector<float> samples_;
  UninitializedVector<float> eta_;
};

using HierarchyPtr = std::shared_ptr<const Hierarchy>;

struct HierarchyBuildOptions {
  int threads = 0;  // 0: all cores
  // Called after each scale with the fraction of points done; may be empty.
  std::function<void(double)> progress;
};

// Builds eta from the padded samples (taken over). Fails only on invalid samples.
absl::StatusOr<HierarchyPtr> BuildHierarchy(PaddedSamples samples,
                                            const HierarchyBuildOptions& options = {});

// Wraps a hierarchy whose eta was computed before (the on-disk cache). Sizes must match.
absl::StatusOr<HierarchyPtr> AssembleHierarchy(PaddedSamples samples, UninitializedVector<float> eta);

}  // namespace isostream
