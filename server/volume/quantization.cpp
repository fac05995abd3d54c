#include "server/volume/quantization.h"

#include <algorithm>
#include <cfloat>
#include <cmath>

namespace isostream {

void QuantizationFor(const Volume& v, QuantizationBox* box, int* bits) {
  double lo[3], extent = 0, step = INFINITY, largest = 0;
  for (int a = 0; a < 3; ++a) {
    const double end = v.origin[a] + v.spacing[a] * (v.dims[a] - 1);
    lo[a] = std::min(v.origin[a], end);
    extent = std::max(extent, std::abs(end - v.origin[a]));
    step = std::min(step, std::abs(v.spacing[a]));
    largest = std::max({largest, std::abs(v.origin[a]), std::abs(end)});
  }
  // The margin keeps vertices on the data boundary inside the box after float rounding (the
  // encoder rejects positions outside it): a part of the box, and some float steps of the
  // coordinates. An absolute margin (1e-6) once made the box of a volume with spacing 1e-25
  // 2e19 voxels wide, and every vertex decoded to one point.
  const double margin = 1e-4 * extent + 16 * FLT_EPSILON * largest;
  for (int a = 0; a < 3; ++a) box->origin[a] = float(lo[a] - margin);
  box->range = float(extent + 2 * margin);
  // Draco's own quantization (codec 2, .glb files) decodes every coordinate of a box narrower
  // than ~1e-7 (measured: 1e-6 kept, 1e-7 lost) to the box's corner: such boxes go unquantized.
  if (!(box->range >= kNarrowestQuantizedBox)) {
    *bits = 0;
    return;
  }
  // The fewest bits whose rounding (half a step) is at most 1/64 of the smallest spacing. None
  // can where the box spans over 2^25 (~3.4e7) smallest spacings (spacings far apart: 4096
  // samples 10 apart on one axis, 0.001 on another): positions then go as floats, unquantized.
  // (The float arithmetic's share of PositionErrorBound, a few float steps of the coordinates,
  // is what any float position carries, unquantized too.)
  for (int b = 8; b <= 30; ++b) {
    if (double(box->range) / (2 * (std::ldexp(1.0, b) - 1)) <= step / 64) {
      *bits = b;
      return;
    }
  }
  *bits = 0;
}

}  // namespace isostream
