// Internal to shared/: the vertex attributes of an edge-cache chunk (codec 3), coded by
// isostream itself. Replaces the Draco point cloud codec 3 used to carry: the same
// quantization (so PositionErrorBound, NormalErrorBound and seam-free chunks hold unchanged),
// without Draco's per-value attribute machinery.
//
// Layout (little-endian), exactly data[0, size):
//   uint8    position_bits (0: float32 positions)
//   uint8    normal_bits (0: float32 normals; 0 when the chunk has no normals)
//   float32  origin x, y, z, range    only when position_bits > 0: the quantization cube
//   tags     each vertex's tag (surface index | kUndefinedNormalBit) in runs of equal tags:
//            uint32 R (1..V runs), R symbols run length - 1, R symbols the run's tag minus the
//            previous run's, mod 256, zigzagged (the first run's previous is 0)
//   positions  position_bits > 0: 3V symbols, per vertex and axis the quantized coordinate minus
//            the previous vertex's, mod 2^position_bits, zigzagged (first from 0);
//            otherwise 3V float32
//   normals  only when the chunk has normals, for the N vertices whose tag lacks
//            kUndefinedNormalBit: normal_bits > 0: 2N symbols, octahedral (s, t) minus the
//            previous such vertex's, mod 2^normal_bits - 1, zigzagged (first from the centre);
//            otherwise 3N float32
// Symbol arrays are written with AppendSymbols (shared/internal/symbol_stream.h).
//
// Positions are quantized as Draco does (q = floor((p - origin) * M / range + 0.5), M =
// 2^bits - 1, decoded as q * (range / M) + origin, in float), so a vertex decodes to the same
// value as before and in every chunk sharing the box. Normals use the octahedral map: project
// onto |x| + |y| + |z| = 1, fold the lower half over the diagonals, round x and y to multiples
// of 1 / c with c = 2^(bits-1) - 1 (s = c + round(c x)), and decode by unfolding and
// normalizing; NormalErrorBound's derivation covers it (no re-balancing is needed: every (s,
// t) in [0, 2c]^2 unfolds to a point of the octahedron).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "shared/frame_codec.h"
#include "shared/internal/chunk_gather.h"
#include "shared/status.h"

namespace isostream::internal {

// Appends the coded attributes of `chunk`'s vertices (at least one) to `out`. Bits as in
// CodecOptions, already range-checked; `box` null quantizes on the chunk's BoundingCube. With
// a `box` and position_bits > 0, InvalidArgument (as CheckInsideBox) for a position outside
// it; `out` is then unspecified.
absl::Status EncodeChunkVertices(const GatheredChunk& chunk, int position_bits, int normal_bits,
                                 const QuantizationBox* box, std::string* out);

// Decodes exactly data[0, size) into `vertex_count` vertices' positions, normals (when
// `has_normals`; zero where undefined) and tags, replacing out's arrays. DataLoss on anything
// malformed: bad bits or box, symbols out of range, truncation, bytes left over, non-finite
// float values, undefined-normal tags in a chunk without normals.
absl::Status DecodeChunkVertices(const char* data, size_t size, uint32_t vertex_count,
                                 bool has_normals, DecodedChunk* out);

}  // namespace isostream::internal
