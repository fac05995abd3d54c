// Loading volumes from a SPEC string: a built-in generator, or a file.
//
// SPEC forms:
//   cayley:N | buckyball:N | sphere:N | shells:N | noise:N[:SEED]   built-in generators, N^3 samples
//   path/to/file.vdb[#GRIDNAME]        OpenVDB file: the named float grid, else the first float grid
//   path/to/file.nii | .nii.gz          NIfTI-1 (uint8, int16, uint16, int32, float32, float64)
//   raw:PATH:NXxNYxNZ:TYPE[:le|be]      raw samples, x fastest; TYPE one of uint8 int8 uint16 int16
//                                       uint32 int32 float32 float64; little-endian by default
//
// Every failure returns a status whose message names the input and the problem (missing file,
// wrong magic, truncated data, dims out of range, unsupported type, NaN/Inf sample). A volume is
// returned only when it loaded whole; nothing half-loaded escapes. The spec is taken apart
// first by ParseVolumeSpec (volume_spec.h), whose refusals come back unchanged.
#pragma once

#include <atomic>
#include <string_view>

#include "server/volume/volume.h"
#include "shared/status.h"

namespace isostream {

// `stop`, if set and true, ends a generator's sampling (GenerateVolume); files are read whole.
absl::StatusOr<VolumePtr> LoadVolume(std::string_view spec, const VolumeLimits& limits = {},
                                     const std::atomic<bool>* stop = nullptr);

// The generator names LoadVolume understands, for help texts and catalogues.
const char* const* GeneratorNames();  // null-terminated

}  // namespace isostream
