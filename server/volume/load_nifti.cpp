// NIfTI-1 single-file volumes (.nii, .nii.gz), following the nifti1.h header layout of the
// NIfTI Data Format Working Group (348-byte header, magic "n+1").
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>

#include "server/volume/loaders.h"
#include "server/volume/orientation.h"
#include "server/volume/sample_reader.h"
#include "shared/number_list.h"

namespace isostream {
namespace {

constexpr int kHeaderSize = 348;

// Byte offsets of the nifti_1_header fields this loader reads.
constexpr int kDimOffset = 40;         // short dim[8]
constexpr int kDatatypeOffset = 70;    // short
constexpr int kBitpixOffset = 72;      // short
constexpr int kPixdimOffset = 76;      // float pixdim[8]
constexpr int kVoxOffsetOffset = 108;  // float
constexpr int kSclSlopeOffset = 112;   // float
constexpr int kSclInterOffset = 116;   // float
constexpr int kXyztUnitsOffset = 123;  // char: spatial units in bits 0-2
constexpr int kQformCodeOffset = 252;  // short
constexpr int kSformCodeOffset = 254;  // short
constexpr int kQuaternOffset = 256;    // float quatern_b, _c, _d
constexpr int kQoffsetOffset = 268;    // float qoffset_x, _y, _z
constexpr int kSrowOffset = 280;       // float srow_x[4], srow_y[4], srow_z[4]
constexpr int kMagicOffset = 344;      // char[4]

// NIfTI-1 datatype codes (nifti1.h DT_*).
struct NiftiType {
  int16_t code;
  SampleType type;
};
constexpr NiftiType kNiftiTypes[] = {
    {2, SampleType::kUint8}, {4, SampleType::kInt16},    {512, SampleType::kUint16},
    {8, SampleType::kInt32}, {16, SampleType::kFloat32}, {64, SampleType::kFloat64},
};

// Meters per unit of nifti1.h's spatial unit codes NIFTI_UNITS_METER, _MM and _MICRON; 0 for
// NIFTI_UNITS_UNKNOWN and the codes nifti1.h leaves undefined.
double MetersPerUnit(unsigned char xyzt_units) {
  switch (xyzt_units & 0x07) {
    case 1:
      return 1;
    case 2:
      return 1e-3;
    case 3:
      return 1e-6;
    default:
      return 0;
  }
}

class HeaderView {
 public:
  HeaderView(const unsigned char* bytes, bool swap) : bytes_(bytes), swap_(swap) {}
  int32_t I32(int offset) const { return Load<int32_t>(offset); }
  int16_t I16(int offset) const { return Load<int16_t>(offset); }
  float F32(int offset) const { return Load<float>(offset); }

