// On-disk cache of built hierarchies, so a restart does not rebuild.
//
// A cache file holds eta for one set of padded samples as the hierarchy stores it: bfloat16
// codes, linear (x fastest) over the planes it stores (the whole cube, or stand-ins for the
// planes deep in the padding: stored_planes.h), 2 bytes per point (format version 2; version 1
// held float eta, 4 bytes per point). It is keyed by a hash of the samples (so any change to the source, the
// padding or the generator makes the entry stale) and carries a format version and a checksum
// of the payload. A file that is stale, truncated, from another version or fails its checksum
// is ignored and replaced by a fresh build; writes go to a temporary file renamed into place,
// so readers never see half a file.
#pragma once

#include <string>

#include "server/hierarchy/hierarchy.h"

namespace isostream {

enum class CacheOutcome { kDisabled, kHit, kMissBuilt, kInvalidRebuilt };
const char* CacheOutcomeName(CacheOutcome outcome);

struct HierarchyCacheOptions {
  std::string dir;  // empty: no cache
  // After a store, the least recently used entries (by modification time, which a hit
  // refreshes) are removed until the cache's entries total at most this many bytes; the one
  // just stored stays, and entries whose hierarchies this process still holds go last. 0: no
  // cap. The daemon sets one: its clients name the volumes.
  uint64_t max_bytes = 0;
};

// Default cache directory: $ISOSTREAM_CACHE_DIR, else $XDG_CACHE_HOME/isostream, else
// $HOME/.cache/isostream.
std::string DefaultCacheDir();

// Returns the cached hierarchy for these samples, or builds (and stores) it. A cache that
// cannot be written is not an error: the built hierarchy is returned and `why` says so.
// CANCELLED once build.stop is set: the cache is read, as the hierarchy is built, in slabs.
absl::StatusOr<HierarchyPtr> LoadOrBuildHierarchy(PaddedSamples samples,
                                                  const HierarchyCacheOptions& cache,
                                                  const HierarchyBuildOptions& build,
                                                  CacheOutcome* outcome = nullptr,
                                                  std::string* why = nullptr);

// Applies cache.max_bytes now (the daemon at start: a cap lowered since the last run), and
// removes entries left half-written by a process that died. No-op without a cap.
void TrimHierarchyCache(const HierarchyCacheOptions& cache);

// The path a given sample set is cached under (for tests and `isostream info`).
std::string HierarchyCachePath(const std::string& dir, const PaddedSamples& samples);

inline constexpr uint32_t kHierarchyCacheVersion = 2;

}  // namespace isostream
