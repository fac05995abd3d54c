#include "server/volume/quantization.h"

#include <algorithm>
#include <cmath>

namespace isostream {

void QuantizationFor(const Volume& v, QuantizationBox* box, int* bits) {
  double lo[3], hi[3], extent = 0, step = INFINITY;
  for (int a = 0; a < 3; ++a) {
    lo[a] = v.origin[a];
    hi[a] = v.origin[a] + v.spacing[a] * (v.dims[a] - 1);
    extent = std::max(extent, hi[a] - lo[a]);
    step = std::min(step, std::abs(v.spacing[a]));
  }
  // The margin keeps vertices on the data boundary inside the box after float rounding (the
  // encoder rejects positions outside it).
  const double margin = 1e-4 * extent + 1e-6;
  for (int a = 0; a < 3; ++a) box->origin[a] = float(std::min(lo[a], hi[a]) - margin);
  box->range = float(extent + 2 * margin);
  int b = 8;
  while (b < 24 && box->range / double((1u << b) - 1) > step / 32) ++b;
  *bits = b;
}

}  // namespace isostream
