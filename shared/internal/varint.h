// Internal to shared/: LEB128 varints of 32-bit values (7 bits a byte, low first, the high bit
// set on every byte but the last), as Draco writes its header counts and as the rANS symbol
// stream writes its sizes and frequencies. One implementation, so the bounds checks that keep
// hostile input from reading past a buffer are written once.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace isostream::internal {

// The longest encoding of a uint32: ceil(32 / 7) bytes.
inline constexpr size_t kMaxVarint32Bytes = 5;

// Appends v in the fewest bytes (1..5).
inline void PutVarint32(uint32_t v, std::string* out) {
  while (v >= 0x80) {
    out->push_back(static_cast<char>(v | 0x80));
    v >>= 7;
  }
  out->push_back(static_cast<char>(v));
}

// Reads one varint from data[*at, size) into *value and advances *at past it. False, with *at
// and *value unchanged, if the bytes end before the varint does, if it runs longer than 5
// bytes, or if its value does not fit in 32 bits (bits above 2^32 in the 5th byte). Reads no
// byte at or past `size`. Encodings padded with zero groups (0x80 0x00 for 0) are accepted, as
// Draco's own decoder accepts them.
inline bool GetVarint32(const uint8_t* data, size_t size, size_t* at, uint32_t* value) {
  uint64_t v = 0;
  size_t i = *at;
  for (size_t n = 0; n < kMaxVarint32Bytes; ++n) {
    if (i >= size) return false;
    const uint8_t byte = data[i++];
    v |= uint64_t{byte & 0x7fu} << (7 * n);
    if (!(byte & 0x80)) {
      if (v > 0xffffffffu) return false;
      *value = static_cast<uint32_t>(v);
      *at = i;
      return true;
    }
  }
  return false;
}

}  // namespace isostream::internal
