#include "server/volume/load.h"

#include <algorithm>
#include <cctype>
#include <exception>
#include <new>
#include <string>

#include "absl/strings/match.h"
#include "server/volume/generators.h"
#include "server/volume/loaders.h"
#include "server/volume/sample_reader.h"

namespace isostream {
namespace {

// "word:..." with a word of two or more letters, digits or '_' is a generator spec, so that an
// unknown generator gets "unknown generator" rather than "no such file"; the length rule keeps
// Windows-style "C:..." paths out.
bool LooksLikeGenerator(std::string_view spec) {
  const size_t colon = spec.find(':');
  if (colon == std::string_view::npos || colon < 2) return false;
  if (!std::isalpha(static_cast<unsigned char>(spec[0]))) return false;
  return std::all_of(spec.begin(), spec.begin() + colon, [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_';
  });
}

absl::StatusOr<VolumePtr> LoadFromSpec(std::string_view spec, const VolumeLimits& limits) {
  if (spec.empty()) return absl::InvalidArgumentError("empty volume spec");
  if (spec.substr(0, 4) == "raw:") return LoadRawSpec(spec, limits);
  const std::string spec_text(spec);
  if (LooksLikeGenerator(spec) && !CheckInputFile(spec_text).ok()) {
    return GenerateVolume(spec, limits);
  }

  std::string path = spec_text;
  std::string grid_name;
  // PATH.vdb#GRID: the grid name is everything after the first ".vdb#" (it may hold '#').
  const size_t vdb_hash = spec.find(".vdb#");
  if (vdb_hash != std::string_view::npos && !CheckInputFile(spec_text).ok()) {
    const size_t hash = vdb_hash + 4;
    path = spec_text.substr(0, hash);
    grid_name = spec_text.substr(hash + 1);
  }
  if (absl::EndsWithIgnoreCase(path, ".vdb")) return LoadVdbFile(spec_text, path, grid_name, limits);
  if (absl::EndsWithIgnoreCase(path, ".nii") || absl::EndsWithIgnoreCase(path, ".nii.gz")) {
    return LoadNiftiFile(spec_text, path, limits);
  }
  ISOSTREAM_RETURN_IF_ERROR(CheckInputFile(path));
  std::string generators;
  for (const char* const* g = GeneratorNames(); *g != nullptr; ++g) {
    generators += std::string(generators.empty() ? "" : ", ") + *g;
  }
  return absl::InvalidArgumentError(
      path +
      ": unrecognised volume type; expected a .vdb, .nii or .nii.gz file, "
      "raw:PATH:NXxNYxNZ:TYPE[:le|be], or a generator NAME:N (" +
      generators + ")");
}

}  // namespace

absl::StatusOr<VolumePtr> LoadVolume(std::string_view spec, const VolumeLimits& limits) {
  // The module edge: nothing thrown by OpenVDB, TBB or the standard library gets past here.
  try {
    return LoadFromSpec(spec, limits);
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError(std::string(spec) + ": out of memory while loading");
  } catch (const std::exception& e) {
    return absl::InternalError(std::string(spec) + ": " + e.what());
  } catch (...) {
    return absl::UnknownError(std::string(spec) + ": unknown exception while loading");
  }
}

}  // namespace isostream
