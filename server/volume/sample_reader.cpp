#include "server/volume/sample_reader.h"

#include <sys/stat.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "absl/strings/match.h"
#include "server/volume/grid_builder.h"
#include "shared/number_list.h"

namespace isostream {
namespace {

constexpr bool kHostBigEndian = __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__;

struct TypeInfo {
  SampleType type;
  const char* name;
  int bytes;
};
constexpr TypeInfo kTypes[] = {
    {SampleType::kUint8, "uint8", 1},     {SampleType::kInt8, "int8", 1},
    {SampleType::kUint16, "uint16", 2},   {SampleType::kInt16, "int16", 2},
    {SampleType::kUint32, "uint32", 4},   {SampleType::kInt32, "int32", 4},
    {SampleType::kFloat32, "float32", 4}, {SampleType::kFloat64, "float64", 8},
};

const TypeInfo& Info(SampleType type) { return kTypes[static_cast<int>(type)]; }

template <typename T>
T LoadSample(const unsigned char* p, bool swap) {
  unsigned char b[sizeof(T)];
  if (swap) {
    for (size_t i = 0; i < sizeof(T); ++i) b[i] = p[sizeof(T) - 1 - i];
  } else {
    std::memcpy(b, p, sizeof(T));
  }
  T v;
  std::memcpy(&v, b, sizeof(T));
  return v;
}

// A sample in single precision. Past the float range a value is infinite (and refused as such
// by the grid builder): converting it would be undefined.
inline float ToFloat(double v) {
  if (std::abs(v) <= double(std::numeric_limits<float>::max())) return static_cast<float>(v);
  if (std::isnan(v)) return std::numeric_limits<float>::quiet_NaN();
  return std::copysign(std::numeric_limits<float>::infinity(), static_cast<float>(v > 0 ? 1 : -1));
}

// One templated loop per type, chosen once per slab.
template <typename T>
void Decode(const unsigned char* in, size_t count, bool swap, double slope, double inter,
            float* out) {
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, count, 1 << 16), [&](const tbb::blocked_range<size_t>& r) {
        if (slope == 1 && inter == 0) {
          for (size_t i = r.begin(); i != r.end(); ++i) {
            const T v = LoadSample<T>(in + i * sizeof(T), swap);
            if constexpr (std::is_same_v<T, double>)
              out[i] = ToFloat(v);  // the only type whose values can pass the float range
            else
              out[i] = static_cast<float>(v);
          }
        } else {
          for (size_t i = r.begin(); i != r.end(); ++i)
            out[i] = ToFloat(static_cast<double>(LoadSample<T>(in + i * sizeof(T), swap)) * slope +
                             inter);
        }
      });
}

void DecodeSamples(const SampleLayout& layout, const unsigned char* in, size_t count, float* out) {
  const bool swap = layout.big_endian != kHostBigEndian;
  const double s = layout.slope, c = layout.inter;
  switch (layout.type) {
    case SampleType::kUint8:
      return Decode<uint8_t>(in, count, swap, s, c, out);
    case SampleType::kInt8:
      return Decode<int8_t>(in, count, swap, s, c, out);
    case SampleType::kUint16:
      return Decode<uint16_t>(in, count, swap, s, c, out);
    case SampleType::kInt16:
      return Decode<int16_t>(in, count, swap, s, c, out);
    case SampleType::kUint32:
      return Decode<uint32_t>(in, count, swap, s, c, out);
    case SampleType::kInt32:
      return Decode<int32_t>(in, count, swap, s, c, out);
    case SampleType::kFloat32:
      return Decode<float>(in, count, swap, s, c, out);
    case SampleType::kFloat64:
      return Decode<double>(in, count, swap, s, c, out);
  }
}

// zlib's message for a gzip file opened by name starts with that name, which ours already
// gives: "x.gz: corrupt data: x.gz: unexpected end of file".
std::string GzMessage(const char* message, const std::string& path) {
  if (message == nullptr) return "read error";
  std::string_view m(message);
  if (m.size() > path.size() + 2 && m.substr(0, path.size()) == path &&
      m.substr(path.size(), 2) == ": ")
    m.remove_prefix(path.size() + 2);
  return std::string(m);
}

}  // namespace

int SampleBytes(SampleType type) { return Info(type).bytes; }
const char* SampleTypeName(SampleType type) { return Info(type).name; }

bool ParseSampleType(std::string_view name, SampleType* type) {
  for (const TypeInfo& t : kTypes) {
    if (name == t.name) {
      *type = t.type;
      return true;
    }
  }
  return false;
}

