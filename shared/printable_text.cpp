#include "shared/printable_text.h"

#include <algorithm>
#include <cstdint>

namespace isostream {
namespace {

// Length of the UTF-8 sequence starting at text[i] if it is a well-formed one (no overlong
// forms, no surrogates, at most U+10FFFF), else 0.
size_t Utf8Length(std::string_view text, size_t i) {
  const auto byte = [&](size_t k) { return uint8_t(text[k]); };
  const uint8_t lead = byte(i);
  size_t length;
  uint32_t code;
  if (lead >= 0xc2 && lead <= 0xdf) {
    length = 2, code = lead & 0x1f;
  } else if (lead >= 0xe0 && lead <= 0xef) {
    length = 3, code = lead & 0x0f;
  } else if (lead >= 0xf0 && lead <= 0xf4) {
    length = 4, code = lead & 0x07;
  } else {
    return 0;
  }
  if (i + length > text.size()) return 0;
  for (size_t k = 1; k < length; ++k) {
    if ((byte(i + k) & 0xc0) != 0x80) return 0;
    code = code << 6 | (byte(i + k) & 0x3f);
  }
  const uint32_t least[5] = {0, 0, 0x80, 0x800, 0x10000};
  if (code < least[length] || code > 0x10ffff || (code >= 0xd800 && code <= 0xdfff)) return 0;
  return length;
}

}  // namespace

std::string PrintableText(std::string_view text, size_t max_bytes) {
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out;
  out.reserve(std::min(text.size(), max_bytes) + 8);
  for (size_t i = 0; i < text.size();) {
    const uint8_t c = uint8_t(text[i]);
    std::string piece;
    size_t used = 1;
    if (c >= 0x20 && c < 0x7f) {
      piece = c == '\\' ? "\\\\" : std::string(1, char(c));
    } else if (const size_t n = c >= 0x80 ? Utf8Length(text, i) : 0;
               n > 0 && !(n == 2 && c == 0xc2 && uint8_t(text[i + 1]) < 0xa0)) {
      piece = std::string(text.substr(i, n));  // C1 controls (U+0080-U+009F) are escaped
      used = n;
    } else {
      piece = {'\\', 'x', kHex[c >> 4], kHex[c & 15]};
    }
    if (out.size() + piece.size() > max_bytes) {
      out += "...";
      break;
    }
    out += piece;
    i += used;
  }
  return out;
}

}  // namespace isostream
