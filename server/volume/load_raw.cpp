// Raw sample files: no header, everything comes from the spec raw:PATH:NXxNYxNZ:TYPE[:le|be].
#include <string>

#include "absl/strings/match.h"
#include "server/volume/loaders.h"
#include "server/volume/sample_reader.h"

namespace isostream {

absl::StatusOr<VolumePtr> LoadRawFile(const VolumeSpec& spec, const std::atomic<bool>* stop) {
  SampleLayout layout;
  ParseSampleType(spec.sample_type, &layout.type);  // ParseVolumeSpec took only known types
  layout.big_endian = spec.big_endian;
  layout.dims = spec.dims;
  const std::string& path = spec.path;
  // How the messages name the layout; ParseVolumeSpec has checked the dims against the limits.
  const std::string described = std::to_string(spec.dims[0]) + "x" + std::to_string(spec.dims[1]) +
                                "x" + std::to_string(spec.dims[2]) + " " + spec.sample_type;

  // Compressed only when named so: samples are any bytes, and a plain file whose first two
  // are gzip's magic was refused as corrupt gzip.
  GzInput input;
  ISOSTREAM_RETURN_IF_ERROR(input.Open(path, !absl::EndsWithIgnoreCase(path, ".gz")));
  const int64_t expected =
      int64_t{spec.dims[0]} * spec.dims[1] * spec.dims[2] * SampleBytes(layout.type);
  // More bytes than the spec describes almost always means wrong dims or type, which would load
  // as plausible-looking garbage: refuse rather than guess.
  const int64_t disk_size = input.UncompressedSize();
  if (disk_size > expected) {
    return absl::InvalidArgumentError(path + ": file has " + std::to_string(disk_size) +
                                      " bytes but " + described + " samples need " +
                                      std::to_string(expected));
  }
  std::string grid_name = path.substr(path.find_last_of('/') + 1);
  ISOSTREAM_RETURN_IF_ERROR(CheckWorldBox(spec.dims, {1, 1, 1}, {0, 0, 0}, path));
  ISOSTREAM_ASSIGN_OR_RETURN(VolumePtr volume, ReadSamples(input, layout, spec.text, grid_name,
                                                           {1, 1, 1}, {0, 0, 0}, stop));
  // A compressed file's size is known only once read: the same refusal, after the fact.
  unsigned char extra;
  ISOSTREAM_ASSIGN_OR_RETURN(const size_t more, input.Read(&extra, 1));
  if (more != 0) {
    return absl::InvalidArgumentError(path + ": file has more than the " +
                                      std::to_string(expected) + " bytes that " + described +
                                      " samples need");
  }
  return volume;
}

}  // namespace isostream