absl::Status CheckInputFile(const std::string& path) {
  struct stat st;
  if (::stat(path.c_str(), &st) != 0) {
    if (errno == ENOENT || errno == ENOTDIR) return absl::NotFoundError(path + ": no such file");
    return absl::PermissionDeniedError(path + ": cannot access: " + std::strerror(errno));
  }
  if (!S_ISREG(st.st_mode)) return absl::InvalidArgumentError(path + ": not a regular file");
  if (::access(path.c_str(), R_OK) != 0) {
    return absl::PermissionDeniedError(path + ": not readable: " + std::strerror(errno));
  }
  return absl::OkStatus();
}

absl::Status CheckDims(const std::array<int64_t, 3>& dims, const VolumeLimits& limits,
                       const std::string& where) {
  const std::string text =
      std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]);
  for (int64_t d : dims) {
    if (d < 2) {
      return absl::InvalidArgumentError(where + ": dims " + text +
                                        " need at least 2 samples per axis");
    }
  }
  for (int64_t d : dims) {
    if (d > limits.max_dim) {
      return absl::ResourceExhaustedError(where + ": dims " + text + " exceed the limit of " +
                                          std::to_string(limits.max_dim) + " samples per axis");
    }
  }
  // Divide rather than multiply: dims come from untrusted headers and specs.
  if (dims[0] > limits.max_voxels / dims[1] / dims[2]) {
    return absl::ResourceExhaustedError(where + ": dims " + text + " exceed the limit of " +
                                        std::to_string(limits.max_voxels) + " samples");
  }
  return absl::OkStatus();
}

absl::Status CheckWorldBox(const std::array<int, 3>& dims, const std::array<double, 3>& spacing,
                           const std::array<double, 3>& origin, const std::string& where) {
  static const char* const kAxis[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    const double s = spacing[a], lo = origin[a], hi = lo + s * (dims[a] - 1);
    char text[96];
    if (!(s >= 1 / kMaxWorldCoordinate && s <= kMaxWorldCoordinate)) {
      // %g: std::to_string showed a spacing of 1e-35 as 0.000000 and 3e38 as 39 digits.
      std::snprintf(text, sizeof(text), "%s spacing %g", kAxis[a], s);
      return absl::InvalidArgumentError(where + ": " + text + " is outside [1e-30, 1e30]");
    }
    if (!(std::fabs(lo) <= kMaxWorldCoordinate && std::fabs(hi) <= kMaxWorldCoordinate)) {
      std::snprintf(text, sizeof(text), "%s extent [%g, %g]", kAxis[a], lo, hi);
      return absl::InvalidArgumentError(where + ": " + text + " is outside +-1e30 world units");
    }
    const double far = std::max(std::fabs(lo), std::fabs(hi));
    if (s < far * kMinCellFloatSteps * 0x1p-23) {  // a float's step at x is at most x * 2^-23
      std::snprintf(text, sizeof(text), "%s spacing %g at coordinates up to %g", kAxis[a], s, far);
      return absl::InvalidArgumentError(
          where + ": " + text + " cannot be told apart in single-precision positions (fewer than " +
          std::to_string(kMinCellFloatSteps) + " float steps per cell)");
    }
  }
  return absl::OkStatus();
}

GzInput::~GzInput() {
  if (file_ != nullptr) gzclose(file_);
  if (plain_ != nullptr) std::fclose(plain_);
}

absl::Status GzInput::Open(const std::string& path, bool plain) {
  path_ = path;
  ISOSTREAM_RETURN_IF_ERROR(CheckInputFile(path));
  struct stat st;
  if (::stat(path.c_str(), &st) == 0) disk_size_ = st.st_size;
  if (plain) {
    plain_ = std::fopen(path.c_str(), "rb");
    if (plain_ == nullptr)
      return absl::PermissionDeniedError(path + ": cannot open: " + std::strerror(errno));
    return absl::OkStatus();
  }
  file_ = gzopen(path.c_str(), "rb");
  if (file_ == nullptr) {
    return absl::PermissionDeniedError(path + ": cannot open: " + std::strerror(errno));
  }
  gzbuffer(file_, 1 << 18);  // fewer, larger reads: default 8 KiB buffers cost ~2x on big files
  return absl::OkStatus();
}

int64_t GzInput::Tell() const {
  if (plain_ != nullptr) return int64_t(std::ftell(plain_));
  return file_ != nullptr ? gztell(file_) : 0;
}

