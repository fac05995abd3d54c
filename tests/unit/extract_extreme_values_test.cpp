// The extractor on samples near FLT_MAX. Float differences of such samples overflow
// (3e38 - -3e38 = inf), which is why NewVertex computes an edge's crossing parameter in double:
// in float it becomes 0 or NaN on the long edges below, and the eps > 0 checks fail (NaN
// positions, vertices off the surface).
//
// The field is the L1 distance from the cube's centre, (|x| + |y| + |z| - 1.5) * 2e38: its
// samples span [-3e38, 3e38] exactly, and it is linear on each octant, so
//  * the hierarchy's full-resolution field equals it (no finest tetrahedron straddles two
//    octants), and a crossing lies exactly on the octahedron |x| + |y| + |z| = r of its
//    isovalue (within eps where a leaf does straddle octants);
//  * with eps > 0 whole octants become leaves (their eta is only the samples' rounding), with
//    edges from -3e38 at the centre to 3e38 at a corner: the case the double parameter is for.
// The coarse diamonds across octants have |w| up to 6e38, beyond float: their eta is stored
// as +inf, which only forces refinement.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "mesh_checks.h"
#include "server/extract/extractor.h"
#include "shared/mesh_validate.h"
#include "test_volumes.h"

namespace isostream {
namespace {

constexpr int kLevels = 4;         // 17^3 samples
constexpr double kRadius = 1.5;    // of the zero level set, in L1
constexpr double kScale = 2e38;    // samples span +-kRadius * kScale
constexpr float kExtreme = 3e38f;  // kRadius * kScale, below FLT_MAX = 3.4028e38

float OctahedronField(double x, double y, double z) {
  return float((std::abs(x) + std::abs(y) + std::abs(z) - kRadius) * kScale);
}

// Grid point i is at -1 + i / 8 on each axis: world positions are the field's coordinates,
// exactly, and the volume's world box is [-1, 1]^3.
const GridToWorld kWorld{{-1, -1, -1}, {0.125, 0.125, 0.125}};

TEST(ExtractExtremeValues, OctahedraNearFltMaxAreFiniteClosedAndOnTheSurface) {
  PaddedSamples samples = testing::MakeSamples(kLevels, OctahedronField);
  const auto [lo, hi] = std::minmax_element(samples.values.begin(), samples.values.end());
  ASSERT_EQ(*lo, -kExtreme);
  ASSERT_EQ(*hi, kExtreme);
  auto built = BuildHierarchy(std::move(samples));
  ASSERT_TRUE(built.ok()) << built.status();
  const Hierarchy& h = **built;

  // L1 radii 0.25, 0.5 and 0.75: closed octahedra inside the cube.
  const std::vector<float> iso = {-2.5e38f, -2e38f, -1.5e38f};
  size_t finest = 0;
  for (double eps : {0.0, 1e36, 1e38}) {
    char what[32];
    std::snprintf(what, sizeof(what), "eps %g", eps);
    ExtractRequest r;
    r.isovalues = iso;
    r.eps = eps;
    r.view.eye = {3, -2, 5};
    const auto res = Extract(h, kWorld, r);
    ASSERT_TRUE(res.ok()) << what << ": " << res.status();
    const OrderedMesh& m = res->mesh;
    for (size_t s = 0; s < iso.size(); ++s)
      EXPECT_GT(res->stats.triangles_per_surface[s], 0) << what << ", surface " << s;

    std::vector<int> surface_of(m.vertex_count(), -1);
    for (size_t t = 0; t < m.triangle_count(); ++t)
      for (int i = 0; i < 3; ++i) surface_of[m.triangles[3 * t + i]] = m.surface[t];
    size_t not_finite = 0, outside = 0, off_surface = 0, normal_not_finite = 0;
    // A crossing's field value is within eps of its isovalue (the extractor's contract), and
    // the field changes by kScale per unit of L1 distance.
    const double tolerance = eps / kScale + 1e-5;
    for (size_t v = 0; v < m.vertex_count(); ++v) {
      const float* p = &m.positions[3 * v];
      const float* n = &m.normals[3 * v];
      // Unit length: see NormalsNearFltMaxAreUnitVectors.
      if (!std::isfinite(n[0]) || !std::isfinite(n[1]) || !std::isfinite(n[2])) ++normal_not_finite;
      if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
        ++not_finite;
        continue;
      }
      if (std::max({std::abs(p[0]), std::abs(p[1]), std::abs(p[2])}) > 1.0f) ++outside;
      if (surface_of[v] < 0) continue;  // unused: caught by the watertightness check
      const double l1 = double(std::abs(p[0])) + std::abs(p[1]) + std::abs(p[2]);
      const double radius = kRadius + double(iso[surface_of[v]]) / kScale;
      if (std::abs(l1 - radius) > tolerance) ++off_surface;
    }
    EXPECT_EQ(not_finite, 0u) << what << ": of " << m.vertex_count() << " vertices";
    EXPECT_EQ(normal_not_finite, 0u) << what << ": of " << m.vertex_count() << " vertices";
    EXPECT_EQ(outside, 0u) << what << ": of " << m.vertex_count() << " vertices";
    EXPECT_EQ(off_surface, 0u) << what << ": of " << m.vertex_count() << " vertices";
    testing::ExpectWatertight(m, what);
    // eps > 0 must reach the coarse octant leaves whose edges overflow in float.
    if (eps == 0) {
      finest = m.triangle_count();
    } else {
      EXPECT_LT(m.triangle_count(), finest / 2) << what;
    }
  }
}

// The normal is the gradient normalised in float on the hot path: |g|^2 overflows once |g|
// exceeds sqrt(FLT_MAX) ~ 1.8e19 data units per world unit (the octahedra), and the gradient
// itself passes FLT_MAX in the central differences around the block below. Either would give
// (0, 0, 0) or NaN normals, which ValidateMesh and EncodeChunk reject; the extractor redoes
// such normals in double.
TEST(ExtractExtremeValues, NormalsNearFltMaxAreUnitVectors) {
  const auto octahedra = testing::MakeHierarchy(kLevels, OctahedronField);
  // A 3^3 block of -3e38 in 3e38: every crossing edge spans the whole range.
  const auto block = testing::MakeHierarchy(3, [](double x, double y, double z) {
    return std::max({std::abs(x), std::abs(y), std::abs(z)}) < 0.3 ? -kExtreme : kExtreme;
  });
  ASSERT_TRUE(octahedra && block);
  const struct {
    const Hierarchy* h;
    float iso;
    const char* name;
  } cases[] = {{octahedra.get(), -2e38f, "octahedra"}, {block.get(), 0.0f, "block"}};
  for (const auto& c : cases)
    for (NormalMode normals : {NormalMode::kSmooth, NormalMode::kFlat}) {
      const std::string what =
          std::string(c.name) + (normals == NormalMode::kSmooth ? " smooth" : " flat");
      ExtractRequest r;
      r.isovalues = {c.iso};
      r.normals = normals;
      r.view.eye = {3, -2, 5};
      const auto res = Extract(*c.h, GridToWorld{}, r);
      ASSERT_TRUE(res.ok()) << what << ": " << res.status();
      const OrderedMesh& m = res->mesh;
      ASSERT_GT(m.vertex_count(), 0u) << what;
      size_t bad = 0;
      for (size_t v = 0; v < m.vertex_count(); ++v) {
        const float* n = &m.normals[3 * v];
        const double len =
            std::sqrt(double(n[0]) * n[0] + double(n[1]) * n[1] + double(n[2]) * n[2]);
        if (!(std::abs(len - 1) < 1e-3)) ++bad;  // NaN counts
      }
      EXPECT_EQ(bad, 0u) << what << ": of " << m.vertex_count() << " normals";
      EXPECT_TRUE(ValidateMesh(m).ok()) << what << ": " << ValidateMesh(m);
    }
}

// The other end: gradients below ~1e-19 per world unit underflow float's squared length
// (the normal would be (0, 0, 0)); they are normalised in double too.
TEST(ExtractExtremeValues, NormalsOfTinyGradientsAreUnitVectors) {
  const auto h = testing::MakeHierarchy(4, [](double x, double y, double z) {
    return float(1e-25 * std::sqrt(x * x + y * y + z * z));
  });
  ASSERT_TRUE(h);
  for (NormalMode normals : {NormalMode::kSmooth, NormalMode::kFlat}) {
    ExtractRequest r;
    r.isovalues = {0.5e-25f};
    r.normals = normals;
    r.view.eye = {3, -2, 5};
    const auto res = Extract(*h, GridToWorld{}, r);
    ASSERT_TRUE(res.ok()) << res.status();
    const OrderedMesh& m = res->mesh;
    ASSERT_GT(m.vertex_count(), 100u);
    size_t bad = 0;
    for (size_t v = 0; v < m.vertex_count(); ++v) {
      const float* n = &m.normals[3 * v];
      const double len = std::sqrt(double(n[0]) * n[0] + double(n[1]) * n[1] + double(n[2]) * n[2]);
      if (!(std::abs(len - 1) < 1e-3)) ++bad;
    }
    EXPECT_EQ(bad, 0u) << (normals == NormalMode::kFlat ? "flat" : "smooth");
  }
}

// Diamonds whose wavelets pass the float range store eta = +inf, the root's among them; the
// budget search must still bracket eps with finite values and find a frame that fits.
TEST(ExtractExtremeValues, BudgetSearchStaysFiniteWhenEtaOverflows) {
  const auto octahedra = testing::MakeHierarchy(kLevels, OctahedronField);
  const auto block = testing::MakeHierarchy(3, [](double x, double y, double z) {
    return std::max({std::abs(x), std::abs(y), std::abs(z)}) < 0.3 ? -kExtreme : kExtreme;
  });
  ASSERT_TRUE(octahedra && block);
  const int half = (octahedra->n() - 1) / 2;
  ASSERT_TRUE(std::isinf(octahedra->eta(half, half, half)));
  for (const Hierarchy* h : {octahedra.get(), block.get()})
    for (int64_t budget : {50, 200, 1000}) {
      ExtractRequest r;
      r.isovalues = {h == block.get() ? 0.0f : -2e38f};
      r.budget = budget;
      r.view.eye = {3, -2, 5};
      const auto res = Extract(*h, GridToWorld{}, r);
      ASSERT_TRUE(res.ok()) << res.status();
      const std::string what = std::string(h == block.get() ? "block" : "octahedra") + " budget " +
                               std::to_string(budget);
      EXPECT_TRUE(std::isfinite(res->stats.eps_used)) << what << ": " << res->stats.eps_used;
      EXPECT_GT(res->stats.triangles, 0) << what;
      // Plateaus of the count over decades of eps are strided (without: the 60-pass cap).
      EXPECT_LE(res->stats.budget_passes, 30) << what;
      // Over budget only where even the coarsest mesh is: seen on the first pass.
      if (res->stats.triangles > budget) {
        EXPECT_EQ(res->stats.budget_passes, 1) << what;
      }
    }
}

}  // namespace
}  // namespace isostream
