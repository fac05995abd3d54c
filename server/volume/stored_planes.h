// Which planes of the hierarchy cube a volume stores. The cube has 2^k + 1 points per axis, so a
// volume only a little past a power of two, or thin along some axis, would be held mostly as
// padding (a 2048x2048x50 stack as 2049^3 points, 51 GB). Planes deep in the padding are not
// stored: each stands in for all of them with the same number of trailing zero bits in their
// coordinate, and the per-axis offset tables send every coordinate to its stand-in, so the
// traversal and the extractor read through them unchanged.
//
// Why a stand-in is exact. Beyond the data the padding replicates the last data plane (padding.h),
// so the samples do not depend on a padded coordinate, and any two padded planes hold the same
// samples. eta at a point p of scale h (every coordinate a multiple of u = 2^h) is its wavelet
// plus the largest eta among its diamond's children (hierarchy.cpp): cube centre -> face centres
// at +-u, face centre -> edge centres at +-u along its odd axes, edge centre -> cube centres of
// scale h - 1 at +-u/2 on every axis. Along one axis a point's descendants and the ends of their
// refinement edges therefore stay within 3u of it (u for one chain of cube, face and edge
// centres, then u/2 + u/4 + ... twice). Take coordinate c on an axis with c - 4 * 2^v >= the last
// data coordinate, v = c's trailing zero bits (so u <= 2^v for every point on its plane; and
// c < 2^k). Everything eta(p) reads then lies in the padding; the refinement edges' directions
// along that axis are mirror images at most, and the samples do not depend on it; and a child's
// coordinate c + delta has the same trailing zero bits as c' + delta for another such c' with v
// trailing zeros, or more than its own scale in both, which is all its eta can depend on. The
// cube's far face clips some descendants: an edge centre on it has no children beyond it. But
// in the padding each such child's mirror image about the face (an even lattice plane of its
// scale, about which the hierarchy is symmetric, as the samples are about any padded plane) is
// a child too, with the same eta, so the largest eta is the same with or without it. By
// induction over the scales, eta(p) is the same on every such plane with v trailing zeros: one
// stored plane per v stands in for them all. Tested point for point against the whole cube
// (hierarchy_stand_in_test.cpp, random shapes among them).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <vector>

namespace isostream {

struct AxisPlanes {
  std::vector<int> planes;    // the stored cube coordinates, ascending
  std::vector<int> plane_of;  // per cube coordinate 0..2^k: the index in `planes` standing for it
};

// The planes along an axis of the 2^k + 1 cube holding `data_points` points of data (from
// coordinate 0): all of the data's, those within reach of the data (the far face among them),
// and one stand-in per number of trailing zero bits for the rest.
AxisPlanes StoredPlanesOf(int k, int data_points);

// The three axes' stored planes for a volume of these dimensions in the 2^k + 1 cube, where the
// stand-ins are worth it: they keep at most 3/4 of the cube's points. Empty: the whole cube.
// The stand-in builder is ~2x slower per point than the whole cube's (tiles of a regular
// lattice), but a build's time is mostly first touches of its memory: 300x400x500 (53.5% of its
// 513^3 cube with the planes of the time) prepared in about the same time either way, in 0.81 GB
// instead of 1.41. Nearer a cube, the whole cube's builder wins.
std::optional<std::array<AxisPlanes, 3>> StandInPlanes(int k, const std::array<int, 3>& data_dims);
inline bool UseStandIns(int k, const std::array<int, 3>& data_dims) {
  return StandInPlanes(k, data_dims).has_value();
}

// Points stored for a volume of these dimensions in the 2^k + 1 cube: the stand-in planes'
// product, else the whole cube's.
int64_t StoredPointCount(int k, const std::array<int, 3>& data_dims);

}  // namespace isostream
