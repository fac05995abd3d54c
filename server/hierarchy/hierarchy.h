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
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
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

// eta is stored as bfloat16 (the top 16 bits of a float32) rounded up: 2 bytes per point,
// within 2^-7 of the float value, and never below it, so the bound and the saturation order
// (rounding up is monotone) survive.
inline uint16_t EncodeEtaRoundingUp(float eta) {
  uint32_t bits;
  std::memcpy(&bits, &eta, sizeof(bits));
  if (bits & 0xffffu) bits += 0x10000u;  // eta >= 0: adding one ulp of bfloat16 rounds up
  return static_cast<uint16_t>(bits >> 16);
}
inline float DecodeEta(uint16_t stored) {
  const uint32_t bits = uint32_t{stored} << 16;
  float eta;
  std::memcpy(&eta, &bits, sizeof(eta));
  return eta;
}

// 8x8x8 points: their samples, then their eta (3 KiB). A traversal reads a tetrahedron's
// corners and refinement vertex together, and they are close in space: bricks keep them on
// the same pages and mostly in the same cache lines, where a linear layout puts every z step
// a whole plane away.
//
// Inside a brick the points are grouped by the parities of their coordinates: 8 groups of
// 4x4x4 (all even first), x fastest within a group. Above the last three levels the
// traversal reads only even points, and each level below reads mostly one parity class at a
// time: a line of samples then holds 16 points it will read (4x4 of one class, spanning 8x8
// cells of one plane), where rows of x put 4 of them in a line.
struct HierarchyBrick {
  static constexpr int kLog2 = 3;
  static constexpr int kMask = (1 << kLog2) - 1;
  static constexpr int kPoints = 1 << (3 * kLog2);
  // Index contribution of local coordinate c (0..7) on axis a (0 = x): the parity selects the
  // group (64 points), c / 2 the place in it. The three axes' contributions add up.
  static constexpr int Local(int axis, int c) {
    return ((c & 1) << (6 + axis)) | ((c >> 1) << (2 * axis));
  }
  float value[kPoints];
  uint16_t eta[kPoints];
};

struct HierarchyBuildOptions;

// Where AssembleHierarchy gets the eta codes of a previous build: writes those of the stored
// points on stored z planes [z_begin, z_end) to `codes`, linear (x fastest over the stored
// planes), and returns true; false if they cannot be had (a truncated file).
using EtaCodeSlabs = std::function<bool(int z_begin, int z_end, uint16_t* codes)>;

class Hierarchy {
 public:
  int k() const { return k_; }
  int n() const { return n_; }  // points per axis, 2^k + 1
  const std::array<int, 3>& data_dims() const { return data_dims_; }
  size_t point_count() const { return size_t(n_) * n_ * n_; }  // the cube's
  // Planes stored per axis: n, or fewer where stand-ins hold the planes deep in the padding
  // (stored_planes.h); every cube point reads as its stand-in's sample and eta.
  const std::array<int, 3>& stored_dims() const { return stored_; }
  size_t stored_point_count() const { return size_t(stored_[0]) * stored_[1] * stored_[2]; }

  // Point index: brick number * 512 + position inside the brick. The brick layout separates
  // per axis, so it is a sum of three per-axis offsets, tabulated (three small-table loads
  // beat the shifts and multiplies on the traversal's hot path); a coordinate whose plane is not
  // stored maps to its stand-in's.
  size_t index(int x, int y, int z) const {
    return size_t(axis_offset_[0][x]) + axis_offset_[1][y] + axis_offset_[2][z];
  }
  // axis_offsets()[a][c]: the index contribution of coordinate c on axis a.
  const std::array<std::vector<uint64_t>, 3>& axis_offsets() const { return axis_offset_; }
  // The same separation in bytes from bricks(): the sum over the axes of value_byte_offsets()
  // is the byte offset of the point's sample, of eta_byte_offsets() that of its eta. The
  // extractor's hot loops address the store with these (a sum and a load, where the index
  // needs a shift, a multiply and a mask first).
  const std::array<std::vector<uint64_t>, 3>& value_byte_offsets() const { return value_bytes_; }
  const std::array<std::vector<uint64_t>, 3>& eta_byte_offsets() const { return eta_bytes_; }
  const HierarchyBrick* bricks() const { return bricks_.data(); }
  float sample_at(size_t i) const { return bricks_[i >> 9].value[i & 511]; }
  float eta_at(size_t i) const { return DecodeEta(bricks_[i >> 9].eta[i & 511]); }
  float sample(int x, int y, int z) const { return sample_at(index(x, y, z)); }
  float eta(int x, int y, int z) const { return eta_at(index(x, y, z)); }

