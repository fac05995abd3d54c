#include "server/volume/load.h"

#include <exception>
#include <new>
#include <string>

#include "server/volume/generators.h"
#include "server/volume/loaders.h"
#include "server/volume/volume_spec.h"

namespace isostream {
namespace {

absl::StatusOr<VolumePtr> LoadFromSpec(std::string_view spec, const VolumeLimits& limits,
                                       const std::atomic<bool>* stop) {
  ISOSTREAM_ASSIGN_OR_RETURN(const VolumeSpec parsed, ParseVolumeSpec(spec, limits));
  switch (parsed.source) {
    case VolumeSource::kGenerator:
      return GenerateVolume(parsed, stop);
    case VolumeSource::kVdbFile:
      return LoadVdbFile(parsed.text, parsed.path, parsed.grid_name, limits);
    case VolumeSource::kNiftiFile:
      return LoadNiftiFile(parsed.text, parsed.path, limits, stop);
    case VolumeSource::kRawFile:
      return LoadRawFile(parsed, stop);
  }
  return absl::InternalError(parsed.text + ": no loader for this source");
}

}  // namespace

absl::StatusOr<VolumePtr> LoadVolume(std::string_view spec, const VolumeLimits& limits,
                                     const std::atomic<bool>* stop) {
  // The module edge: nothing thrown by OpenVDB, TBB or the standard library gets past here.
  try {
    return LoadFromSpec(spec, limits, stop);
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError(std::string(spec) + ": out of memory while loading");
  } catch (const std::exception& e) {
    return absl::InternalError(std::string(spec) + ": " + e.what());
  } catch (...) {
    return absl::UnknownError(std::string(spec) + ": unknown exception while loading");
  }
}

}  // namespace isostream
