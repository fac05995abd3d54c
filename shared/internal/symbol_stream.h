// Internal to shared/: the entropy coder behind the edge-cache chunk's symbol arrays
// (connectivity and vertex attributes). One place, so the coder can change without touching
// the models that produce the symbols.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace draco {
class DecoderBuffer;
}  // namespace draco

namespace isostream::internal {

// Appends `count` symbols (count > 0), coded with Draco's rANS symbol coder; `components`
// values that belong together (x, y, z of one position) let it pick per-group bit lengths.
// False if the coder fails.
bool AppendSymbols(const uint32_t* symbols, size_t count, int components, std::string* out);

// Reads `count` symbols (count > 0) written by AppendSymbols from `buffer`, which must have
// been initialised with draco::kDracoMeshBitstreamVersion. False on any malformed input;
// `symbols` must hold `count` values.
bool ReadSymbols(draco::DecoderBuffer* buffer, size_t count, int components, uint32_t* symbols);

}  // namespace isostream::internal
