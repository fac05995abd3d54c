// Grid points as refinement vertices of the bisection hierarchy.
//
// On a cube of n = 2^k + 1 points, every grid point except the 8 domain corners is the
// refinement vertex (the centre of one diamond) of exactly one level. With u = 2^h the largest
// power of two dividing all three coordinates, the point is the centre of an edge, face or cube
// of side 2u according to how many coordinates are odd multiples of u (1, 2 or 3). Diamond
// kinds cycle with the level: a cube centre at tree level 3(k-h-1), a face centre one level
// below, an edge centre two below.
//
// The refinement edge of a diamond runs through the point along its odd axes; for face and
// cube centres it is the diagonal that ends at the corner whose odd-axis coordinates are
// multiples of 4u (the finest tetrahedra form a reflected Kuhn triangulation). Children are the
// diamonds one level below whose parents include this one; see hierarchy.cpp for why
// saturating eta over them keeps refinement closed.
#pragma once

#include <cstdint>

namespace isostream {

enum class DiamondKind : uint8_t { kCube = 0, kFace = 1, kEdge = 2 };  // == level mod 3

struct RefinementVertex {
  int h = 0;         // the diamond's cells have side 2^(h+1)
  int odd_mask = 0;  // bit a set: coordinate a is an odd multiple of 2^h
  DiamondKind kind = DiamondKind::kCube;
};

inline int TreeLevel(int k, const RefinementVertex& v) {
  return 3 * (k - v.h - 1) + static_cast<int>(v.kind);
}

// False for the 8 domain corners, which refine nothing.
inline bool ClassifyGridPoint(int x, int y, int z, int k, RefinementVertex* out) {
  const unsigned bits = static_cast<unsigned>(x | y | z);
  if (bits == 0) return false;
  const int h = __builtin_ctz(bits);
  if (h >= k) return false;
  out->h = h;
  out->odd_mask = ((x >> h) & 1) | (((y >> h) & 1) << 1) | (((z >> h) & 1) << 2);
  const int odd = __builtin_popcount(static_cast<unsigned>(out->odd_mask));
  out->kind = static_cast<DiamondKind>(3 - odd);
  return true;
}

// Direction (+1 or -1) from the point to the refinement-edge end whose coordinate along this
// odd axis is a multiple of 4u. `c` is the coordinate, `h` the vertex's scale.
inline int EvenEndSign(int c, int h) { return ((c >> h) & 3) == 3 ? 1 : -1; }

}  // namespace isostream
