// A volume SPEC taken apart before anything is read: which source it names and the parameters
// written in the spec itself (a generator's N and seed, a raw file's layout). The forms are
// listed in load.h.
//
// Parsing is a step of its own so that a caller can tell a spec that is wrong as written (an
// unknown generator, a malformed N or raw layout, a file type no loader reads) from a source
// that fails when read (a missing, unreadable or damaged file): the command line calls the
// first a usage error. Whether a file by the spec's own name exists is consulted only where the
// forms overlap ("file.vdb#grid" may also be a file's name); no file is opened.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

#include "server/volume/volume.h"
#include "shared/status.h"

namespace isostream {

enum class VolumeSource { kGenerator, kVdbFile, kNiftiFile, kRawFile };

struct VolumeSpec {
  VolumeSource source = VolumeSource::kGenerator;
  std::string text;  // as written: the volume is named by it and messages quote it

  // kGenerator
  std::string generator;  // one of GeneratorNames()
  int n = 0;              // samples per axis, within the limits parsed against
  uint32_t seed = 0;      // noise only

  // kVdbFile, kNiftiFile, kRawFile
  std::string path;
  std::string grid_name;  // kVdbFile: the grid after '#'; empty: the first float grid

  // kRawFile: the layout the spec gives, dims within the limits parsed against
  std::array<int, 3> dims{0, 0, 0};
  std::string sample_type;  // uint8 int8 uint16 int16 uint32 int32 float32 float64
  bool big_endian = false;
};

// Errors, each naming the spec: NotFound for an unknown generator name, ResourceExhausted for
// a generator's N or raw dims beyond LIMITS, InvalidArgument for everything else (empty spec,
// malformed N, seed or raw fields, N or dims below 2, a file name without a known extension).
absl::StatusOr<VolumeSpec> ParseVolumeSpec(std::string_view spec, const VolumeLimits& limits = {});

}  // namespace isostream
