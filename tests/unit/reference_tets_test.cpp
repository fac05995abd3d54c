// Facts about the reference tetrahedra and the bisection tree, checked against direct geometry.
#include <gtest/gtest.h>

#include <algorithm>
#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>
#include <map>
#include <random>
#include <set>
#include <tuple>

#include "server/hierarchy/refinement_vertex.h"
#include "tree_walk.h"

namespace isostream {
namespace {

using testing::TetNode;
using testing::WalkTree;

using PointKey = std::tuple<int, int, int>;
PointKey Key(const glm::ivec3& p) { return {p.x, p.y, p.z}; }

std::set<PointKey> VertexSet(const TetVertices& v) {
  return {Key(v[0]), Key(v[1]), Key(v[2]), Key(v[3])};
}

TEST(ReferenceTets, SeventyTwoClassesTwentyFourPerLevelMod3) {
  const auto& tables = ReferenceTets::Get();
  ASSERT_EQ(tables.all().size(), 72u);
  int per[3] = {0, 0, 0};
  for (const auto& t : tables.all()) ++per[t.level_mod3];
  EXPECT_EQ(per[0], 24);
  EXPECT_EQ(per[1], 24);
  EXPECT_EQ(per[2], 24);
}

TEST(ReferenceTets, ChildMapIsClosedAndAdvancesTheLevel) {
  const auto& tables = ReferenceTets::Get();
  std::set<int> reached;
  for (const auto& t : tables.all())
    for (int c = 0; c < 2; ++c) {
      ASSERT_TRUE(t.child[c].valid());
      ASSERT_LT(t.child[c].value, 72);
      EXPECT_EQ(tables[t.child[c]].level_mod3, (t.level_mod3 + 1) % 3);
      reached.insert(t.child[c].value);
    }
  EXPECT_EQ(reached.size(), 72u);  // every class is some class's child
}

TEST(ReferenceTets, SeparatingPlanesAreTheNineMirrorPlanesAndSeparate) {
  const auto& tables = ReferenceTets::Get();
  std::set<std::tuple<int, int, int>> directions;
  for (const auto& t : tables.all()) {
    glm::dvec3 n = t.plane_normal;
    // Canonical sign: first nonzero component positive.
    for (int a = 0; a < 3; ++a)
      if (std::abs(n[a]) > 1e-9) {
        if (n[a] < 0) n = -n;
        break;
      }
    const glm::dvec3 scaled = n / std::max({std::abs(n.x), std::abs(n.y), std::abs(n.z)});
    directions.insert({static_cast<int>(std::lround(scaled.x)),
                       static_cast<int>(std::lround(scaled.y)),
                       static_cast<int>(std::lround(scaled.z))});
    // Components are 0 or +-1 after scaling: axis planes or face-diagonal planes.
    for (int a = 0; a < 3; ++a)
      EXPECT_NEAR(std::abs(scaled[a]), std::round(std::abs(scaled[a])), 1e-9);
    // The integer normal: entries 0 or +-1 (the extractor's plane test sums coordinates with
    // those signs), a positive multiple of the real one.
    for (int a = 0; a < 3; ++a) EXPECT_LE(std::abs(int(t.plane_normal_int[a])), 1);
    const glm::dvec3 ni(t.plane_normal_int[0], t.plane_normal_int[1], t.plane_normal_int[2]);
    EXPECT_NEAR(glm::dot(ni, t.plane_normal),
                glm::length(ni) * glm::length(t.plane_normal), 1e-9);
    // Strict separation: vertex 0 (child 0 only) in front, vertex 3 (child 1 only) behind.
    const glm::dvec3 mid = (glm::dvec3(t.vertex[0]) + glm::dvec3(t.vertex[3])) * 0.5;
    EXPECT_GT(glm::dot(t.plane_normal, glm::dvec3(t.vertex[0]) - mid), 0.1);
    EXPECT_LT(glm::dot(t.plane_normal, glm::dvec3(t.vertex[3]) - mid), -0.1);
    EXPECT_NEAR(glm::dot(t.plane_normal, glm::dvec3(t.vertex[1]) - mid), 0.0, 1e-12);
    EXPECT_NEAR(glm::dot(t.plane_normal, glm::dvec3(t.vertex[2]) - mid), 0.0, 1e-12);
  }
  EXPECT_EQ(directions.size(), 9u);
  for (const auto& d : directions) {
    const int nz = (std::get<0>(d) != 0) + (std::get<1>(d) != 0) + (std::get<2>(d) != 0);
    EXPECT_TRUE(nz == 1 || nz == 2);  // 3 axis planes, 6 face-diagonal planes
  }
}

// Walk the tree on [0,8]^3 and check every node against direct geometry.
TEST(BisectionTree, NodesMatchGeometryAndLongestEdgeBisection) {
  const int k = 3;
  const auto& tables = ReferenceTets::Get();
  size_t nodes = 0;
  WalkTree(k, [&](const TetNode& t) {
    ++nodes;
    std::array<int, 4> perm;
    EXPECT_EQ(tables.Classify(t.v, &perm), t.cls);
    EXPECT_EQ(perm, (std::array<int, 4>{0, 1, 2, 3}));
    EXPECT_EQ(tables[t.cls].level_mod3, t.level % 3);
    // Unique longest edge, and it is the refinement edge (vertex 0, vertex 3).
    auto len2 = [](glm::ivec3 d) { return d.x * d.x + d.y * d.y + d.z * d.z; };
    const int ref = len2(t.v[3] - t.v[0]);
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j)
        if (!(i == 0 && j == 3)) {
          EXPECT_LT(len2(t.v[j] - t.v[i]), ref);
        }
    // Volume is 1/6 of the cube cell at the level, halved per level.
    const glm::dmat3 e(glm::dvec3(t.v[1] - t.v[0]), glm::dvec3(t.v[2] - t.v[0]),
                       glm::dvec3(t.v[3] - t.v[0]));
    EXPECT_NEAR(std::abs(glm::determinant(e)) / 6.0, 512.0 / 6.0 / (1 << t.level), 1e-9);
    return true;
  });
  // 6 * (2^0 + ... + 2^9) tetrahedra.
  EXPECT_EQ(nodes, 6u * ((1u << (3 * k + 1)) - 1));
}

// Maubach's tagged rule, run independently, produces the same tetrahedra at every level.
TEST(BisectionTree, MaubachTaggedRuleGivesTheSameTetrahedra) {
  const int k = 2, size = 1 << k;
  std::vector<std::set<std::set<PointKey>>> ours(3 * k + 1), maubach(3 * k + 1);
  WalkTree(k, [&](const TetNode& t) {
    ours[t.level].insert(VertexSet(t.v));
    return true;
  });
  struct Simplex {
    std::array<glm::ivec3, 4> x;
    int tag;
  };
  std::vector<Simplex> level;
  int axes[3] = {0, 1, 2};
  do {
    Simplex s{{}, 3};
    glm::ivec3 p(0);
    s.x[0] = p;
    for (int i = 0; i < 3; ++i) {
      p[axes[i]] += size;
      s.x[i + 1] = p;
    }
    level.push_back(s);
  } while (std::next_permutation(axes, axes + 3));
  for (int l = 0; l <= 3 * k; ++l) {
    std::vector<Simplex> next;
    for (const auto& s : level) {
      maubach[l].insert(VertexSet(s.x));
      const int t = s.tag;
      const glm::ivec3 z = (s.x[0] + s.x[t]) / 2;
      Simplex a{s.x, t > 1 ? t - 1 : 3}, b{{}, t > 1 ? t - 1 : 3};
      a.x[t] = z;                                       // (x0, ..., x_{t-1}, z, x_{t+1}, ...)
      for (int i = 0; i < t; ++i) b.x[i] = s.x[i + 1];  // (x1, ..., x_t, z, x_{t+1}, ...)
      b.x[t] = z;
      for (int i = t + 1; i < 4; ++i) b.x[i] = s.x[i];
      next.push_back(a);
      next.push_back(b);
    }
    level = std::move(next);
  }
  for (int l = 0; l <= 3 * k; ++l) EXPECT_EQ(ours[l], maubach[l]) << "level " << l;
}

TEST(BisectionTree, RefinementVerticesAreGridPointsOfExactlyOneLevel) {
  const int k = 3, n = (1 << k) + 1;
  std::map<PointKey, std::set<int>> levels;
  WalkTree(k, [&](const TetNode& t) {
    if (t.level == 3 * k) return false;
    const glm::ivec3 sum = t.v[0] + t.v[3];
    EXPECT_TRUE(sum.x % 2 == 0 && sum.y % 2 == 0 && sum.z % 2 == 0) << "not a grid point";
    const glm::ivec3 x = sum / 2;
    levels[Key(x)].insert(t.level);
    RefinementVertex rv;
    EXPECT_TRUE(ClassifyGridPoint(x.x, x.y, x.z, k, &rv));
    EXPECT_EQ(TreeLevel(k, rv), t.level);
    // The refinement edge predicted from the point alone.
    glm::ivec3 e(0);
    for (int a = 0; a < 3; ++a)
      if ((rv.odd_mask >> a) & 1) e[a] = EvenEndSign(x[a], rv.h) * (1 << rv.h);
    EXPECT_EQ(std::set<PointKey>({Key(t.v[0]), Key(t.v[3])}),
              std::set<PointKey>({Key(x + e), Key(x - e)}));
    return true;
  });
  int corners = 0;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        RefinementVertex rv;
        const bool is_vertex = ClassifyGridPoint(x, y, z, k, &rv);
        auto it = levels.find({x, y, z});
        if (!is_vertex) {
          ++corners;
          EXPECT_TRUE(it == levels.end());
          continue;
        }
        ASSERT_TRUE(it != levels.end()) << x << "," << y << "," << z;
        EXPECT_EQ(it->second.size(), 1u);
      }
  EXPECT_EQ(corners, 8);
}

