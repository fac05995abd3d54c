#include "client/render/image.h"

#include <absl/strings/match.h>
#include <absl/strings/str_cat.h>
#include <png.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "shared/file_io.h"

namespace isostream::render {

std::string NumberedPngPath(const std::string& path, int index, int count) {
  const size_t slash = path.find_last_of('/');
  const size_t dot = path.find_last_of('.');
  const bool has_extension =
      dot != std::string::npos && (slash == std::string::npos || dot > slash);
  const std::string stem = has_extension ? path.substr(0, dot) : path;
  const std::string extension = has_extension ? path.substr(dot) : ".png";
  // As many digits as the last index needs (at least 3): out_999.png sorted after out_1000.png.
  int digits = 3;
  for (int last = std::max(count - 1, 0) / 1000; last > 0; last /= 10) ++digits;
  char number[24];
  std::snprintf(number, sizeof(number), "_%0*d", digits, index);
  return stem + number + extension;
}

absl::Status CheckPngOutputs(const std::string& path, int orbit) {
  if (!absl::EndsWithIgnoreCase(path, ".png"))
    return absl::InvalidArgumentError("-o writes a PNG image: give a .png path, got '" + path +
                                      "'");
  for (int i = 0; i < std::max(1, orbit); ++i)
    ISOSTREAM_RETURN_IF_ERROR(CheckOutputPath(orbit > 0 ? NumberedPngPath(path, i, orbit) : path));
  return absl::OkStatus();
}
namespace {

// Larger images are refused before allocating, so that a small malicious header cannot make
// the decoder reserve gigabytes.
constexpr uint64_t kMaxDecodedPixels = uint64_t(1) << 28;

png_image EmptyPngImage() {
  png_image image;
  std::memset(&image, 0, sizeof(image));
  image.version = PNG_IMAGE_VERSION;
  return image;
}

}  // namespace

// libpng's simplified API reports errors through png_image::message instead of longjmp, which
// keeps C++ destructors out of setjmp/longjmp territory.
absl::Status EncodePng(const Image& image, std::string* out) {
  if (image.width <= 0 || image.height <= 0 ||
      image.rgba.size() != 4 * size_t(image.width) * size_t(image.height)) {
    return absl::InvalidArgumentError(absl::StrCat("EncodePng: image is ", image.width, "x",
                                                   image.height, " but holds ", image.rgba.size(),
                                                   " bytes"));
  }
  png_image png = EmptyPngImage();
  png.width = png_uint_32(image.width);
  png.height = png_uint_32(image.height);
  png.format = PNG_FORMAT_RGBA;
  png_alloc_size_t size = 0;
  if (!png_image_write_to_memory(&png, nullptr, &size, 0, image.rgba.data(), 0, nullptr)) {
    return absl::InternalError(absl::StrCat("EncodePng: libpng: ", png.message));
  }
  out->resize(size);
  if (!png_image_write_to_memory(&png, out->data(), &size, 0, image.rgba.data(), 0, nullptr)) {
    return absl::InternalError(absl::StrCat("EncodePng: libpng: ", png.message));
  }
  out->resize(size);
  return absl::OkStatus();
}

absl::Status WritePng(const Image& image, const std::string& path) {
  std::string bytes;
  ISOSTREAM_RETURN_IF_ERROR(PrefixStatus(path, EncodePng(image, &bytes)));
  return WriteFileBytes(path, bytes);
}

absl::StatusOr<Image> DecodePng(std::string_view bytes) {
  png_image png = EmptyPngImage();
  if (!png_image_begin_read_from_memory(&png, bytes.data(), bytes.size())) {
    return absl::InvalidArgumentError(absl::StrCat("not a PNG: ", png.message));
  }
  if (uint64_t(png.width) * png.height > kMaxDecodedPixels) {
    png_image_free(&png);
    return absl::InvalidArgumentError(
        absl::StrCat("PNG is ", png.width, "x", png.height, ", more pixels than accepted"));
  }
  png.format = PNG_FORMAT_RGBA;
  Image image;
  image.width = int(png.width);
  image.height = int(png.height);
  image.rgba.resize(PNG_IMAGE_SIZE(png));
  if (!png_image_finish_read(&png, nullptr, image.rgba.data(), 0, nullptr)) {
    return absl::InvalidArgumentError(absl::StrCat("corrupt PNG: ", png.message));
  }
  return image;
}

absl::StatusOr<Image> ReadPng(const std::string& path) {
  ISOSTREAM_ASSIGN_OR_RETURN(std::string bytes, ReadFileBytes(path));
  absl::StatusOr<Image> image = DecodePng(bytes);
  if (!image.ok()) return PrefixStatus(path, image.status());
  return image;
}

double MeanAbsoluteDifference(const Image& a, const Image& b) {
  if (a.width != b.width || a.height != b.height || a.rgba.size() != b.rgba.size()) return -1.0;
  if (a.rgba.empty()) return 0.0;
  uint64_t sum = 0;
  for (size_t i = 0; i < a.rgba.size(); i += 4) {
    for (size_t c = 0; c < 3; ++c)
      sum += uint64_t(std::abs(int(a.rgba[i + c]) - int(b.rgba[i + c])));
  }
  const double samples = 3.0 * double(a.rgba.size() / 4);
  return double(sum) / (255.0 * samples);
}

}  // namespace isostream::render
