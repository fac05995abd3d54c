// Private to server/volume: one loader per kind of source. LoadVolume (load.cpp) picks one from
// the spec and is the only caller; each returns a status whose message starts with its input.
#pragma once

#include <atomic>
#include <string>

#include "server/volume/volume.h"
#include "server/volume/volume_spec.h"
#include "shared/status.h"

namespace isostream {

// PATH's float grid GRID_NAME, or its first float grid when GRID_NAME is empty.
absl::StatusOr<VolumePtr> LoadVdbFile(const std::string& spec, const std::string& path,
                                      const std::string& grid_name, const VolumeLimits& limits);

// The same from the file open as FD (read-only), which PATH named when it was opened: the
// structure check and OpenVDB's reads see that one file whatever happens to PATH meanwhile.
absl::StatusOr<VolumePtr> LoadVdbOpenFile(int fd, const std::string& spec, const std::string& path,
                                          const std::string& grid_name, const VolumeLimits& limits);

// A single-file NIfTI-1 volume, gzip-compressed or not. Cancelled between slabs once `stop`
// (may be null) is set.
absl::StatusOr<VolumePtr> LoadNiftiFile(const std::string& spec, const std::string& path,
                                        const VolumeLimits& limits,
                                        const std::atomic<bool>* stop = nullptr);

// The raw file a parsed "raw:PATH:NXxNYxNZ:TYPE[:le|be]" spec names, in its layout. Cancelled
// between slabs once `stop` (may be null) is set.
absl::StatusOr<VolumePtr> LoadRawFile(const VolumeSpec& spec,
                                      const std::atomic<bool>* stop = nullptr);

}  // namespace isostream
