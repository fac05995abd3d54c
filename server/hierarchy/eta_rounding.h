// The float arithmetic of one diamond's eta, shared by the whole cube's tiled builder
// (hierarchy.cpp) and the stand-in builder (stand_in_build.cpp) so both store the same bits.
// Private to server/hierarchy.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

namespace isostream::hierarchy_internal {

// The smallest float >= v (v >= 0). For f >= +0 the next float up is the next bit pattern
// (std::nextafter(f, INFINITY), without the library call).
inline float RoundUp(double v) {
  // Past the float range (wavelets of samples near FLT_MAX) the bound is +inf: such diamonds
  // always refine, which is conservative. (Converting the double itself would be undefined.)
  if (v > double(std::numeric_limits<float>::max())) return std::numeric_limits<float>::infinity();
  float f = static_cast<float>(v);
  if (static_cast<double>(f) < v) {
    uint32_t bits;
    std::memcpy(&bits, &f, sizeof(bits));
    ++bits;
    std::memcpy(&f, &bits, sizeof(f));
  }
  return f;
}

// eta of the diamond with sample f at its centre and f_plus, f_minus at its refinement edge's
// ends, given the largest eta of its children (0 if it has none).
inline float DiamondEta(float f, float f_plus, float f_minus, float worst) {
  const double w = static_cast<double>(f) - 0.5 * (static_cast<double>(f_plus) + f_minus);
  return RoundUp(std::fabs(w) + worst);
}

inline bool IsFinite(float v) {
  uint32_t bits;
  std::memcpy(&bits, &v, sizeof(bits));
  return (bits & 0x7f800000u) != 0x7f800000u;
}

}  // namespace isostream::hierarchy_internal
