#include "server/volume/stored_planes.h"

#include <cstddef>

namespace isostream {
namespace {

// Along one axis everything eta at a point reads lies within 3u of it (stored_planes.h); one
// more u of margin.
constexpr int64_t kReach = 4;

int TrailingZeros(int c) { return __builtin_ctz(unsigned(c)); }

}  // namespace

AxisPlanes StoredPlanesOf(int k, int data_points) {
  const int last = 1 << k;
  const int64_t data_last = data_points - 1;
  AxisPlanes axis;
  axis.plane_of.assign(std::size_t(last) + 1, -1);
  // By trailing zeros: the coordinate standing in for the deep planes with that many.
  std::vector<int> stand_in(std::size_t(k) + 1, -1);
  for (int c = 0; c <= last; ++c) {
    bool kept = c <= data_last;
    if (!kept) {
      const int v = TrailingZeros(c);
      const int64_t reach = kReach << v;
      const bool deep = c - reach >= data_last;  // never the far face: 2^k - 4 * 2^k < 0
      if (!deep || stand_in[std::size_t(v)] < 0) {
        kept = true;
        if (deep) stand_in[std::size_t(v)] = c;
      }
    }
    if (kept) {
      axis.plane_of[std::size_t(c)] = int(axis.planes.size());
      axis.planes.push_back(c);
    }
  }
  for (int c = 0; c <= last; ++c)
    if (axis.plane_of[std::size_t(c)] < 0)
      axis.plane_of[std::size_t(c)] =
          axis.plane_of[std::size_t(stand_in[std::size_t(TrailingZeros(c))])];
  return axis;
}

std::optional<std::array<AxisPlanes, 3>> StandInPlanes(int k, const std::array<int, 3>& data_dims) {
  std::array<AxisPlanes, 3> axes;
  int64_t points = 1;
  for (int a = 0; a < 3; ++a) {
    axes[a] = StoredPlanesOf(k, data_dims[a]);
    points *= int64_t(axes[a].planes.size());
  }
  const int64_t side = (int64_t{1} << k) + 1;
  if (4 * points > 3 * side * side * side) return std::nullopt;
  return axes;
}

int64_t StoredPointCount(int k, const std::array<int, 3>& data_dims) {
  const auto axes = StandInPlanes(k, data_dims);
  if (!axes) {
    const int64_t side = (int64_t{1} << k) + 1;
    return side * side * side;
  }
  int64_t points = 1;
  for (const AxisPlanes& axis : *axes) points *= int64_t(axis.planes.size());
  return points;
}

}  // namespace isostream