absl::StatusOr<size_t> GzInput::Read(void* out, size_t size) {
  if (plain_ != nullptr) {
    const size_t got = std::fread(out, 1, size, plain_);
    if (got < size && std::ferror(plain_))
      return absl::DataLossError(path_ + ": read error: " + std::strerror(errno));
    return got;
  }
  size_t done = 0;
  auto* bytes = static_cast<unsigned char*>(out);
  while (done < size) {
    // gzread takes an unsigned and returns an int: read in pieces well below INT_MAX.
    const unsigned piece = static_cast<unsigned>(std::min<size_t>(size - done, 1u << 30));
    const int got = gzread(file_, bytes + done, piece);
    if (got < 0) {
      int code = 0;
      const char* message = gzerror(file_, &code);
      return absl::DataLossError(path_ + ": corrupt data: " + GzMessage(message, path_));
    }
    if (got == 0) {
      int code = 0;
      const char* message = gzerror(file_, &code);
      // A gzip stream cut short reports Z_BUF_ERROR at the end instead of a clean EOF.
      if (code != Z_OK && code != Z_STREAM_END) {
        return absl::DataLossError(path_ +
                                   ": corrupt or truncated data: " + GzMessage(message, path_));
      }
      break;
    }
    done += static_cast<size_t>(got);
  }
  return done;
}

absl::Status GzInput::Skip(size_t size) {
  std::vector<unsigned char> scratch(std::min<size_t>(size, 1 << 16));
  while (size > 0) {
    const size_t piece = std::min(size, scratch.size());
    ISOSTREAM_ASSIGN_OR_RETURN(const size_t got, Read(scratch.data(), piece));
    if (got < piece) return absl::DataLossError(path_ + ": truncated before the sample data");
    size -= piece;
  }
  return absl::OkStatus();
}

int64_t GzInput::UncompressedSize() const {
  if (plain_ != nullptr) return disk_size_;
  return file_ != nullptr && gzdirect(file_) ? disk_size_ : -1;
}

absl::StatusOr<VolumePtr> ReadSamples(GzInput& input, const SampleLayout& layout, std::string name,
                                      const std::string& grid_name,
                                      const std::array<double, 3>& spacing,
                                      const std::array<double, 3>& origin,
                                      const std::atomic<bool>* stop) {
  const int bytes_per_sample = SampleBytes(layout.type);
  const int64_t expected =
      int64_t{layout.dims[0]} * layout.dims[1] * layout.dims[2] * bytes_per_sample;
  const auto truncated = [&](int64_t available) {
    return absl::DataLossError(
        input.path() + ": truncated data: " + std::to_string(layout.dims[0]) + "x" +
        std::to_string(layout.dims[1]) + "x" + std::to_string(layout.dims[2]) + " " +
        SampleTypeName(layout.type) + " samples need " + std::to_string(expected) +
        " bytes, the file has " + std::to_string(available));
  };
  // A plain file's size is known: fail before building anything.
  const int64_t disk_size = input.UncompressedSize();
  if (disk_size >= 0) {
    const int64_t start = input.Tell();
    if (disk_size - start < expected) return truncated(std::max<int64_t>(0, disk_size - start));
  }

  DenseGridBuilder builder(layout.dims);
  std::vector<unsigned char> raw(builder.SlabSamples(0) * bytes_per_sample);
  std::vector<float> slab(builder.SlabSamples(0));
  int64_t read_total = 0;
  for (int s = 0; s < builder.slab_count(); ++s) {
    if (stop != nullptr && stop->load())
      return absl::CancelledError(input.path() + ": reading stopped");
    const size_t count = builder.SlabSamples(s);
    const size_t want = count * bytes_per_sample;
    ISOSTREAM_ASSIGN_OR_RETURN(const size_t got, input.Read(raw.data(), want));
    read_total += static_cast<int64_t>(got);
    if (got < want) return truncated(read_total);
    DecodeSamples(layout, raw.data(), count, slab.data());
    absl::Status status = builder.AddSlab(s, slab.data());
    if (!status.ok()) {
      // An infinite sample may be a finite stored value the header's scaling, or its float64
      // type, took past the float range: said with it.
      const bool inf = absl::StartsWith(status.message(), "Inf sample");
      const bool scaled = inf && (layout.slope != 1 || layout.inter != 0);
      const bool wide = inf && layout.type == SampleType::kFloat64;
      return absl::Status(
          status.code(),
          input.path() + ": " + std::string(status.message()) +
              (scaled ? " (samples scaled by scl_slope " + ShortestText(float(layout.slope)) +
                            ", scl_inter " + ShortestText(float(layout.inter)) + ")"
                      : "") +
              (wide ? " (or a float64 sample past the float range, +-3.4e38, where samples are "
                      "held)"
                    : ""));
    }
  }
  return builder.Finish(std::move(name), grid_name, spacing, origin);
}

}  // namespace isostream
