// Blocks (the last three levels decided on bit sets, traversal.h) against refining the same
// levels node by node: the whole mesh, byte for byte, over the paths that differ (eps 0 and
// eps > 0 with stops inside blocks, eps equal to stored etas, perspective from outside and
// inside, orthographic, unordered, smooth and flat normals, a data box smaller than the cube);
// and the SSE2 bit-set arithmetic against its scalar definition.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>

#include "mesh_checks.h"
#include "server/extract/block_sets.h"
#include "server/extract/extractor.h"
#include "test_volumes.h"

namespace isostream {
namespace {

using testing::BlobsField;
using testing::CayleyField;

using Case = testing::VolumeCase;

std::vector<Case> Volumes() {
  std::vector<Case> v;
  v.push_back({testing::MakeHierarchy(4, CayleyField), {-0.3f, 0.05f, 0.4f}, "cayley 17^3"});
  v.push_back({testing::MakeHierarchy(5, BlobsField), {0.2f, 0.5f, 0.8f}, "blobs 33^3"});
  v.push_back(testing::ClippedCayley());
  return v;
}

TEST(ExtractBlocks, SameMeshByteForByteAsNodeByNode) {
  for (const Case& vol : Volumes()) {
    ASSERT_NE(vol.h, nullptr) << vol.name;
    const Hierarchy& h = *vol.h;
    const int half = (h.n() - 1) / 2;
    // eps 0, a fraction of the root's eta, and etas stored at grid points (refinement vertices
    // of the finest levels and above), where eta < eps and eta >= eps part exactly.
    std::vector<double> eps = {0.0, 1e-2 * h.eta(half, half, half)};
    for (const glm::ivec3 p : {glm::ivec3(1, 1, 1), glm::ivec3(2, 3, 5), glm::ivec3(6, 5, 3),
                               glm::ivec3(4, 4, 2), glm::ivec3(5, 7, 9)})
      if (h.eta(p.x, p.y, p.z) > 0) eps.push_back(h.eta(p.x, p.y, p.z));
    ASSERT_GE(eps.size(), 5u) << vol.name;
    int compared = 0;
    for (double e : eps)
      for (int view = 0; view < 4; ++view)
        for (NormalMode normals : {NormalMode::kSmooth, NormalMode::kFlat}) {
          ExtractRequest r;
          r.isovalues = vol.iso;
          r.eps = e;
          r.normals = normals;
          if (view == 0) r.view.eye = {-7.0, 30.0, 11.0};             // outside
          if (view == 1) r.view.eye = {half + 0.3, half - 0.2, 1.7};  // inside
          if (view == 2) r.view = {true, {}, {0.3, -1.0, 0.6}};       // orthographic
          if (view == 3) r.order = DrawOrder::kNone;
          const std::string what = vol.name + " eps " + std::to_string(e) + " view " +
                                   std::to_string(view) +
                                   (normals == NormalMode::kFlat ? " flat" : " smooth");
          ExtractRequest node_by_node = r;
          node_by_node.blocks = false;
          const auto a = Extract(h, GridToWorld{}, r);
          const auto b = Extract(h, GridToWorld{}, node_by_node);
          ASSERT_TRUE(a.ok() && b.ok()) << what;
          EXPECT_GT(a->mesh.triangle_count(), 0u) << what;
          EXPECT_EQ(a->mesh.triangles, b->mesh.triangles) << what;
          EXPECT_EQ(a->mesh.surface, b->mesh.surface) << what;
          EXPECT_EQ(a->mesh.positions, b->mesh.positions) << what;
          EXPECT_EQ(a->mesh.normals, b->mesh.normals) << what;
          ++compared;
        }
    EXPECT_GE(compared, 40) << vol.name;
  }
}

// Integers 0..4 at random in the middle 9^3 of a 17^3 cube, 0 around (closed level sets).
float ClosedRandomIntegers(double x, double y, double z) {
  if (std::abs(x) > 0.5 || std::abs(y) > 0.5 || std::abs(z) > 0.5) return 0;
  uint32_t h = uint32_t(std::lround((x + 1) * 8)) * 73856093u ^
               uint32_t(std::lround((y + 1) * 8)) * 19349663u ^
               uint32_t(std::lround((z + 1) * 8)) * 83492791u;
  h ^= h >> 13;
  h *= 0x5bd1e995u;
  h ^= h >> 15;
  return float(h % 5);
}

// Sixteen isovalues on, and one to four float steps off, integer samples (crossings on corners,
// rounding onto them on all or some coordinates), under unit voxels and under spacings from 1e-3
// to 7 with origins up to 2e5: blocks on and off and one and two threads give the same bytes,
// counts equal emitted triangles, no triangle has two corners in one place, and the surfaces
// off the samples (closed) stay watertight (with shared vertices: smooth normals).
TEST(ExtractBlocks, IsovaluesNextToIntegerSamplesAgreeAcrossPaths) {
  const auto h = testing::MakeHierarchy(4, ClosedRandomIntegers);
  ASSERT_NE(h, nullptr);
  auto steps = [](float v, int n) {
    for (int i = 0; i < std::abs(n); ++i) v = std::nextafter(v, n > 0 ? 10.0f : -10.0f);
    return v;
  };
  const std::vector<float> off = {steps(1, 1), steps(1, 2),  steps(2, -3), steps(2, -1),
                                  steps(2, 1), steps(2, 4),  steps(3, -2), steps(3, 1),
                                  steps(3, 3), steps(4, -1), steps(1, -1), steps(3, -4)};
  std::vector<float> all = off;
  for (float v : {1.0f, 2.0f, 3.0f, 2.5f}) all.push_back(v);
  GridToWorld far, fine;
  far.origin = {1e5, -2e5, 5e4};
  far.spacing = {0.3, 7, 0.3};
  fine.origin = {-700, 300, 1000};
  fine.spacing = {1e-3, 0.3, 7};
  const double some = 0.05 * h->eta(8, 8, 8);
  int compared = 0;
  for (const GridToWorld& xf : {GridToWorld{}, far, fine})
    for (double eps : {0.0, some})
      for (int view = 0; view < 3; ++view)
        for (NormalMode normals : {NormalMode::kSmooth, NormalMode::kFlat}) {
          ExtractRequest r;
          r.isovalues = view == 0 ? off : all;
          r.eps = eps;
          r.normals = normals;
          r.threads = 1;
          if (view == 0) r.view.eye = xf.origin + xf.spacing * glm::dvec3(-7, 30, 11);  // outside
          if (view == 1) r.view.eye = xf.origin + xf.spacing * glm::dvec3(8.3, 7.8, 2.7);  // inside
          if (view == 2) r.view = {true, {}, {0.3, -1.0, 0.6}};
          const std::string what = "spacing " + std::to_string(xf.spacing.x) + " eps " +
                                   std::to_string(eps) + " view " + std::to_string(view) +
                                   (normals == NormalMode::kFlat ? " flat" : " smooth");
          ExtractRequest node_by_node = r, two = r;
          node_by_node.blocks = false;
          two.threads = 2;
          const auto a = Extract(*h, xf, r);
          const auto b = Extract(*h, xf, node_by_node);
          const auto c = Extract(*h, xf, two);
          ASSERT_TRUE(a.ok() && b.ok() && c.ok()) << what;
          const OrderedMesh& m = a->mesh;
          EXPECT_GT(m.triangle_count(), 1000u) << what;
          for (const OrderedMesh* other : {&b->mesh, &c->mesh}) {
            EXPECT_EQ(m.triangles, other->triangles) << what;
            EXPECT_EQ(m.surface, other->surface) << what;
            EXPECT_EQ(m.positions, other->positions) << what;
            EXPECT_EQ(m.normals, other->normals) << what;
          }
          const auto counted = CountTriangles(*h, xf, r, eps);
          ASSERT_TRUE(counted.ok()) << what;
          EXPECT_EQ(*counted, int64_t(m.triangle_count())) << what;
          size_t two_in_one_place = 0;
          for (size_t t = 0; t < m.triangle_count(); ++t) {
            const float* p[3];
            for (int i = 0; i < 3; ++i) p[i] = &m.positions[3 * size_t(m.triangles[3 * t + i])];
            auto same = [](const float* u, const float* v) {
              return u[0] == v[0] && u[1] == v[1] && u[2] == v[2];
            };
            two_in_one_place += same(p[0], p[1]) || same(p[1], p[2]) || same(p[0], p[2]);
          }
          EXPECT_EQ(two_in_one_place, 0u) << what;
          if (view == 0 && normals == NormalMode::kSmooth) testing::ExpectWatertight(m, what);
          ++compared;
        }
  EXPECT_EQ(compared, 36);
}

TEST(ExtractBlocks, BitSetsMatchTheirScalarDefinition) {
  const ReferenceTets& tets = ReferenceTets::Get();
  const BlockTables& blocks = BlockTables::Get();
  int classes = 0;
  for (const TetClass cls : tets.kuhn_classes()) {
    const int c = cls.value;
    ++classes;
    for (unsigned above = 0; above < (1u << kBlockPoints); ++above)
      ASSERT_EQ(extract_internal::CrossingLeaves(blocks.leaf_corners(cls), above),
                extract_internal::CrossingLeavesScalar(blocks.leaf_corners(cls), above))
          << "class " << c << " points above " << above;
  }
  EXPECT_EQ(classes, 24);
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> pick(-3, 3);
  const float specials[] = {-INFINITY, INFINITY, NAN, -0.0f, 0.0f};
  for (int trial = 0; trial < 20000; ++trial) {
    float f[kBlockPoints];
    for (float& v : f) v = float(pick(rng));  // many ties with the isovalue
    if (trial % 4 == 0) f[trial % kBlockPoints] = specials[trial % 5];
    const float iso = trial % 7 == 0 ? specials[trial % 5] : float(pick(rng));
    ASSERT_EQ(extract_internal::AbovePoints(f, iso), extract_internal::AbovePointsScalar(f, iso))
        << "trial " << trial;
    ASSERT_EQ(extract_internal::AboveCorners(f, iso), extract_internal::AboveCornersScalar(f, iso))
        << "trial " << trial;
  }
  // Samples and isovalues are finite (loaders and requests refuse the others).
  std::uniform_real_distribution<float> fine(-1, 1);
  int near = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    float f[4];
    for (float& v : f) v = trial % 3 == 0 ? float(pick(rng)) : fine(rng);
    const float iso = trial % 5 == 0 ? f[trial % 4] + fine(rng) * 1e-4f : fine(rng);
    const float tau = trial % 2 == 0 ? 1e-4f : 0.25f;
    const unsigned m = extract_internal::CornersNearIso(f, iso, tau);
    ASSERT_EQ(m, extract_internal::CornersNearIsoScalar(f, iso, tau)) << "trial " << trial;
    near += m != 0;
  }
  EXPECT_GT(near, 2000);
  EXPECT_LT(near, 18000);
}

}  // namespace
}  // namespace isostream
