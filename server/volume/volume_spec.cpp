#include "server/volume/volume_spec.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <vector>

#include "absl/strings/match.h"
#include "server/volume/generators.h"
#include "server/volume/load.h"
#include "server/volume/sample_reader.h"

namespace isostream {
namespace {

bool ParseInt64(std::string_view s, int64_t* out) {
  if (s.empty()) return false;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), *out);
  return ec == std::errc() && end == s.data() + s.size();
}

std::string KnownGenerators() {
  std::string known;
  for (const char* const* g = GeneratorNames(); *g != nullptr; ++g)
    known += std::string(known.empty() ? "" : ", ") + *g;
  return known;
}

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

// Where ".vdb#" (any case, as the extension) first occurs in spec, or npos.
size_t FindVdbHash(std::string_view spec) {
  for (size_t at = spec.find('#'); at != std::string_view::npos; at = spec.find('#', at + 1))
    if (at >= 4 && absl::EqualsIgnoreCase(absl::string_view(spec.data() + at - 4, 4), ".vdb"))
      return at - 4;
  return std::string_view::npos;
}

// Ends with a volume file's extension, or holds ".vdb#" (a grid named after the file).
bool NamesVolumeFile(std::string_view spec) {
  const absl::string_view s(spec.data(), spec.size());
  return absl::EndsWithIgnoreCase(s, ".vdb") || absl::EndsWithIgnoreCase(s, ".nii") ||
         absl::EndsWithIgnoreCase(s, ".nii.gz") || FindVdbHash(spec) != std::string_view::npos;
}

// NAME:N[:SEED].
absl::Status ParseGenerator(std::string_view spec, const VolumeLimits& limits, VolumeSpec* out) {
  std::vector<std::string_view> parts;
  for (size_t start = 0;;) {
    const size_t colon = spec.find(':', start);
    parts.push_back(spec.substr(start, colon == std::string_view::npos ? colon : colon - start));
    if (colon == std::string_view::npos) break;
    start = colon + 1;
  }
  const std::string_view name = parts[0];
  const std::string where = "generator spec '" + std::string(spec) + "'";
  const char* const* g = GeneratorNames();
  while (*g != nullptr && name != *g) ++g;
  if (*g == nullptr) {
    return absl::NotFoundError(where + ": unknown generator '" + std::string(name) +
                               "' (known: " + KnownGenerators() + ")");
  }
  const size_t max_parts = name == "noise" ? 3 : 2;
  if (parts.size() < 2 || parts.size() > max_parts) {
    return absl::InvalidArgumentError(where + ": expected " + std::string(name) +
                                      (name == "noise" ? ":N[:SEED]" : ":N"));
  }
  int64_t n = 0;
  if (!ParseInt64(parts[1], &n)) {
    return absl::InvalidArgumentError(where + ": N '" + std::string(parts[1]) +
                                      "' is not an integer");
  }
  ISOSTREAM_RETURN_IF_ERROR(CheckDims({n, n, n}, limits, where));
  int64_t seed = kNoiseDefaultSeed;
  if (parts.size() == 3 && (!ParseInt64(parts[2], &seed) || seed < 0 || seed > UINT32_MAX)) {
    return absl::InvalidArgumentError(where + ": SEED '" + std::string(parts[2]) +
                                      "' is not an integer in [0, 2^32)");
  }
  out->source = VolumeSource::kGenerator;
  out->generator = std::string(name);
  out->n = static_cast<int>(n);
  out->seed = static_cast<uint32_t>(seed);
  return absl::OkStatus();
}

