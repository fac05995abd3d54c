// Private to server/volume: what the file loaders share. Reading through zlib (which reads plain
// files unchanged), decoding typed samples of either byte order into floats, and the checks every
// source makes before it allocates.
#pragma once

#include <zlib.h>

#include <array>
#include <atomic>
#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>

#include "server/volume/volume.h"
#include "shared/status.h"

namespace isostream {

enum class SampleType { kUint8, kInt8, kUint16, kInt16, kUint32, kInt32, kFloat32, kFloat64 };

int SampleBytes(SampleType type);
const char* SampleTypeName(SampleType type);
bool ParseSampleType(std::string_view name, SampleType* type);

// NotFound when PATH does not exist, InvalidArgument when it is not a regular file,
// PermissionDenied when it cannot be read. Messages start with PATH.
absl::Status CheckInputFile(const std::string& path);

// InvalidArgument for dims < 2, ResourceExhausted beyond LIMITS; messages start with WHERE.
absl::Status CheckDims(const std::array<int64_t, 3>& dims, const VolumeLimits& limits,
                       const std::string& where);

// InvalidArgument unless the world box of DIMS samples at SPACING from ORIGIN lies within
// +-kMaxWorldCoordinate and every spacing within [1 / kMaxWorldCoordinate, kMaxWorldCoordinate]:
// mesh positions are single precision, and a box past that range would overflow them (or the
// view placed around it) downstream. Also InvalidArgument where a cell spans fewer than
// kMinCellFloatSteps floats at the box's largest coordinate (an origin of 1e17 with unit
// spacing put every vertex at the same position): geodetic coordinates, ~6e6 m at 12.5 m
// spacing, keep ~25. Messages start with WHERE.
inline constexpr double kMaxWorldCoordinate = 1e30;
inline constexpr int kMinCellFloatSteps = 8;
absl::Status CheckWorldBox(const std::array<int, 3>& dims, const std::array<double, 3>& spacing,
                           const std::array<double, 3>& origin, const std::string& where);

// A file read through zlib's gz* functions (gzip or plain, told by its content), or plainly;
// closed on destruction.
class GzInput {
 public:
  GzInput() = default;
  ~GzInput();
  GzInput(const GzInput&) = delete;
  GzInput& operator=(const GzInput&) = delete;

  // `plain`: read the bytes as they are, even if they start as gzip does (a raw file's first
  // sample can: 1f 8b is the first two bytes of 1 float in 65536).
  absl::Status Open(const std::string& path, bool plain = false);
  // Reads up to SIZE bytes; fewer only at the end of the data. DataLoss on a corrupt stream.
  absl::StatusOr<size_t> Read(void* out, size_t size);
  absl::Status Skip(size_t size);  // DataLoss if the data ends first
  // Bytes on disk when the file is not compressed (known only after the first read), else -1.
  int64_t UncompressedSize() const;
  int64_t Tell() const;  // uncompressed offset
  const std::string& path() const { return path_; }

 private:
  gzFile file_ = nullptr;
  std::FILE* plain_ = nullptr;  // instead of file_
  std::string path_;
  int64_t disk_size_ = -1;
};

struct SampleLayout {
  std::array<int, 3> dims{0, 0, 0};  // x fastest
  SampleType type = SampleType::kFloat32;
  bool big_endian = false;
  double slope = 1;  // value = stored * slope + inter
  double inter = 0;
};

// Reads the samples of LAYOUT from INPUT (positioned at the first sample) into a volume named
// NAME, slab by slab so only the grid and one slab are in memory. DataLoss when the data ends
// early, InvalidArgument naming the first NaN/Inf sample, Cancelled between slabs once `stop`
// (may be null) is set. Messages start with INPUT's path. The caller checks the world box
// (CheckWorldBox) first: only it knows the world's axes (orientation.h).
absl::StatusOr<VolumePtr> ReadSamples(GzInput& input, const SampleLayout& layout, std::string name,
                                      const std::string& grid_name,
                                      const std::array<double, 3>& spacing,
                                      const std::array<double, 3>& origin,
                                      const std::atomic<bool>* stop = nullptr);

}  // namespace isostream
