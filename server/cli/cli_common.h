// Options and parsing shared by the subcommands: the volume/cache flags, vectors like
// "x,y,z", and the view flags that `extract` and (later) `fetch` take alike.
#pragma once

#include <CLI/CLI.hpp>
#include <memory>
#include <string>
#include <vector>

#include "server/extract/extract_request.h"
#include "server/hierarchy/prepared_volume.h"

namespace isostream::cli {

struct VolumeArgs {
  std::string volume;
  std::string cache_dir = DefaultCacheDir();
  bool no_cache = false;
  int threads = 0;
  int max_dim = VolumeLimits{}.max_dim;
};
void AddVolumeOptions(CLI::App* cmd, VolumeArgs* args);

// The spec's own mistakes (ParseVolumeSpec: an unknown generator, a malformed N or raw layout,
// a size past --max-dim, a file type no loader reads), found without reading anything: usage
// errors, where Prepare's failures (a missing or damaged file) are not.
absl::Status CheckVolumeSpec(const VolumeArgs& args);

// Loads, pads and builds (or reads the cached) hierarchy, with a progress line on big volumes.
absl::StatusOr<PreparedVolume> Prepare(const VolumeArgs& args);

// A volume's unit from its meters per unit (Volume::meters_per_unit, > 0): "mm (0.001 m)", "m",
// or the meters alone for a unit without a name.
std::string UnitText(double meters_per_unit);

struct ViewArgs {
  std::string iso;
  double eps = -1;
  int64_t budget = 0;
  std::string eye, view_dir;
  // Whether the flag was given at all (an empty or negative value is then an error, not
  // "absent"); set by AddViewOptions.
  const CLI::Option* eps_flag = nullptr;
  const CLI::Option* budget_flag = nullptr;
  const CLI::Option* eye_flag = nullptr;
  const CLI::Option* view_dir_flag = nullptr;
  std::string order = "back-to-front";
  std::string normals = "smooth";
};
void AddViewOptions(CLI::App* cmd, ViewArgs* args);

// Turns the flags into a request; the default view looks at the volume's centre from outside,
// along an oblique diagonal, when neither --eye nor --view-dir is given.
absl::StatusOr<ExtractRequest> MakeRequest(const ViewArgs& args, const Volume& volume);

// The view's flags checked without the volume (only the default eye needs it), before work
// that may take minutes (preparing a large volume, a call to a daemon).
absl::Status CheckViewArgs(const ViewArgs& args);

absl::StatusOr<std::vector<double>> ParseNumbers(const std::string& text, const char* what);

// --iso's list as the samples' single precision: a value past the float range is refused
// (it could never cross a sample, and converting it would be undefined).
absl::StatusOr<std::vector<float>> ParseIsovalues(const std::string& text);

}  // namespace isostream::cli
