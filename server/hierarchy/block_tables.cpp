// Walks three bisection levels below each reference class with points in barycentric
// coordinates of the root (weights summing to 8, so three halvings stay integral), then names
// each point as one of the root's 10 local points.
#include "server/hierarchy/block_tables.h"

#include <stdexcept>

namespace isostream {
namespace {

using Weights = std::array<int, 4>;
constexpr int kWeightSum = 1 << kBlockDepth;

int LocalPoint(const Weights& w) {
  for (int i = 0; i < 4; ++i)
    if (w[i] == kWeightSum) return i;
  for (int e = 0; e < 6; ++e) {
    const int a = kBlockEdge[e][0], b = kBlockEdge[e][1];
    if (w[a] == kWeightSum / 2 && w[b] == kWeightSum / 2) return 4 + e;
  }
  throw std::logic_error("block descendant vertex is not a corner or edge midpoint of the root");
}

}  // namespace

const BlockTables& BlockTables::Get() {
  static const BlockTables tables;
  return tables;
}

BlockTables::BlockTables() {
  const ReferenceTets& tets = ReferenceTets::Get();
  for (const TetClass root : tets.kuhn_classes()) {
    const int c = root.value;
    std::array<std::array<Weights, 4>, kBlockNodes> corners{};
    auto& nodes = nodes_[c];
    nodes[1].cls = root;
    for (int i = 0; i < 4; ++i) {
      corners[1][i] = {0, 0, 0, 0};
      corners[1][i][i] = kWeightSum;
    }
    for (int p = 1; p < kBlockNodes; ++p) {
      BlockNode& node = nodes[p];
      for (int i = 0; i < 4; ++i) {
        node.corner[i] = static_cast<uint8_t>(LocalPoint(corners[p][i]));
        node.corners |= uint16_t(1u << node.corner[i]);
      }
      if (2 * p >= kBlockNodes) continue;
      const ReferenceTet& rt = tets[node.cls];
      std::array<Weights, 5> points;
      for (int i = 0; i < 4; ++i) points[i] = corners[p][i];
      for (int j = 0; j < 4; ++j) {
        const int sum = corners[p][0][j] + corners[p][3][j];
        if (sum % 2) throw std::logic_error("block refinement vertex off the lattice");
        points[kRefinementPoint][j] = sum / 2;
      }
      node.refinement = static_cast<uint8_t>(LocalPoint(points[kRefinementPoint]));
      for (int ch = 0; ch < 2; ++ch) {
        nodes[2 * p + ch].cls = rt.child[ch];
        for (int i = 0; i < 4; ++i) corners[2 * p + ch][i] = points[rt.child_point[ch][i]];
      }
    }
    for (int j = 0; j < kBlockNodes / 2; ++j)
      leaf_corners_[c][j] = nodes[kBlockNodes / 2 + j].corners;
  }
}

}  // namespace isostream
