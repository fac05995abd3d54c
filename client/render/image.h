// 8-bit RGBA images as the renderer reads them back, and PNG files through libpng. Rows are
// stored top row first (the PNG and screen convention, not OpenGL's bottom-up readback order).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "shared/status.h"

namespace isostream::render {

struct Image {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> rgba;  // 4 bytes per pixel, rows top to bottom, no padding

  const uint8_t* pixel(int x, int y) const { return rgba.data() + 4 * (size_t(y) * width + x); }
  uint8_t* pixel(int x, int y) { return rgba.data() + 4 * (size_t(y) * width + x); }
};

// Encodes `image` as an 8-bit RGBA PNG into `out` (replacing its contents). InvalidArgument when
// the size does not match rgba.size() or is not positive; Internal if libpng refuses.
absl::Status EncodePng(const Image& image, std::string* out);

// EncodePng to the file at `path` (created or truncated); I/O failures name the path.
absl::Status WritePng(const Image& image, const std::string& path);

// The file an image command writes for -o `path` and view `index` of an orbit of `count` views:
// the number goes before the extension (out.png -> out_007.png), with as many digits as the
// orbit's last view needs (at least 3), so an orbit's frames sort in order.
std::string NumberedPngPath(const std::string& path, int index, int count);

// Checks, before any work, that -o `path` names PNG files the command can write: the path
// itself, or with an orbit of `orbit` views (0: none) each numbered file. InvalidArgument for
// a path not ending in .png (another extension would name a file holding something else);
// CheckOutputPath's status for a file it could not write.
absl::Status CheckPngOutputs(const std::string& path, int orbit);

// Decodes PNG bytes of any colour type and bit depth into 8-bit RGBA (grey is replicated, a
// missing alpha channel becomes 255). InvalidArgument, with libpng's reason, for bytes that are
// not a complete, valid PNG: wrong signature, bad CRC, truncated data.
absl::StatusOr<Image> DecodePng(std::string_view bytes);

// DecodePng on the contents of the file at `path`; NotFound if it does not exist. Messages are
// prefixed with the path.
absl::StatusOr<Image> ReadPng(const std::string& path);

// Mean over all pixels and the R, G, B channels of |a - b|, as a fraction of the full range
// (0 = identical, 1 = black against white everywhere). Alpha is ignored because rendered
// frames are opaque. Returns a negative value when the sizes differ.
double MeanAbsoluteDifference(const Image& a, const Image& b);

}  // namespace isostream::render