// raw:PATH:NXxNYxNZ:TYPE[:le|be].
absl::Status ParseRaw(std::string_view spec, const VolumeLimits& limits, VolumeSpec* out) {
  const std::string spec_text(spec);
  const auto malformed = [&](const std::string& why) {
    return absl::InvalidArgumentError("raw spec '" + spec_text + "': " + why +
                                      " (expected raw:PATH:NXxNYxNZ:TYPE[:le|be])");
  };
  // Peel fields off the right (byte order if present, TYPE, DIMS) so PATH may contain ':'.
  std::string_view rest = spec.substr(4);
  const auto pop = [&rest](std::string_view* field) {
    const size_t colon = rest.rfind(':');
    if (colon == std::string_view::npos) return false;
    *field = rest.substr(colon + 1);
    rest = rest.substr(0, colon);
    return true;
  };
  std::string_view last, before_last;
  if (!pop(&last) || !pop(&before_last)) return malformed("missing fields");
  // Four fields when the last names a byte order, or when the one before it names a type (the
  // last is then a wrong byte order, not a wrong type).
  SampleType type;
  const bool order_given = last == "le" || last == "be" || ParseSampleType(before_last, &type);
  std::string_view type_name = last, dims_text = before_last;
  if (order_given) {
    if (last != "le" && last != "be") {
      return malformed("byte order '" + std::string(last) + "' is not le or be");
    }
    type_name = before_last;
    if (!pop(&dims_text)) return malformed("missing fields");
  }
  const std::string path(rest);
  if (path.empty()) return malformed("empty PATH");

  std::array<int64_t, 3> dims{};
  {
    std::string_view d = dims_text;
    for (int axis = 0; axis < 3; ++axis) {
      const size_t x = axis < 2 ? d.find('x') : d.size();
      if (x == std::string_view::npos || !ParseInt64(d.substr(0, x), &dims[axis])) {
        return malformed("dims '" + std::string(dims_text) + "' are not NXxNYxNZ");
      }
      d = axis < 2 ? d.substr(x + 1) : d.substr(d.size());
    }
  }
  if (!ParseSampleType(type_name, &type)) {
    return absl::InvalidArgumentError(
        "raw spec '" + spec_text + "': unsupported type '" + std::string(type_name) +
        "' (supported: uint8 int8 uint16 int16 uint32 int32 float32 float64)");
  }
  ISOSTREAM_RETURN_IF_ERROR(CheckDims(dims, limits, path));
  out->source = VolumeSource::kRawFile;
  out->path = path;
  out->dims = {static_cast<int>(dims[0]), static_cast<int>(dims[1]), static_cast<int>(dims[2])};
  out->sample_type = std::string(type_name);
  out->big_endian = last == "be";
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<VolumeSpec> ParseVolumeSpec(std::string_view spec, const VolumeLimits& limits) {
  if (spec.empty()) return absl::InvalidArgumentError("empty volume spec");
  VolumeSpec out;
  out.text = std::string(spec);
  if (spec.substr(0, 4) == "raw:") {
    ISOSTREAM_RETURN_IF_ERROR(ParseRaw(spec, limits, &out));
    return out;
  }
  // "word:..." naming a volume file ("scan:2024.nii.gz", "a:b.vdb#grid") is a file, found or
  // not (a missing one was called an unknown generator, a usage error); other "word:..." specs
  // are generators, whatever files exist (one named "cayley:9" has no type a loader reads, and
  // made the generator spec "cayley:9" an unrecognised volume type).
  if (LooksLikeGenerator(spec) && !NamesVolumeFile(spec)) {
    ISOSTREAM_RETURN_IF_ERROR(ParseGenerator(spec, limits, &out));
    return out;
  }
  out.path = out.text;
  // PATH.vdb#GRID: the grid name is everything after the first ".vdb#" (it may hold '#'),
  // unless a file has the whole name: it is read whole then.
  const size_t vdb_hash = FindVdbHash(spec);
  if (vdb_hash != std::string_view::npos && !CheckInputFile(out.text).ok()) {
    const size_t hash = vdb_hash + 4;
    out.path = out.text.substr(0, hash);
    out.grid_name = out.text.substr(hash + 1);
  }
  if (absl::EndsWithIgnoreCase(out.path, ".vdb")) {
    out.source = VolumeSource::kVdbFile;
    return out;
  }
  if (absl::EndsWithIgnoreCase(out.path, ".nii") || absl::EndsWithIgnoreCase(out.path, ".nii.gz")) {
    out.source = VolumeSource::kNiftiFile;
    return out;
  }
  // Refused whether the file exists or not: no loader would read it either way ("buckyball"
  // without its N was reported as a missing file).
  return absl::InvalidArgumentError(
      out.path +
      ": unrecognised volume type; expected a .vdb, .nii or .nii.gz file, "
      "raw:PATH:NXxNYxNZ:TYPE[:le|be], or a generator NAME:N (" +
      KnownGenerators() + ")");
}

}  // namespace isostream