// Hierarchical gradients (Gerstner §5) equal a direct solve on every tetrahedron.
TEST(BisectionTree, HierarchicalGradientsEqualDirectSolve) {
  const int k = 2, n = (1 << k) + 1;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> val(-1, 1);
  std::vector<double> f(n * n * n);
  for (auto& v : f) v = val(rng);
  auto at = [&](const glm::ivec3& p) { return f[(p.z * n + p.y) * n + p.x]; };
  auto direct = [&](const TetVertices& v) {
    const glm::dmat3 e(glm::dvec3(v[1] - v[0]), glm::dvec3(v[2] - v[0]), glm::dvec3(v[3] - v[0]));
    const glm::dvec3 df(at(v[1]) - at(v[0]), at(v[2]) - at(v[0]), at(v[3]) - at(v[0]));
    return glm::inverse(glm::transpose(e)) * df;  // E^T g = df
  };
  const auto& tables = ReferenceTets::Get();
  size_t checked = 0;
  std::function<void(const TetNode&, glm::dvec3)> rec = [&](const TetNode& t, glm::dvec3 g) {
    const glm::dvec3 d = direct(t.v);
    EXPECT_LE(glm::length(g - d), 1e-9 * std::max(1.0, glm::length(d)));
    ++checked;
    if (t.level == 3 * k) return;
    const ReferenceTet& rt = tables[t.cls];
    const glm::ivec3 x = RefinementPoint(t.v);
    const double w = at(x) - 0.5 * (at(t.v[0]) + at(t.v[3]));
    const glm::ivec3 ext = glm::max(glm::max(t.v[0], t.v[1]), glm::max(t.v[2], t.v[3])) -
                           glm::min(glm::min(t.v[0], t.v[1]), glm::min(t.v[2], t.v[3]));
    const double unit = std::max({ext.x, ext.y, ext.z}) / 2.0;
    for (int c = 0; c < 2; ++c) {
      TetNode child{{}, rt.child[c], t.level + 1};
      ChildVertices(rt, t.v, c, &child.v);
      rec(child, g + w * rt.gradient_update[c] / unit);
    }
  };
  for (int i = 0; i < kNumInitialTets; ++i) {
    const TetVertices v = InitialVertices(tables, i, 1 << k);
    rec(TetNode{v, tables.initial_class(i), 0}, direct(v));
  }
  EXPECT_EQ(checked, 6u * ((1u << (3 * k + 1)) - 1));
}