 private:
  template <typename T>
  T Load(int offset) const {
    unsigned char b[sizeof(T)];
    for (size_t i = 0; i < sizeof(T); ++i) b[i] = bytes_[offset + (swap_ ? sizeof(T) - 1 - i : i)];
    T v;
    std::memcpy(&v, b, sizeof(T));
    return v;
  }
  const unsigned char* bytes_;
  bool swap_;
};

// The steps of the file's axes from pixdim (their sign belongs to the orientation). A pixdim of
// 0 is "not set" (some writers leave it so): unit spacing, as other NIfTI readers take it. One
// that is not a number, or infinite, is a damaged header: refused rather than guessed, where
// it is used (a usable sform does not use it).
absl::StatusOr<std::array<double, 3>> PixdimSteps(const HeaderView& h, const std::string& path) {
  std::array<double, 3> steps;
  for (int i = 0; i < 3; ++i) {
    const double p = std::fabs(h.F32(kPixdimOffset + 4 * (i + 1)));
    if (!std::isfinite(p))
      return absl::InvalidArgumentError(path + ": pixdim[" + std::to_string(i + 1) +
                                        "] (the voxel spacing) is not a finite number");
    steps[i] = p > 0 ? p : 1.0;
  }
  return steps;
}

// Where the samples lie in the world (nifti1.h, "3D image orientation and location"): the
// sform's matrix if it is set and usable, else the qform's rotation and offset with the pixdim
// steps (pixdim[0] < 0 reverses the third axis), else the steps alone ("method 1", ANALYZE).
// A damaged sform matrix or qform quaternion (not finite, singular) falls through to the next
// (some writers fill in only the sform's offsets); so does one whose offset is not finite, and
// the offset is then 0.
absl::StatusOr<Orientation> FileOrientation(const HeaderView& h, const std::array<int, 3>& dims,
                                            const std::string& path) {
  std::array<double, 3> offset{0, 0, 0};
  auto finite_offset = [&] {
    if (std::isfinite(offset[0]) && std::isfinite(offset[1]) && std::isfinite(offset[2]))
      return true;
    offset = {0, 0, 0};
    return false;
  };
  // Why a set sform or qform was passed over: said beside the placement (`info` shows it), as a
  // file placed by other fields than its writer meant may lie elsewhere than expected.
  std::string passed_over;
  auto pass_over = [&](const std::string& why) {
    passed_over += (passed_over.empty() ? "" : "; ") + why;
  };
  auto placed_by = [&](absl::StatusOr<Orientation> o, const char* by) {
    if (o.ok() && !passed_over.empty()) o->fallback = passed_over + "; placed by " + by;
    return o;
  };
  if (h.I16(kSformCodeOffset) > 0) {
    std::array<std::array<double, 3>, 3> srow;
    for (int r = 0; r < 3; ++r) {
      for (int i = 0; i < 3; ++i) srow[r][i] = h.F32(kSrowOffset + 16 * r + 4 * i);
      offset[r] = h.F32(kSrowOffset + 16 * r + 12);
    }
    if (finite_offset()) {
      absl::StatusOr<Orientation> o = NearestAxes(srow, offset, dims);
      if (o.ok()) return o;
      pass_over("the sform is unusable (" + std::string(o.status().message()) + ")");
    } else {
      pass_over("the sform is unusable (its offset is not a finite number)");
    }
  }
  ISOSTREAM_ASSIGN_OR_RETURN(const auto steps, PixdimSteps(h, path));
  bool qform = h.I16(kQformCodeOffset) > 0;
  if (qform) {  // its offset stands even if its rotation is damaged
    for (int r = 0; r < 3; ++r) offset[r] = h.F32(kQoffsetOffset + 4 * r);
    if (!finite_offset()) {
      pass_over("the qform is unusable (its offset is not a finite number)");
      qform = false;
    }
  }
  double b = h.F32(kQuaternOffset), c = h.F32(kQuaternOffset + 4), d = h.F32(kQuaternOffset + 8);
  const bool quaternion_finite = std::isfinite(b) && std::isfinite(c) && std::isfinite(d);
  if (qform && quaternion_finite) {
    double a2 = 1 - (b * b + c * c + d * d);
    if (a2 < 1e-7) {  // a 180-degree turn, rounded past the unit sphere: normalise (b, c, d)
      const double norm = std::sqrt(b * b + c * c + d * d);
      b /= norm, c /= norm, d /= norm;
      a2 = 0;
    }
    const double a = std::sqrt(a2);
    const double rotation[3][3] = {
        {a * a + b * b - c * c - d * d, 2 * (b * c - a * d), 2 * (b * d + a * c)},
        {2 * (b * c + a * d), a * a + c * c - b * b - d * d, 2 * (c * d - a * b)},
        {2 * (b * d - a * c), 2 * (c * d + a * b), a * a + d * d - c * c - b * b}};
    const double qfac = h.F32(kPixdimOffset) < 0 ? -1 : 1;
    std::array<std::array<double, 3>, 3> q;
    for (int r = 0; r < 3; ++r)
      for (int i = 0; i < 3; ++i) q[r][i] = rotation[r][i] * steps[i] * (i == 2 ? qfac : 1);
    absl::StatusOr<Orientation> o = NearestAxes(q, offset, dims);
    if (o.ok()) return placed_by(std::move(o), "the qform");
    pass_over("the qform is unusable (" + std::string(o.status().message()) + ")");
  } else if (qform) {
    pass_over("the qform is unusable (its quaternion is not finite)");
  }
  std::array<std::array<double, 3>, 3> diagonal{};
  for (int i = 0; i < 3; ++i) diagonal[i][i] = steps[i];
  absl::StatusOr<Orientation> o =
      placed_by(NearestAxes(diagonal, offset, dims), "pixdim's steps at the header's offset");
  if (!o.ok())  // unreachable: positive finite steps on the diagonal
    return absl::InvalidArgumentError(path + ": " + std::string(o.status().message()));
  return o;
}

}  // namespace

absl::StatusOr<VolumePtr> LoadNiftiFile(const std::string& spec, const std::string& path,
                                        const VolumeLimits& limits, const std::atomic<bool>* stop) {
  GzInput input;
  ISOSTREAM_RETURN_IF_ERROR(input.Open(path));
  unsigned char bytes[kHeaderSize];
  ISOSTREAM_ASSIGN_OR_RETURN(const size_t got, input.Read(bytes, kHeaderSize));
  // sizeof_hdr is 348 in the writer's byte order, which tells us the file's endianness.
  const HeaderView native(bytes, false), swapped(bytes, true);
  const bool starts_like_nifti =
      got >= 4 && (native.I32(0) == kHeaderSize || swapped.I32(0) == kHeaderSize);
  if (!starts_like_nifti) {
    return absl::InvalidArgumentError(
        path + ": not a NIfTI-1 file (sizeof_hdr is " +
        (got >= 4 ? std::to_string(native.I32(0)) : std::string("missing")) + ", expected 348)");
  }
  if (got < kHeaderSize) {
    return absl::DataLossError(path + ": truncated NIfTI-1 header (" + std::to_string(got) +
                               " of 348 bytes)");
  }
  const bool swap = native.I32(0) != kHeaderSize;
  const HeaderView h(bytes, swap);
  if (std::memcmp(bytes + kMagicOffset, "ni1\0", 4) == 0) {
    return absl::InvalidArgumentError(path +
                                      ": NIfTI-1 header/image pair (.hdr/.img) is not supported; "
                                      "convert to a single .nii file");
  }
  if (std::memcmp(bytes + kMagicOffset, "n+1\0", 4) != 0) {
    return absl::InvalidArgumentError(path + ": not a NIfTI-1 file (magic is not \"n+1\")");
  }

  int16_t dim[8];
  for (int i = 0; i < 8; ++i) dim[i] = h.I16(kDimOffset + 2 * i);
  // Three dimensions, or more of which those past the third are 1 (a single time point or
  // component, as some writers store a 3D volume).
  bool three_d = dim[0] >= 3 && dim[0] <= 7;
  for (int i = 4; three_d && i <= dim[0]; ++i) three_d = dim[i] == 1;
  if (!three_d) {
    std::string dims = std::to_string(dim[0]);
    for (int i = 1; i <= std::clamp<int>(dim[0], 0, 7); ++i) dims += ", " + std::to_string(dim[i]);
    return absl::InvalidArgumentError(path + ": not a 3D volume (dim = " + dims + ")");
  }
  ISOSTREAM_RETURN_IF_ERROR(CheckDims({dim[1], dim[2], dim[3]}, limits, path));

  const int16_t datatype = h.I16(kDatatypeOffset);
  SampleLayout layout;
  bool known_type = false;
  for (const NiftiType& t : kNiftiTypes) {
    if (t.code == datatype) {
      layout.type = t.type;
      known_type = true;
    }
  }
  if (!known_type) {
    return absl::InvalidArgumentError(
        path + ": unsupported NIfTI datatype " + std::to_string(datatype) +
        " (supported: uint8, int16, uint16, int32, float32, float64)");
  }
  const int16_t bitpix = h.I16(kBitpixOffset);
  if (bitpix != 8 * SampleBytes(layout.type)) {
    return absl::InvalidArgumentError(path + ": bitpix " + std::to_string(bitpix) +
                                      " does not match datatype " + SampleTypeName(layout.type));
  }
  layout.dims = {dim[1], dim[2], dim[3]};
  layout.big_endian = swap != (__BYTE_ORDER__ == __ORDER_BIG_ENDIAN__);

  // nifti1.h: scaling applies only when scl_slope is nonzero (a NaN one, as some writers leave
  // it, is none too). Applied, an infinite slope or an intercept that is not a finite number
  // would make every sample so: a damaged header.
  const float slope = h.F32(kSclSlopeOffset), inter = h.F32(kSclInterOffset);
  if (slope != 0 && !std::isnan(slope)) {
    if (!std::isfinite(slope) || !std::isfinite(inter))
      return absl::InvalidArgumentError(path + ": scl_slope " + ShortestText(slope) +
                                        " and scl_inter " + ShortestText(inter) +
                                        " do not scale samples to numbers");
    layout.slope = slope;
    layout.inter = inter;
  }

  ISOSTREAM_ASSIGN_OR_RETURN(const Orientation orientation, FileOrientation(h, layout.dims, path));
  // The samples are read as stored, with the file's axes' steps, then turned onto the world's.
  std::array<double, 3> file_spacing;
  for (int a = 0; a < 3; ++a) file_spacing[orientation.source[a]] = orientation.spacing[a];
  ISOSTREAM_RETURN_IF_ERROR(
      CheckWorldBox(orientation.dims, orientation.spacing, orientation.origin, path));

  float vox_offset = h.F32(kVoxOffsetOffset);
  if (!(vox_offset >= 0) || vox_offset > 1e9f) {
    return absl::InvalidArgumentError(
        path + ": vox_offset " + ShortestText(vox_offset) +
        (vox_offset > 1e9f ? " is past any file this loader reads" : " is not a byte offset"));
  }
  // A .nii's data follow the header and its 4 extension bytes at least: nifti1_io reads a
  // smaller vox_offset as 352 (read as given, 348-351 took the samples from those bytes).
  vox_offset = std::max(vox_offset, float(kHeaderSize + 4));
  ISOSTREAM_RETURN_IF_ERROR(input.Skip(static_cast<size_t>(vox_offset) - kHeaderSize));

  std::string grid_name = path.substr(path.find_last_of('/') + 1);
  ISOSTREAM_ASSIGN_OR_RETURN(VolumePtr stored, ReadSamples(input, layout, spec, grid_name,
                                                           file_spacing, orientation.origin, stop));
  if (const double meters = MetersPerUnit(bytes[kXyztUnitsOffset]); meters > 0) {
    auto with_units = std::make_shared<Volume>(*stored);  // shares the grid
    with_units->meters_per_unit = meters;
    stored = std::move(with_units);
  }
  if (orientation.Describe().empty()) return stored;
  return Reorient(std::move(stored), orientation);
}

}  // namespace isostream
