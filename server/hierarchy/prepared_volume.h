// A volume ready to extract from: loaded, padded, and its hierarchy built or read from the
// cache. The CLI and the daemon's catalogue both go through PrepareVolume.
#pragma once

#include <string>

#include "server/hierarchy/hierarchy_cache.h"
#include "server/volume/volume.h"

namespace isostream {

struct PreparedVolume {
  // The volume's facts (dims, spacing, origin, value range). Its grid is released (null) once
  // the hierarchy holds the samples: read them there (Hierarchy::sample).
  VolumePtr volume;
  HierarchyPtr hierarchy;
  GridToWorld grid_to_world;  // hierarchy cube point -> world (volume spacing and origin)
  CacheOutcome cache = CacheOutcome::kDisabled;
  std::string cache_note;
  double load_s = 0, pad_s = 0, hierarchy_s = 0;
};

// build.stop, if set, also stops the preparation (CANCELLED) between its steps and a
// generator's slabs; reading a file and padding are not interrupted.
absl::StatusOr<PreparedVolume> PrepareVolume(const std::string& spec, const VolumeLimits& limits,
                                             const HierarchyCacheOptions& cache,
                                             const HierarchyBuildOptions& build);

}  // namespace isostream