  // Linear (x fastest) copies of the whole cube, for tests and tools; LinearEtaCodes: the
  // stored bfloat16 codes.
  std::vector<float> LinearSamples() const;
  std::vector<float> LinearEta() const;
  UninitializedVector<uint16_t> LinearEtaCodes() const;
  // The codes of the stored points, linear over the stored planes (x fastest): what the
  // on-disk cache keeps. The same as LinearEtaCodes where every plane is stored.
  UninitializedVector<uint16_t> StoredEtaCodes() const;

  // Memory: eta's share and the whole store (bricks pad the stored planes up to a multiple of 8
  // per axis).
  size_t eta_bytes() const { return bricks_.size() * sizeof(HierarchyBrick::eta); }
  size_t total_bytes() const { return bricks_.size() * sizeof(HierarchyBrick); }

 private:
  friend class HierarchyBuilder;
  friend class StandInBuilder;
  friend absl::StatusOr<std::shared_ptr<const Hierarchy>> BuildHierarchy(
      PaddedSamples samples, const HierarchyBuildOptions& options);
  friend absl::StatusOr<std::shared_ptr<const Hierarchy>> AssembleHierarchy(
      const PaddedSamples& samples, const EtaCodeSlabs& read_eta_codes);
  // Checks the cube's shape, sets the sizes and offset tables, allocates (does not fill) the
  // bricks.
  absl::Status SetUpStore(const PaddedSamples& samples);
  // The brick holding stored point (i, j, l) (stored plane indices), and its place there.
  size_t BrickOf(int i, int j, int l) const {
    constexpr int b = HierarchyBrick::kLog2;
    return (size_t(l >> b) * bricks_per_axis_[1] + size_t(j >> b)) * bricks_per_axis_[0] +
           size_t(i >> b);
  }
  static int PlaceInBrick(int i, int j, int l) {
    constexpr int m = HierarchyBrick::kMask;
    return HierarchyBrick::Local(0, i & m) + HierarchyBrick::Local(1, j & m) +
           HierarchyBrick::Local(2, l & m);
  }
  template <typename F>
  void ForEachRow(F&& f) const;

  int k_ = 0;
  int n_ = 0;
  std::array<int, 3> data_dims_{0, 0, 0};
  std::array<int, 3> stored_{0, 0, 0};
  std::array<size_t, 3> bricks_per_axis_{0, 0, 0};
  UninitializedVector<HierarchyBrick> bricks_;
  // 64-bit: at k = 11 and 12 the cube has 8.7e9 and 6.9e10 point slots.
  std::array<std::vector<uint64_t>, 3> axis_offset_;
  std::array<std::vector<uint64_t>, 3> value_bytes_, eta_bytes_;
};

using HierarchyPtr = std::shared_ptr<const Hierarchy>;

struct HierarchyBuildOptions {
  int threads = 0;  // 0: all cores
  // Called after each scale with the fraction of points done; may be empty.
  std::function<void(double)> progress;
  // If set, and true while building (a daemon shutting down), the build gives up between
  // tiles and returns CANCELLED: a 1025^3 build takes far longer than a service may take to stop.
  const std::atomic<bool>* stop = nullptr;
};

// Builds eta from the padded samples (taken over: the build uses their array as scratch).
// Fails only on invalid (non-finite) samples. Where finite samples near FLT_MAX give wavelets
// past the float range, eta is stored as +inf: those tetrahedra always refine (conservative).
// Allocates nothing large beyond the bricks it returns.
absl::StatusOr<HierarchyPtr> BuildHierarchy(PaddedSamples samples,
                                            const HierarchyBuildOptions& options = {});

// Builds the hierarchy's store from the samples and the bfloat16 eta codes of a previous build
// of the same stored planes (Hierarchy::StoredEtaCodes, as kept by the on-disk cache; linear
// over the stored planes, a plane being stored(0) x stored(1) codes), asked for 8 planes at a
// time: the whole cube's codes are never held beside the samples and the store (at
// 1025^3 they were 2.15 GB more than a build's peak). DATA_LOSS if `read_eta_codes` fails.
absl::StatusOr<HierarchyPtr> AssembleHierarchy(const PaddedSamples& samples,
                                               const EtaCodeSlabs& read_eta_codes);

}  // namespace isostream
