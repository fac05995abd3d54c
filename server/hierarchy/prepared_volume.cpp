#include "server/hierarchy/prepared_volume.h"

#include <chrono>
#include <exception>
#include <new>

#include "server/volume/load.h"
#include "server/volume/padding.h"
#include "server/volume/stored_planes.h"
#include "shared/malloc_tuning.h"

namespace isostream {
namespace {

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

absl::Status StopRequested(const HierarchyBuildOptions& build) {
  if (build.stop && build.stop->load()) return absl::CancelledError("preparation stopped");
  return absl::OkStatus();
}

absl::StatusOr<PreparedVolume> PrepareSteps(const std::string& spec, const VolumeLimits& limits,
                                            const HierarchyCacheOptions& cache,
                                            const HierarchyBuildOptions& build) {
  PreparedVolume p;
  auto t0 = std::chrono::steady_clock::now();
  ISOSTREAM_ASSIGN_OR_RETURN(p.volume, LoadVolume(spec, limits, build.stop));
  p.load_s = Seconds(t0);
  ISOSTREAM_RETURN_IF_ERROR(StopRequested(build));
  // The loader counted the data's samples; the hierarchy holds the points of the cube's planes it
  // stores (stored_planes.h: with stand-ins, a 1025x2x2 file of 4 KB holds 1025x29x29 points,
  // where the whole cube would take ~13 GB), and that is what max_voxels must bound.
  const int k = HierarchyLevelFor(p.volume->dims);
  const int64_t side = (int64_t{1} << k) + 1;
  const int64_t points = StoredPointCount(k, p.volume->dims);
  if (points > limits.max_voxels)
    return absl::ResourceExhaustedError(
        spec + ": is held as " + std::to_string(points) + " points of a " + std::to_string(side) +
        "^3 cube (its longest side, cubed" +
        (points < side * side * side ? ", less the planes deep in its padding" : "") +
        "), past the limit of " + std::to_string(limits.max_voxels));
  t0 = std::chrono::steady_clock::now();
  ISOSTREAM_ASSIGN_OR_RETURN(PaddedSamples padded, PadToHierarchyDomain(*p.volume, build.stop));
  p.pad_s = Seconds(t0);
  // The padded samples hold every sample and nothing reads the grid again; kept, it would be
  // ~40% of what a served volume holds (cayley:513: 540 of 1430 MB). It goes before the
  // hierarchy is made, whose store is the peak (the grid of a 600x700x800 volume is 1.3 GB),
  // and its leaves are small heap blocks, which a heap kept for reuse would keep.
  auto facts = std::make_shared<Volume>(*p.volume);
  facts->grid.reset();
  p.volume = std::move(facts);
  ReturnFreedMemory();
  ISOSTREAM_RETURN_IF_ERROR(StopRequested(build));
  t0 = std::chrono::steady_clock::now();
  ISOSTREAM_ASSIGN_OR_RETURN(
      p.hierarchy, LoadOrBuildHierarchy(std::move(padded), cache, build, &p.cache, &p.cache_note));
  p.hierarchy_s = Seconds(t0);
  for (int a = 0; a < 3; ++a) {
    p.grid_to_world.origin[a] = p.volume->origin[a];
    p.grid_to_world.spacing[a] = p.volume->spacing[a];
  }
  return p;
}

}  // namespace

absl::StatusOr<PreparedVolume> PrepareVolume(const std::string& spec, const VolumeLimits& limits,
                                             const HierarchyCacheOptions& cache,
                                             const HierarchyBuildOptions& build) {
  // The module edge: a throw from any step (the standard library's file system calls, an
  // allocation) is the caller's error status, not the end of a daemon serving other volumes.
  try {
    return PrepareSteps(spec, limits, cache, build);
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError(spec + ": out of memory while preparing");
  } catch (const std::exception& e) {
    return absl::InternalError(spec + ": " + e.what());
  }
}

}  // namespace isostream