// Rays from eyes around and inside the cube: the initial tetrahedra they cross must come in
// the order InitialOrder gives, far to near.
TEST(ReferenceTets, InitialOrderIsPaintersOrderAlongRays) {
  const auto& tables = ReferenceTets::Get();
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.5, 2.5), unit(0, 1);
  auto entry = [&](int tet, glm::dvec3 o, glm::dvec3 d, double* t0) {
    const TetVertices v = InitialVertices(tables, tet, 2);
    double lo = 0, hi = 1e30;
    for (int f = 0; f < 4; ++f) {
      const glm::dvec3 a(v[(f + 1) % 4]), b(v[(f + 2) % 4]), c(v[(f + 3) % 4]), p(v[f]);
      glm::dvec3 nrm = glm::cross(b - a, c - a);
      if (glm::dot(nrm, p - a) < 0) nrm = -nrm;  // inward
      const double num = glm::dot(nrm, o - a), den = glm::dot(nrm, d);
      if (std::abs(den) < 1e-15) {
        if (num < 0) return false;
        continue;
      }
      const double t = -num / den;
      if (den > 0) {
        lo = std::max(lo, t);
      } else {
        hi = std::min(hi, t);
      }
    }
    *t0 = lo;
    return hi > lo + 1e-9;
  };
  int rays = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const bool ortho = trial % 3 == 0;
    glm::dvec3 eye(u(rng), u(rng), u(rng));  // cube is [0,2]^3; some eyes inside
    if (ortho) eye = glm::normalize(glm::dvec3(u(rng), u(rng), u(rng)) - 0.5);
    int order[6];
    tables.InitialOrder(ortho ? eye : eye / 2.0, ortho, order);
    int rank[6];
    for (int i = 0; i < 6; ++i) rank[order[i]] = i;
    for (int r = 0; r < 10; ++r) {
      const glm::dvec3 target(2 * unit(rng), 2 * unit(rng), 2 * unit(rng));
      const glm::dvec3 dir = ortho ? eye : glm::normalize(target - eye);
      const glm::dvec3 origin = ortho ? target - 10.0 * dir : eye;
      std::vector<std::pair<double, int>> hits;
      for (int t = 0; t < 6; ++t) {
        double t0;
        if (entry(t, origin, dir, &t0)) hits.push_back({t0, t});
      }
      std::sort(hits.begin(), hits.end());
      for (size_t i = 1; i < hits.size(); ++i)
        EXPECT_GT(rank[hits[i - 1].second], rank[hits[i].second]) << "nearer drawn first";
      ++rays;
    }
  }
  EXPECT_EQ(rays, 20000);
}

}  // namespace
}  // namespace isostream
