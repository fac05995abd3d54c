// Raw sample files: no header, everything comes from the spec raw:PATH:NXxNYxNZ:TYPE[:le|be].
#include <charconv>
#include <string>
#include <vector>

#include "server/volume/loaders.h"
#include "server/volume/sample_reader.h"

namespace isostream {
namespace {

bool ParseDim(std::string_view s, int64_t* out) {
  if (s.empty()) return false;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), *out);
  return ec == std::errc() && end == s.data() + s.size();
}

}  // namespace

absl::StatusOr<VolumePtr> LoadRawSpec(std::string_view spec, const VolumeLimits& limits) {
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
  SampleType ignored;
  const bool order_given = last == "le" || last == "be" || ParseSampleType(before_last, &ignored);
  std::string_view type_name = last, dims_text = before_last;
  if (order_given) {
    if (last != "le" && last != "be") {
      return malformed("byte order '" + std::string(last) + "' is not le or be");
    }
    type_name = before_last;
    if (!pop(&dims_text)) return malformed("missing fields");
  }
  const bool big_endian = last == "be";
  const std::string path(rest);
  if (path.empty()) return malformed("empty PATH");

  std::array<int64_t, 3> dims{};
  {
    std::string_view d = dims_text;
    for (int axis = 0; axis < 3; ++axis) {
      const size_t x = axis < 2 ? d.find('x') : d.size();
      if (x == std::string_view::npos || !ParseDim(d.substr(0, x), &dims[axis])) {
        return malformed("dims '" + std::string(dims_text) + "' are not NXxNYxNZ");
      }
      d = axis < 2 ? d.substr(x + 1) : d.substr(d.size());
    }
  }
  SampleLayout layout;
  if (!ParseSampleType(type_name, &layout.type)) {
    return absl::InvalidArgumentError(
        "raw spec '" + spec_text + "': unsupported type '" + std::string(type_name) +
        "' (supported: uint8 int8 uint16 int16 uint32 int32 float32 float64)");
  }
  layout.big_endian = big_endian;
  ISOSTREAM_RETURN_IF_ERROR(CheckDims(dims, limits, path));
  layout.dims = {static_cast<int>(dims[0]), static_cast<int>(dims[1]), static_cast<int>(dims[2])};

  GzInput input;
  ISOSTREAM_RETURN_IF_ERROR(input.Open(path));
  const int64_t expected = dims[0] * dims[1] * dims[2] * SampleBytes(layout.type);
  // More bytes than the spec describes almost always means wrong dims or type, which would load
  // as plausible-looking garbage: refuse rather than guess.
  const int64_t disk_size = input.UncompressedSize();
  if (disk_size > expected) {
    return absl::InvalidArgumentError(
        path + ": file has " + std::to_string(disk_size) + " bytes but " + std::string(dims_text) +
        " " + std::string(type_name) + " samples need " + std::to_string(expected));
  }
  std::string grid_name = path.substr(path.find_last_of('/') + 1);
  ISOSTREAM_ASSIGN_OR_RETURN(
      VolumePtr volume, ReadSamples(input, layout, spec_text, grid_name, {1, 1, 1}, {0, 0, 0}));
  // A compressed file's size is known only once read: the same refusal, after the fact.
  unsigned char extra;
  ISOSTREAM_ASSIGN_OR_RETURN(const size_t more, input.Read(&extra, 1));
  if (more != 0) {
    return absl::InvalidArgumentError(
        path + ": file has more than the " + std::to_string(expected) + " bytes that " +
        std::string(dims_text) + " " + std::string(type_name) + " samples need");
  }
  return volume;
}

}  // namespace isostream
