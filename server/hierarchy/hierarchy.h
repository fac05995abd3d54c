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
#include <glm/vec3.hpp>
#include <memory>
#include <vector>

#include "server/volume/padded_samples.h"
#include "shared/status.h"
#include "shared/uninitialized_vector.h"

namespace isostream {

// Maps grid points of the hierarchy cube to world space: world = origin + spacing * grid.
struct GridToWorld {
  glm::dvec3 origin{0.0};
  glm::dvec3 spacing{1.0};
};

class Hierarchy {
 public:
  int k() const { return k_; }
  int n() const { return n_; }  // points per axis, 2^k + 1
  const std::array<int, 3>& data_dims() const { return data_dims_; }
  size_t point_count() const { return size_t(n_) * n_ * n_; }

  // Storage: sample and eta interleaved, in bricks of 8x8x8 points (4 KiB, one page). A
  // traversal reads a tetrahedron's corners and refinement vertex together, and they are
  // close in space: bricks keep them on the same page and mostly in the same cache lines,
  // where a linear layout puts every z step a whole plane away.
  size_t index(int x, int y, int z) const {
    const size_t brick =
        (size_t(z >> kBrickLog2) * nb_ + size_t(y >> kBrickLog2)) * nb_ + size_t(x >> kBrickLog2);
    return (brick << (3 * kBrickLog2)) | (size_t(z & kBrickMask) << (2 * kBrickLog2)) |
           (size_t(y & kBrickMask) << kBrickLog2) | size_t(x & kBrickMask);
  }
  const float* pairs() const { return data_.data(); }  // [2 i] sample, [2 i + 1] eta
  float sample(int x, int y, int z) const { return data_[2 * index(x, y, z)]; }
  float eta(int x, int y, int z) const { return data_[2 * index(x, y, z) + 1]; }

  // Linear (x fastest) copies, for the cache file and for tests.
  std::vector<float> LinearSamples() const;
  std::vector<float> LinearEta() const;

  // Memory: eta's share and the whole interleaved store (bricks pad n up to a multiple of 8).
  size_t eta_bytes() const { return data_.size() / 2 * sizeof(float); }
  size_t total_bytes() const { return data_.size() * sizeof(float); }

  static constexpr int kBrickLog2 = 3;
  static constexpr int kBrickMask = (1 << kBrickLog2) - 1;

 private:
  friend absl::StatusOr<std::shared_ptr<const Hierarchy>> AssembleHierarchy(
      PaddedSamples samples, UninitializedVector<float> eta);
  template <typename F>
  void ForEachRow(F&& f) const;

  int k_ = 0;
  int n_ = 0;
  size_t nb_ = 0;  // bricks per axis
  std::array<int, 3> data_dims_{0, 0, 0};
  UninitializedVector<float> data_;
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

// Builds the hierarchy's store from linear samples and linear eta (computed by
// BuildHierarchy, or read from the on-disk cache). Sizes must match.
absl::StatusOr<HierarchyPtr> AssembleHierarchy(PaddedSamples samples,
                                               UninitializedVector<float> eta);

}  // namespace isostream
