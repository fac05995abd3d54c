// How finely a volume's mesh positions are quantized when compressed (the daemon's frames, the
// CLI's .glb files): one box and bit count per volume, from its sample spacing.
#pragma once

#include "server/volume/volume.h"
#include "shared/frame_codec.h"

namespace isostream {

// The box and bit count for a volume's meshes: bits = the fewest (8..30) that make the
// quantization step at most 1/32 of the smallest sample spacing, so its rounding (half a step)
// is at most 1/64 of a voxel; 0 (float positions, unquantized) where 30 bits cannot. 129^3 at
// unit spacing: 13 bits; 513^3: 15 bits. Boxes narrower than kNarrowestQuantizedBox (world
// units) go unquantized too.
inline constexpr double kNarrowestQuantizedBox = 1e-5;
void QuantizationFor(const Volume& volume, QuantizationBox* box, int* bits);

}  // namespace isostream
