// The adaptive extractor (eps > 0) against marching tetrahedra run directly on the leaves of the
// adaptive tree (refine T iff eta(x_ref(T)) >= eps), found by a plain recursive walk. The
// extractor culls with eta bounds, decides the last three levels in blocks and stops refining
// inside them; none of that may change the triangle set.
#include <gtest/gtest.h>

#include <map>

#include "marching_reference.h"
#include "server/extract/extractor.h"
#include "test_volumes.h"
#include "tree_walk.h"

namespace isostream {
namespace {

using testing::AdaptiveLeaves;
using testing::BlobsField;
using testing::CayleyField;
using testing::MakeHierarchy;
using testing::MarchTet;
using testing::MeshTriangles;
using testing::TriKey;

TEST(ExtractAdaptive, EqualsMarchingTetrahedraOverTheAdaptiveLeaves) {
  const std::vector<float> iso = {-0.3f, 0.05f, 0.4f};  // ascending: surface == index
  std::map<int, int> crossing_leaves_by_depth_below_finest;
  for (int k : {4, 5})
    for (auto field : {CayleyField, BlobsField}) {
      const auto h = MakeHierarchy(k, field);
      ASSERT_NE(h, nullptr);
      const int half = (h->n() - 1) / 2;
      const double root_eta = h->eta(half, half, half);
      for (double fraction : {1e-3, 1e-2, 1e-1}) {
        const double eps = root_eta * fraction;
        std::multiset<TriKey> reference;
        for (const auto& t : AdaptiveLeaves(*h, eps)) {
          float f[4];
          for (int i = 0; i < 4; ++i) f[i] = h->sample(t.v[i].x, t.v[i].y, t.v[i].z);
          const size_t before = reference.size();
          MarchTet(t.v.data(), f, iso, &reference);
          if (reference.size() > before) ++crossing_leaves_by_depth_below_finest[3 * k - t.level];
        }
        ExtractRequest r;
        r.isovalues = iso;
        r.eps = eps;
        r.view.eye = {-7.0, 30.0, 11.0};
        const auto res = Extract(*h, GridToWorld{}, r);
        ASSERT_TRUE(res.ok()) << res.status();
        const std::multiset<TriKey> ours = MeshTriangles(res->mesh);
        EXPECT_GT(reference.size(), 100u) << "k " << k << " eps " << eps;
        EXPECT_EQ(ours.size(), reference.size()) << "k " << k << " eps " << eps;
        EXPECT_TRUE(ours == reference) << "k " << k << " eps " << eps;
      }
    }
  // The cases reach leaves at every depth of the last block (finest, one and two above) and
  // above it, so both the node-by-node and the block paths are compared.
  for (int d = 0; d <= 3; ++d) EXPECT_GT(crossing_leaves_by_depth_below_finest[d], 0) << d;
}

}  // namespace
}  // namespace isostream
