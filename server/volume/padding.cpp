#include "server/volume/padding.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <exception>
#include <new>
#include <string>

#include "server/volume/grid_blocks.h"
#include "server/volume/stored_planes.h"

namespace isostream {
namespace {

// 2^12 + 1 = 4097 samples per axis is 275 GB of floats: far past any machine this runs on, so a
// larger k can only come from a bug or a hostile input.
constexpr int kMaxHierarchyLevel = 12;
// Leaf buffers are z fastest: consecutive x are a plane of the leaf apart.
constexpr int kLeafXStride = FloatLeaf::DIM * FloatLeaf::DIM;

// The stored planes are the one allocation padding makes, and the one that can be huge (a
// 2049-sample axis makes the whole cube 2049^3 floats, 32 GiB): its failure says how much was
// asked for.
absl::Status OutOfMemory(const std::string& where, const PaddedSamples& out) {
  const double bytes = double(out.stored_points()) * sizeof(float);
  char size[32];
  if (bytes >= double(1 << 30))
    std::snprintf(size, sizeof(size), "%.1f GiB", bytes / double(1 << 30));
  else
    std::snprintf(size, sizeof(size), "%.0f MiB", bytes / double(1 << 20));
  const std::string what = out.whole_cube() ? "the " + std::to_string(out.n) + "^3 cube"
                                            : "the " + std::to_string(out.n) + "^3 cube's " +
                                                  std::to_string(out.stored(0)) + "x" +
                                                  std::to_string(out.stored(1)) + "x" +
                                                  std::to_string(out.stored(2)) + " stored planes";
  return absl::ResourceExhaustedError(where + ": out of memory for " + what + " (" + size + ")");
}

absl::StatusOr<PaddedSamples> Pad(const Volume& volume, const std::string& where,
                                  const std::atomic<bool>* stop, CubePlanes planes) {
  // Each pass skips its remaining work once told to stop; the status says so after it.
  const auto stopped = [stop] { return stop != nullptr && stop->load(); };
  const std::array<int, 3>& dims = volume.dims;
  if (volume.grid == nullptr) return absl::InvalidArgumentError(where + ": volume has no grid");
  if (std::min({dims[0], dims[1], dims[2]}) < 2) {
    return absl::InvalidArgumentError(where + ": dims " + std::to_string(dims[0]) + "x" +
                                      std::to_string(dims[1]) + "x" + std::to_string(dims[2]) +
                                      " need at least 2 samples per axis");
  }
  const int k = HierarchyLevelFor(dims);
  if (k > kMaxHierarchyLevel) {
    return absl::ResourceExhaustedError(where + ": needs a cube of 2^" + std::to_string(k) +
                                        "+1 samples per axis; the limit is 2^" +
                                        std::to_string(kMaxHierarchyLevel) + "+1");
  }

  PaddedSamples out;
  out.k = k;
  out.n = (1 << k) + 1;
  out.data_dims = dims;
  if (planes == CubePlanes::kStandIns)
    if (auto axes = StandInPlanes(k, dims))
      for (int a = 0; a < 3; ++a) {
        out.planes[a] = std::move((*axes)[a].planes);
        out.plane_of[a] = std::move((*axes)[a].plane_of);
      }
  // Stored plane indices equal cube coordinates up to the data's last plane on every axis (all
  // of those are stored, first), so the data box sits at the array's origin corner as in the
  // whole cube; sx, sy, sz are the stored extents.
  const int sx = out.stored(0), sy = out.stored(1), sz = out.stored(2);
  const size_t plane = static_cast<size_t>(sx) * sy;
  try {
    out.values.resize(plane * sz);
  } catch (const std::bad_alloc&) {
    return OutOfMemory(where, out);
  }
  float* cube = out.values.data();

  // Copy the data box to the cube's origin corner, leaf block by leaf block.
  const openvdb::Coord lo(volume.index_min[0], volume.index_min[1], volume.index_min[2]);
  const openvdb::CoordBBox box(lo, lo.offsetBy(dims[0] - 1, dims[1] - 1, dims[2] - 1));
  ForEachBlock(*volume.grid, box,
               [&](const openvdb::CoordBBox& block, const float* leaf_values, float value) {
                 if (stopped()) return;
                 for (int z = block.min().z(); z <= block.max().z(); ++z) {
                   for (int y = block.min().y(); y <= block.max().y(); ++y) {
                     float* row = cube + (z - lo.z()) * plane +
                                  static_cast<size_t>(y - lo.y()) * sx + (block.min().x() - lo.x());
                     const int width = block.max().x() - block.min().x() + 1;
                     if (leaf_values == nullptr) {
                       std::fill(row, row + width, value);
                       continue;
                     }
                     const float* src =
                         leaf_values + LeafOffset(openvdb::Coord(block.min().x(), y, z));
                     if (width == 8) {  // a whole leaf row: unrolled, constant strides
#pragma GCC unroll 8
                       for (int x = 0; x < 8; ++x) row[x] = src[x * kLeafXStride];
                       continue;
                     }
                     for (int x = 0; x < width; ++x) row[x] = src[x * kLeafXStride];
                   }
                 }
               });

  if (stopped()) return absl::CancelledError(where + ": stopped");

  // Replicate edges: first along x and y inside the data planes, then whole planes along z
  // (which need the finished plane dims[2] - 1, hence two passes).
  const int dx = dims[0], dy = dims[1], dz = dims[2];
  tbb::parallel_for(tbb::blocked_range<int>(0, dz), [&](const tbb::blocked_range<int>& r) {
    for (int z = r.begin(); z != r.end() && !stopped(); ++z) {
      float* p = cube + z * plane;
      for (int y = 0; y < dy; ++y) {
        float* row = p + static_cast<size_t>(y) * sx;
        std::fill(row + dx, row + sx, row[dx - 1]);
      }
      const float* last_row = p + static_cast<size_t>(dy - 1) * sx;
      for (int y = dy; y < sy; ++y)
        std::memcpy(p + static_cast<size_t>(y) * sx, last_row, sx * sizeof(float));
    }
  });
  if (stopped()) return absl::CancelledError(where + ": stopped");
  tbb::parallel_for(tbb::blocked_range<int>(dz, sz), [&](const tbb::blocked_range<int>& r) {
    const float* last_plane = cube + (dz - 1) * plane;
    for (int z = r.begin(); z != r.end() && !stopped(); ++z) {
      std::memcpy(cube + z * plane, last_plane, plane * sizeof(float));
    }
  });
  if (stopped()) return absl::CancelledError(where + ": stopped");
  return out;
}

}  // namespace

int HierarchyLevelFor(const std::array<int, 3>& dims) {
  const int64_t largest = std::max({dims[0], dims[1], dims[2]});
  int k = 1;  // the hierarchy starts at one cube of 3^3 points: 2 samples per axis pad to it
  while ((int64_t{1} << k) + 1 < largest) ++k;
  return k;
}

absl::StatusOr<PaddedSamples> PadToHierarchyDomain(const Volume& volume,
                                                   const std::atomic<bool>* stop,
                                                   CubePlanes planes) {
  const std::string where = "padding '" + volume.name + "'";
  // A module edge like LoadVolume: a throw from OpenVDB or TBB becomes a status here.
  try {
    return Pad(volume, where, stop, planes);
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError(where + ": out of memory");
  } catch (const std::exception& e) {
    return absl::InternalError(where + ": " + e.what());
  }
}

}  // namespace isostream
