#include "shared/internal/symbol_stream.h"

#include <draco/compression/entropy/symbol_decoding.h>
#include <draco/compression/entropy/symbol_encoding.h>
#include <draco/core/decoder_buffer.h>
#include <draco/core/encoder_buffer.h>

#include <limits>

namespace isostream::internal {

bool AppendSymbols(const uint32_t* symbols, size_t count, int components, std::string* out) {
  if (count > size_t{std::numeric_limits<int>::max()}) return false;
  draco::EncoderBuffer buffer;
  // Draco's default compression level; higher levels change nothing on these alphabets.
  if (!draco::EncodeSymbols(symbols, static_cast<int>(count), components, nullptr, &buffer)) {
    return false;
  }
  out->append(buffer.data(), buffer.size());
  return true;
}

bool ReadSymbols(draco::DecoderBuffer* buffer, size_t count, int components, uint32_t* symbols) {
  if (count > std::numeric_limits<uint32_t>::max()) return false;
  return draco::DecodeSymbols(static_cast<uint32_t>(count), components, buffer, symbols);
}

}  // namespace isostream::internal
