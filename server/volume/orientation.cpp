#include "server/volume/orientation.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>
#include <vector>

#include "server/volume/grid_builder.h"

namespace isostream {

bool Orientation::identity() const {
  return source == std::array<int, 3>{0, 1, 2} && !flip[0] && !flip[1] && !flip[2];
}

std::string Orientation::Describe() const {
  if (identity() && off_axis_degrees == 0) return fallback;
  std::array<std::string, 3> on;  // per file axis: the world axis it lies along
  for (int a = 0; a < 3; ++a) on[source[a]] = std::string(flip[a] ? "-" : "+") + "xyz"[a];
  std::string text = "file axes i j k on world " + on[0] + " " + on[1] + " " + on[2];
  if (off_axis_degrees > 0) {
    char angle[32];
    std::snprintf(angle, sizeof(angle), "%.3g", off_axis_degrees);
    text += std::string(" (the nearest axes: the file's grid is rotated ") + angle +
            " degrees off them)";
  }
  return fallback.empty() ? text : text + "; " + fallback;
}

absl::StatusOr<Orientation> NearestAxes(const std::array<std::array<double, 3>, 3>& m,
                                        const std::array<double, 3>& offset,
                                        const std::array<int, 3>& dims) {
  std::array<double, 3> length{};
  for (int i = 0; i < 3; ++i) {
    for (int r = 0; r < 3; ++r)
      if (!std::isfinite(m[r][i]))
        return absl::InvalidArgumentError("the voxel-to-world matrix is not finite");
    length[i] = std::hypot(m[0][i], m[1][i], m[2][i]);
    if (!(length[i] > 0) || !std::isfinite(length[i]))
      return absl::InvalidArgumentError(
          "the voxel-to-world matrix has a zero or overflowing column");
  }
  const double det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
                     m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                     m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
  // Relative to the columns' lengths: a matrix whose columns are (nearly) dependent has no
  // axes to follow.
  if (!(std::abs(det) > 1e-6 * length[0] * length[1] * length[2]))
    return absl::InvalidArgumentError("the voxel-to-world matrix is singular");

  // The permutation whose axes agree best with the columns' directions (all six are tried:
  // taking each column's largest entry alone can pick one world axis twice).
  std::array<int, 3> world_of{0, 1, 2};  // world axis of file axis i
  std::array<int, 3> best{0, 1, 2};
  double best_score = -1;
  do {
    double score = 0;
    for (int i = 0; i < 3; ++i) score += std::abs(m[world_of[i]][i]) / length[i];
    if (score > best_score) best_score = score, best = world_of;
  } while (std::next_permutation(world_of.begin(), world_of.end()));

  Orientation o;
  std::array<double, 3> corner = offset;  // world position of the first sample
  for (int i = 0; i < 3; ++i) {
    const int a = best[i];
    o.source[a] = i;
    o.flip[a] = m[a][i] < 0;
    o.dims[a] = dims[i];
    o.spacing[a] = length[i];
    const double cosine = std::min(1.0, std::abs(m[a][i]) / length[i]);
    o.off_axis_degrees = std::max(o.off_axis_degrees, std::acos(cosine) * 180.0 / M_PI);
    if (o.flip[a])
      for (int r = 0; r < 3; ++r) corner[r] += m[r][i] * (dims[i] - 1);
  }
  // Float rounding in a file's matrix must not read as a rotation.
  if (o.off_axis_degrees < 1e-3) o.off_axis_degrees = 0;
  o.origin = corner;
  return o;
}

VolumePtr Reorient(VolumePtr volume, const Orientation& o) {
  if (o.identity()) {  // the samples stay as they are; only the note changes
    auto same = std::make_shared<Volume>(*volume);
    same->orientation = o.Describe();
    return same;
  }
  using Leaf = openvdb::FloatTree::LeafNodeType;
  constexpr int kDim = Leaf::DIM;
  // Where each value of a converted leaf comes from in its source leaf.
  std::vector<openvdb::Index> from(Leaf::SIZE);
  for (int x = 0; x < kDim; ++x)
    for (int y = 0; y < kDim; ++y)
      for (int z = 0; z < kDim; ++z) {
        const int t[3] = {x, y, z};
        int s[3];
        for (int a = 0; a < 3; ++a) s[o.source[a]] = o.flip[a] ? kDim - 1 - t[a] : t[a];
        from[Leaf::coordToOffset(openvdb::Coord(x, y, z))] =
            Leaf::coordToOffset(openvdb::Coord(s[0], s[1], s[2]));
      }
  // A source index c maps to c (kept) or -1 - c (reversed) on its world axis.
  auto target_origin = [&](const openvdb::Coord& c) {
    openvdb::Coord t;
    for (int a = 0; a < 3; ++a) t[a] = o.flip[a] ? -kDim - c[o.source[a]] : c[o.source[a]];
    return t;
  };

  // The grid is turned in place (its name, class and metadata stay).
  const openvdb::FloatGrid::Ptr& grid = volume->grid;
  openvdb::FloatTree& tree = grid->tree();
  const float background = grid->background();
  // Tiles (OpenVDB files may hold them, inside the box or not) are put back turned: a tile's
  // cube maps onto an aligned cube of its size, as a leaf's does. Inactive ones holding the
  // background are no different from no tile. (Making leaves of the box's tiles instead made
  // a sparse grid dense: 785 MB for two voxels 511 apart.)
  struct Tile {
    openvdb::Index level;
    openvdb::Coord origin;
    float value;
    bool active;
  };
  std::vector<Tile> tiles;
  {
    openvdb::FloatTree::ValueAllCIter it = tree.cbeginValueAll();
    it.setMaxDepth(openvdb::FloatTree::ValueAllCIter::LEAF_DEPTH - 1);  // tiles, not voxels
    for (; it; ++it) {
      if (!it.isValueOn() && *it == background) continue;
      const openvdb::CoordBBox b = it.getBoundingBox();
      openvdb::Coord t;
      for (int a = 0; a < 3; ++a)
        t[a] = o.flip[a] ? -1 - b.max()[o.source[a]] : b.min()[o.source[a]];
      tiles.push_back({it.getLevel(), t, *it, it.isValueOn()});
    }
  }
  std::vector<Leaf*> leaves;
  tree.stealNodes(leaves);
  tree.clear();
  // Each leaf is turned in place: its values and active states permuted, its origin moved.
  tbb::parallel_for(size_t(0), leaves.size(), [&](size_t i) {
    Leaf* leaf = leaves[i];
    float* values = leaf->buffer().data();
    float before[Leaf::SIZE];
    std::copy(values, values + Leaf::SIZE, before);
    for (openvdb::Index j = 0; j < Leaf::SIZE; ++j) values[j] = before[from[j]];
    if (!leaf->isValueMaskOn() && !leaf->isValueMaskOff()) {
      const Leaf::NodeMaskType mask = leaf->getValueMask();
      for (openvdb::Index j = 0; j < Leaf::SIZE; ++j) leaf->setActiveState(j, mask.isOn(from[j]));
    }
    leaf->setOrigin(target_origin(leaf->origin()));
  });
  size_t added = 0;
  try {
    openvdb::FloatGrid::Accessor acc = grid->getAccessor();
    for (; added < leaves.size(); ++added) acc.addLeaf(leaves[added]);
    for (const Tile& t : tiles) tree.addTile(t.level, t.origin, t.value, t.active);
  } catch (...) {
    // The tree owns what it was given; the rest is still ours (bad_alloc reaches LoadVolume).
    for (size_t i = added; i < leaves.size(); ++i) delete leaves[i];
    throw;
  }

  auto turned = std::make_shared<Volume>(*volume);
  turned->dims = o.dims;
  std::array<double, 3> index_zero;  // world position of grid index (0, 0, 0)
  for (int a = 0; a < 3; ++a) {
    const int first = volume->index_min[o.source[a]];  // the source's first index on the axis
    turned->index_min[a] = o.flip[a] ? -1 - (first + o.dims[a] - 1) : first;
    index_zero[a] = o.origin[a] - o.spacing[a] * turned->index_min[a];
  }
  turned->spacing = o.spacing;
  turned->origin = o.origin;
  turned->orientation = o.Describe();
  grid->setTransform(MakeIndexToWorld(o.spacing, index_zero));
  return turned;
}

}  // namespace isostream
