// Internal to shared/: the entropy coder behind the edge-cache chunk's symbol arrays
// (connectivity and vertex attributes), isostream's own: a static rANS coder with byte-wise
// renormalization over a small token alphabet, plus raw extra bits for large values.
//
// A symbol v (uint32) becomes a token and 0-29 extra bits: v < 128 is token v with no extra
// bits (the connectivity and cache symbols, small deltas: their exact distribution matters);
// otherwise, with b = bit width of v (8..32), token 128 + 4 (b - 8) + the two bits below v's
// leading one, and the b - 3 bits below those as extra bits. Tokens are at most 227.
// Most symbols here are small (cache positions, deltas of neighbouring vertices), so the
// tokens carry nearly all the information and the extra bits are close to uniform.
//
// One array, exactly:
//   varint   A, the token alphabet size (largest token + 1), 1..228
//   varint   A frequencies, each 0..4096, summing to 4096 (kProbabilityBits = 12)
//   varint   R >= 16, then R bytes: the rANS stream: four interleaved states (symbol i uses
//            state i % 4), their final values first (4 bytes little-endian each, state 0
//            first), then the renormalization bytes
//   varint   E, then E bytes: the extra bits, least significant first, symbol order, the last
//            byte zero-padded
// Varints are LEB128 (7 bits a byte, low first, at most 5 bytes). The decoder checks every
// field, refuses to read past either stream, and requires all four rANS states to end where
// the encoder started them and both streams to be consumed exactly.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace isostream::internal {

// Appends `count` symbols (count > 0) to `out`.
void AppendSymbols(const uint32_t* symbols, size_t count, std::string* out);

// Reads one array of `count` symbols (count > 0) from data[*at, size) into `symbols` (room for
// `count`) and advances *at past it. False on malformed input; `symbols` is then unspecified.
bool ReadSymbols(const char* data, size_t size, size_t* at, size_t count, uint32_t* symbols);

}  // namespace isostream::internal
