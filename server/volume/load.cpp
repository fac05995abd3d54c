#include "server/volume/load.h"

#include <exception>
#include <new>
#include <string>

#include "server/volume/generators.h"
#include "server/volume/loaders.h"
#include "server/volume/volume_spec.h"
#include "shared/printable_text.h"

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

// The module edge: nothing thrown by OpenVDB, TBB or the standard library gets past here.
absl::StatusOr<VolumePtr> LoadGuarded(std::string_view spec, const VolumeLimits& limits,
                                      const std::atomic<bool>* stop) {
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

}  // namespace

absl::StatusOr<VolumePtr> LoadVolume(std::string_view spec, const VolumeLimits& limits,
                                     const std::atomic<bool>* stop) {
  absl::StatusOr<VolumePtr> loaded = LoadGuarded(spec, limits, stop);
  // Messages quote the file (grid, metadata and transform names, OpenVDB's words about them):
  // printable, so a file cannot write lines of its own into the daemon's log or a terminal.
  if (!loaded.ok()) {
    const absl::string_view message = loaded.status().message();
    return absl::Status(loaded.status().code(),
                        PrintableText(std::string_view(message.data(), message.size())));
  }
  return loaded;
}

}  // namespace isostream
