// The extractor against direct computations: watertightness, painter's order along rays,
// equality with brute-force marching tetrahedra at eps = 0, monotone counts, thread
// independence, and clear errors for bad requests.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <glm/geometric.hpp>
#include <limits>
#include <random>
#include <set>

#include "marching_reference.h"
#include "mesh_checks.h"
#include "server/extract/block_sets.h"
#include "server/extract/data_box_clip.h"
#include "server/extract/extractor.h"
#include "test_volumes.h"

namespace isostream {
namespace {

using testing::BlobsField;
using testing::CayleyField;
using testing::ExpectWatertight;
using testing::MakeHierarchy;
using testing::MarchTet;
using testing::MeshTriangles;
using testing::SphereField;
using testing::TriKey;

const GridToWorld kGrid{};  // world == grid coordinates

ExtractRequest Request(std::vector<float> iso, double eps, glm::dvec3 eye) {
  ExtractRequest r;
  r.isovalues = std::move(iso);
  r.eps = eps;
  r.view.eye = eye;
  return r;
}

ExtractResult RunExtract(const Hierarchy& h, const ExtractRequest& r,
                         const GridToWorld& xf = kGrid) {
  auto res = Extract(h, xf, r);
  EXPECT_TRUE(res.ok()) << res.status();
  return res.ok() ? std::move(*res) : ExtractResult{};
}

TEST(Extract, ClosedSurfacesAreWatertightAtSeveralEps) {
  const auto sphere = MakeHierarchy(5, SphereField);
  const auto blobs = MakeHierarchy(5, BlobsField);
  for (double eps : {0.0, 0.002, 0.01, 0.05, 0.2}) {
    const auto a = RunExtract(*sphere, Request({0.35f, 0.6f, 0.85f}, eps, {-40, 10, 70}));
    EXPECT_GT(a.mesh.triangle_count(), 100u);
    ExpectWatertight(a.mesh, "sphere eps " + std::to_string(eps));
    const auto b = RunExtract(*blobs, Request({0.2f, 0.5f, 0.8f}, eps, {16, 16, 16}));
    EXPECT_GT(b.mesh.triangle_count(), 100u);
    ExpectWatertight(b.mesh, "blobs eps " + std::to_string(eps));
  }
}

// Ray-triangle intersection (Moller-Trumbore), distance along the ray or -1.
double Hit(const OrderedMesh& m, size_t t, const glm::dvec3& o, const glm::dvec3& d) {
  auto P = [&](int i) {
    const float* p = &m.positions[3 * size_t(m.triangles[3 * t + i])];
    return glm::dvec3(p[0], p[1], p[2]);
  };
  const glm::dvec3 a = P(0), b = P(1), c = P(2);
  const glm::dvec3 e1 = b - a, e2 = c - a, pv = glm::cross(d, e2);
  const double det = glm::dot(e1, pv);
  if (std::abs(det) < 1e-14) return -1;
  const glm::dvec3 tv = o - a;
  const double u = glm::dot(tv, pv) / det;
  if (u < 0 || u > 1) return -1;
  const glm::dvec3 qv = glm::cross(tv, e1);
  const double v = glm::dot(d, qv) / det;
  if (v < 0 || u + v > 1) return -1;
  const double dist = glm::dot(e2, qv) / det;
  return dist > 1e-9 ? dist : -1;
}

// Along every ray, the triangles it crosses come in draw order from far to near.
int CheckPaintersOrder(const OrderedMesh& m, const View& view, int rays, std::mt19937* rng,
                       const std::string& what) {
  std::uniform_int_distribution<size_t> pick(0, m.triangle_count() - 1);
  std::uniform_real_distribution<double> jitter(-0.3, 0.3);
  int violations = 0, multi = 0;
  for (int r = 0; r < rays; ++r) {
    // Aim at a random triangle so every ray hits something.
    const size_t t = pick(*rng);
    glm::dvec3 target(0.0);
    for (int i = 0; i < 3; ++i) {
      const float* p = &m.positions[3 * size_t(m.triangles[3 * t + i])];
      target += glm::dvec3(p[0], p[1], p[2]) / 3.0;
    }
    target += glm::dvec3(jitter(*rng), jitter(*rng), jitter(*rng));
    const glm::dvec3 dir =
        view.orthographic ? glm::normalize(view.direction) : glm::normalize(target - view.eye);
    const glm::dvec3 origin = view.orthographic ? target - 1000.0 * dir : view.eye;
    std::vector<std::pair<double, size_t>> hits;
    for (size_t i = 0; i < m.triangle_count(); ++i) {
      const double d = Hit(m, i, origin, dir);
      if (d > 0) hits.push_back({d, i});
    }
    std::sort(hits.begin(), hits.end());
    multi += hits.size() > 1;
    for (size_t i = 1; i < hits.size(); ++i) {
      if (hits[i].first - hits[i - 1].first < 1e-7 * (1 + hits[i].first)) continue;  // shared edge
      if (hits[i - 1].second < hits[i].second) ++violations;  // nearer one drawn earlier
    }
  }
  EXPECT_EQ(violations, 0) << what;
  EXPECT_GT(multi, rays / 4) << what << ": rays should cross several surfaces";
  return rays;
}

TEST(Extract, PaintersOrderAlongRandomRays) {
  std::mt19937 rng(17);
  const auto blobs = MakeHierarchy(4, BlobsField);
  const auto cayley = MakeHierarchy(4, CayleyField);
  int rays = 0;
  struct Case {
    const Hierarchy* h;
    std::vector<float> iso;
    double eps;
    View view;
    const char* name;
  };
  View outside, inside, ortho, ortho2;
  outside.eye = {-20, 35, 50};
  inside.eye = {7.3, 9.1, 8.2};  // inside the 16^3 cube
  ortho.orthographic = true;
  ortho.direction = {0.3, -0.5, 0.8};
  ortho2.orthographic = true;
  ortho2.direction = {-1, 0.2, -0.1};
  const std::vector<Case> cases = {
      {blobs.get(), {0.2f, 0.45f, 0.7f}, 0.0, outside, "blobs outside eps 0"},
      {blobs.get(), {0.2f, 0.45f, 0.7f}, 0.03, inside, "blobs inside eps .03"},
      {blobs.get(), {0.15f, 0.3f, 0.45f, 0.6f}, 0.1, ortho, "blobs ortho eps .1"},
      {cayley.get(), {-0.5f, 0.0f, 0.5f}, 0.05, outside, "cayley outside"},
      {cayley.get(), {-0.5f, 0.0f, 0.5f}, 0.2, inside, "cayley inside"},
      {cayley.get(), {-2.f, -0.5f, 0.0f, 0.5f, 2.f}, 0.0, ortho2, "cayley ortho"},
  };
  for (const auto& c : cases) {
    ExtractRequest r = Request(c.iso, c.eps, c.view.eye);
    r.view = c.view;
    const auto res = RunExtract(*c.h, r);
    ASSERT_GT(res.mesh.triangle_count(), 50u) << c.name;
    rays += CheckPaintersOrder(res.mesh, c.view, 1700, &rng, c.name);
  }
  EXPECT_GE(rays, 10000);
}

// The draw order is not an accident of the traversal: with --order none the same rays see
// violations, so the check above can fail.
TEST(Extract, UnorderedTraversalViolatesPaintersOrder) {
  const auto blobs = MakeHierarchy(4, BlobsField);
  ExtractRequest r = Request({0.2f, 0.45f, 0.7f}, 0.0, {-20, 35, 50});
  r.order = DrawOrder::kNone;
  const auto res = RunExtract(*blobs, r);
  std::mt19937 rng(1);
  std::uniform_int_distribution<size_t> pick(0, res.mesh.triangle_count() - 1);
  int violations = 0;
  for (int ray = 0; ray < 300; ++ray) {
    const size_t t = pick(rng);
    const float* p = &res.mesh.positions[3 * size_t(res.mesh.triangles[3 * t])];
    const glm::dvec3 dir = glm::normalize(glm::dvec3(p[0], p[1], p[2]) - r.view.eye);
    std::vector<std::pair<double, size_t>> hits;
    for (size_t i = 0; i < res.mesh.triangle_count(); ++i) {
      const double d = Hit(res.mesh, i, r.view.eye, dir);
      if (d > 0) hits.push_back({d, i});
    }
    std::sort(hits.begin(), hits.end());
    for (size_t i = 1; i < hits.size(); ++i)
      if (hits[i].first - hits[i - 1].first > 1e-6 && hits[i - 1].second < hits[i].second)
        ++violations;
  }
  EXPECT_GT(violations, 10);
}

// Brute-force marching tetrahedra over the reflected Kuhn triangulation, built directly from
// the grid (each unit cube split around the diagonal through its all-even corner).
std::multiset<TriKey> BruteForce(const Hierarchy& h, const std::vector<float>& iso) {
  std::multiset<TriKey> tris;
  const int n = h.n();
  for (int z = 0; z + 1 < n; ++z)
    for (int y = 0; y + 1 < n; ++y)
      for (int x = 0; x + 1 < n; ++x) {
        const glm::ivec3 c(x, y, z);
        const glm::ivec3 even(x + (x & 1), y + (y & 1), z + (z & 1));
        const glm::ivec3 step = (2 * c + glm::ivec3(1) - even) - even;  // +-1 per axis
        int axes[3] = {0, 1, 2};
        do {
          glm::ivec3 v[4];
          v[0] = even;
          for (int i = 0; i < 3; ++i) {
            v[i + 1] = v[i];
            v[i + 1][axes[i]] += step[axes[i]];
          }
          float f[4];
          for (int i = 0; i < 4; ++i) f[i] = h.sample(v[i].x, v[i].y, v[i].z);
          MarchTet(v, f, iso, &tris);
        } while (std::next_permutation(axes, axes + 3));
      }
  return tris;
}

TEST(Extract, EpsZeroEqualsBruteForceMarchingTetrahedra) {
  for (auto field : {CayleyField, BlobsField}) {
    const auto h = MakeHierarchy(4, field);
    const std::vector<float> iso = {-0.4f, 0.1f, 0.3f, 0.6f};  // ascending: surface == index
    const auto res = RunExtract(*h, Request(iso, 0.0, {40, -30, 20}));
    const std::multiset<TriKey> ours = MeshTriangles(res.mesh);
    const auto brute = BruteForce(*h, iso);
    EXPECT_GT(brute.size(), 1000u);
    EXPECT_EQ(ours.size(), brute.size());
    EXPECT_TRUE(ours == brute);
  }
}

// Isovalues equal to sample values (flat or integer data): the crossings on such a corner are one
// vertex, and no triangle without an area is emitted (on shells:65 at 0.25, 47,568 of 64,368
// had none); the surface stays closed, the count passes agree, and eps 0 still equals marching
// tetrahedra by brute force (which leaves such triangles out too).
// The apex of a double cone |x| + |y| - |z| lies on the grid at the isovalue 0, and every
// difference about it cancels its opposite: its normal came out (0, 0, 0).
TEST(Extract, ASymmetricSaddleCornerGetsANormal) {
  const auto h = MakeHierarchy(4, [](double x, double y, double z) {
    return float(std::abs(x) + std::abs(y) - std::abs(z));
  });
  for (double eps : {0.0, 0.05}) {
    const auto res = RunExtract(*h, Request({0.0f}, eps, {40, -30, 20}));
    const OrderedMesh& m = res.mesh;
    ASSERT_GT(m.triangle_count(), 0u);
    size_t without_normal = 0;
    for (size_t v = 0; v < m.vertex_count(); ++v) {
      const float* n = &m.normals[3 * v];
      without_normal += n[0] == 0 && n[1] == 0 && n[2] == 0;
    }
    EXPECT_EQ(without_normal, 0u) << "eps " << eps;
  }
}

// Isovalues on sample values, and a float step or a rounding off them: crossings that round
// onto a corner are moved off it (OffTheEnds). One step above the terrace 0.5, 64% of the
// triangles had two corners in one place; with the origin far from the grid, crossings up to a
// few 1e-6 of an edge from a corner round onto it. (Farther off, a crossing can round onto a
// corner on some coordinates only: the next test.)
TEST(Extract, IsovaluesOnOrNextToSampleValuesGiveNoTrianglesWithoutArea) {
  const auto h = MakeHierarchy(5, testing::TerracesField);
  struct Case {
    std::vector<float> iso;
    GridToWorld xf;
    std::string name;
  };
  const GridToWorld far{{1000, -2000, 500}, {0.5, 0.25, 1}};
  const Case cases[] = {
      {{0.5f, 0.75f}, kGrid, "on terrace values"},
      {{std::nextafter(0.5f, 1.0f), std::nextafter(0.75f, 0.0f)}, kGrid, "a float step off"},
      {{0.5f + 1e-6f, 0.75f - 1e-6f}, far, "1e-6 off, far origin"},
  };
  for (const Case& k : cases)
    for (double eps : {0.0, 0.1}) {
      const std::string what = k.name + ", eps " + std::to_string(eps);
      const auto res = RunExtract(*h, Request(k.iso, eps, {40, -30, 20}), k.xf);
      const OrderedMesh& m = res.mesh;
      EXPECT_GT(m.triangle_count(), 500u) << what;
      size_t without_area = 0;
      for (size_t t = 0; t < m.triangle_count(); ++t) {
        glm::dvec3 p[3];
        for (int i = 0; i < 3; ++i) {
          const float* q = &m.positions[3 * size_t(m.triangles[3 * t + i])];
          p[i] = {q[0], q[1], q[2]};
        }
        without_area += glm::length(glm::cross(p[1] - p[0], p[2] - p[0])) == 0;
      }
      EXPECT_EQ(without_area, 0u) << what;
      ExpectWatertight(m, what);
      auto counted = CountTriangles(*h, k.xf, Request(k.iso, eps, {40, -30, 20}), eps);
      ASSERT_TRUE(counted.ok());
      EXPECT_EQ(*counted, int64_t(m.triangle_count())) << what;
      if (eps == 0 && k.xf.origin == kGrid.origin) {
        EXPECT_TRUE(MeshTriangles(m) == BruteForce(*h, k.iso)) << what;
      }
    }
}

// Two or three float steps above the terrace 0.5 (grid units, origin 0): a crossing ~5e-7 of an
// edge from a corner keeps that offset on a small coordinate and loses it on a larger one, so
// the crossings of an axis edge and a diagonal edge from one corner are stored at one point that
// is not the corner. They were two vertices there, and the triangle through both had no area
// (brute-force marching tetrahedra leaves it out); also with the origin far from the grid, a few
// 1e-6 off the terraces.
TEST(Extract, IsovaluesAFewFloatStepsOffSampleValuesGiveNoTwoVerticesInOnePlace) {
  const auto h = MakeHierarchy(5, testing::TerracesField);
  const GridToWorld far{{1000, -2000, 500}, {0.5, 0.25, 1}};
  for (int steps : {2, 3, 20, 40, 80}) {
    float iso = 0.5f;
    for (int i = 0; i < steps; ++i) iso = std::nextafter(iso, 1.0f);
    const GridToWorld& xf = steps < 20 ? kGrid : far;
    const std::string what = std::to_string(steps) + " float steps above 0.5";
    const auto res = RunExtract(*h, Request({iso}, 0.0, {40, -30, 20}), xf);
    const OrderedMesh& m = res.mesh;
    EXPECT_GT(m.triangle_count(), 3000u) << what;
    size_t two_in_one_place = 0;
    for (size_t t = 0; t < m.triangle_count(); ++t) {
      glm::vec3 p[3];
      for (int i = 0; i < 3; ++i) {
        const float* q = &m.positions[3 * size_t(m.triangles[3 * t + i])];
        p[i] = {q[0], q[1], q[2]};
      }
      two_in_one_place += p[0] == p[1] || p[1] == p[2] || p[2] == p[0];
    }
    EXPECT_EQ(two_in_one_place, 0u) << what;
    ExpectWatertight(m, what);
    auto counted = CountTriangles(*h, xf, Request({iso}, 0.0, {40, -30, 20}), 0.0);
    ASSERT_TRUE(counted.ok());
    EXPECT_EQ(*counted, int64_t(m.triangle_count())) << what;
    if (steps < 20) {
      EXPECT_TRUE(MeshTriangles(m) == BruteForce(*h, {iso})) << what;
    }
  }
}

// A peak of 4 at grid point (8, 8, 8), its neighbours at +x and +y 0, its other 24 neighbours
// 3, and 0 elsewhere: a closed surface around the peak. Four float steps below 4 (grid units),
// the crossings towards the 0s are 2.4e-7 of an edge from the peak and round onto it, those
// towards the 3s (9.5e-7) do not. Only the crossings at +x and +y become the peak's vertex:
// two vertices of the small closed surface that no triangle joins are made one, and the edges
// both shared (to the crossings at +x+y, +x+y+z, +x+y-z) are each used by four triangles. Left
// on their edges (as without snapping) the surface is closed and manifold.
float PeakWithTwoLowNeighbours(double x, double y, double z) {
  const glm::ivec3 p(int(std::lround((x + 1) * 8)), int(std::lround((y + 1) * 8)),
                     int(std::lround((z + 1) * 8)));
  const glm::ivec3 off = p - glm::ivec3(8);
  if (off == glm::ivec3(0)) return 4;
  if (off == glm::ivec3(1, 0, 0) || off == glm::ivec3(0, 1, 0)) return 0;
  return glm::all(glm::lessThanEqual(glm::abs(off), glm::ivec3(1))) ? 3 : 0;
}

TEST(Extract, CrossingsNextToAPeakKeepTheSurfaceManifold) {
  const auto h = MakeHierarchy(4, PeakWithTwoLowNeighbours);
  float iso = 4;
  for (int i = 0; i < 4; ++i) iso = std::nextafter(iso, 0.0f);
  const auto res = RunExtract(*h, Request({iso}, 0.0, {40, -30, 20}));
  EXPECT_GT(res.mesh.triangle_count(), 40u);
  ExpectWatertight(res.mesh, "four float steps below a peak of 4");
  EXPECT_TRUE(MeshTriangles(res.mesh) == BruteForce(*h, {iso}));
}

// The bound that decides which components are placed exactly: every crossing whose stored
// position, or a coordinate of it along the edge, is one of its edge's ends' must have that end
// flagged by CornersNearIso, for grids up to 4097 points, origins up to 8e6 and spacings from
// 1e-3 to 1e3 (crossings from 1e-9 of an edge to 1 - 1e-9, edges along any lattice direction,
// long ones too).
TEST(Extract, EveryCrossingThatRoundsOntoACornerIsFlagged) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> unit(0, 1);
  auto pick = [&](int n) { return int(rng() % unsigned(n)); };
  int snapped = 0, checked = 0, partly = 0;
  for (int trial = 0; trial < 400000; ++trial) {
    extract_internal::Context c;
    const int last = 32 << pick(8);  // 32 .. 4096
    for (int a = 0; a < 3; ++a) {
      c.world_spacing[a] = float(std::pow(10.0, -3 + 6 * unit(rng)));
      c.world_origin[a] = float((unit(rng) - 0.5) * std::pow(10.0, 7 * unit(rng)));
    }
    c.snap_tau = extract_internal::SnapTau(c.world_origin, c.world_spacing, last);
    const int len = 1 << pick(4);
    glm::ivec3 d(0);
    while (d == glm::ivec3(0))
      for (int a = 0; a < 3; ++a) d[a] = (pick(3) - 1) * len;
    glm::ivec3 a;
    for (int i = 0; i < 3; ++i) a[i] = len + pick(last - 2 * len);
    const glm::ivec3 b = a + d;
    const float fa = float(unit(rng) * 4 - 2), fb = fa + float(0.01 + unit(rng) * 3);
    const double t = std::pow(10.0, -9 * unit(rng));
    const float iso = trial % 2 ? float(fa + t * (fb - fa)) : float(fb - t * (fb - fa));
    if (!(iso > fa && iso <= fb)) continue;
    ++checked;
    const extract_internal::PackedPoint pa = extract_internal::Pack(a),
                                        pb = extract_internal::Pack(b);
    const glm::vec3 q = extract_internal::EdgeCrossingWorld(c, pa, pb, fa, fb, iso);
    const float f[4] = {fa, fb, fa, fb};  // the least band a tetrahedron with this edge gets
    const unsigned near = extract_internal::CornersNearIso(f, iso, c.snap_tau);
    if (q == extract_internal::CornerWorld(c, pa)) {
      ++snapped;
      ASSERT_TRUE(near & 1u) << "trial " << trial << " t " << t;
    } else if (q == extract_internal::CornerWorld(c, pb)) {
      ++snapped;
      ASSERT_TRUE(near & 2u) << "trial " << trial << " t " << t;
    }
    // A coordinate that rounds onto an end's (OffTheEnds moves it) is flagged too.
    const glm::vec3 wa = extract_internal::CornerWorld(c, pa),
                    wb = extract_internal::CornerWorld(c, pb);
    for (int axis = 0; axis < 3; ++axis) {
      if (d[axis] == 0) continue;
      partly += q != wa && q != wb && (q[axis] == wa[axis] || q[axis] == wb[axis]);
      if (q[axis] == wa[axis]) {
        ASSERT_TRUE(near & 1u) << "trial " << trial << " axis " << axis;
      }
      if (q[axis] == wb[axis]) {
        ASSERT_TRUE(near & 2u) << "trial " << trial << " axis " << axis;
      }
    }
  }
  EXPECT_GT(checked, 300000);
  EXPECT_GT(snapped, 50000);
  EXPECT_GT(partly, 10000);
}

TEST(Extract, TriangleCountNeverGrowsWithEps) {
  const auto h = MakeHierarchy(5, BlobsField);
  int64_t previous = INT64_MAX;
  for (double eps = 0; eps < 2; eps = eps == 0 ? 1e-4 : eps * 1.6) {
    const auto res = RunExtract(*h, Request({0.2f, 0.5f, 0.8f}, eps, {50, 50, 50}));
    const int64_t count = int64_t(res.mesh.triangle_count());
    EXPECT_LE(count, previous) << "eps " << eps;
    EXPECT_EQ(res.stats.triangles, count);
    auto counted = CountTriangles(*h, kGrid, Request({0.2f, 0.5f, 0.8f}, eps, {50, 50, 50}), eps);
    ASSERT_TRUE(counted.ok());
    EXPECT_EQ(*counted, count);
    previous = count;
  }
}

TEST(Extract, IsovaluesOutsideTheDataRangeGiveAnEmptyMesh) {
  const auto h = MakeHierarchy(4, SphereField);  // values in [0, sqrt(3)]
  for (double eps : {0.0, 0.1}) {
    const auto res = RunExtract(*h, Request({-1.0f, 5.0f}, eps, {1, 2, 3}));
    EXPECT_EQ(res.mesh.triangle_count(), 0u);
    EXPECT_EQ(res.mesh.vertex_count(), 0u);
  }
}

TEST(Extract, SameOutputForOneAndTwoThreadsAndForOrderNoneAsASet) {
  const auto h = MakeHierarchy(5, CayleyField);
  ExtractRequest r = Request({-0.5f, 0.0f, 0.5f}, 0.01, {-10, 50, 20});
  r.threads = 1;
  const auto one = RunExtract(*h, r);
  r.threads = 2;
  const auto two = RunExtract(*h, r);
  EXPECT_GT(one.stats.subtrees, 8);
  EXPECT_EQ(one.mesh.positions, two.mesh.positions);
  EXPECT_EQ(one.mesh.normals, two.mesh.normals);
  EXPECT_EQ(one.mesh.triangles, two.mesh.triangles);
  EXPECT_EQ(one.mesh.surface, two.mesh.surface);
  r.order = DrawOrder::kNone;
  const auto none = RunExtract(*h, r);
  auto as_set = [](const OrderedMesh& m) {
    std::multiset<std::array<float, 10>> s;
    for (size_t t = 0; t < m.triangle_count(); ++t) {
      std::array<std::array<float, 3>, 3> v;
      for (int i = 0; i < 3; ++i)
        for (int a = 0; a < 3; ++a) v[i][a] = m.positions[3 * size_t(m.triangles[3 * t + i]) + a];
      std::sort(v.begin(), v.end());
      s.insert({float(m.surface[t]), v[0][0], v[0][1], v[0][2], v[1][0], v[1][1], v[1][2], v[2][0],
                v[2][1], v[2][2]});
    }
    return s;
  };
  EXPECT_EQ(none.mesh.triangle_count(), one.mesh.triangle_count());
  EXPECT_TRUE(as_set(none.mesh) == as_set(one.mesh));
  EXPECT_NE(none.mesh.triangles, one.mesh.triangles);
}

// An eye ever farther away along -d orders every separating plane as the view direction d
// does: perspective at 1e6 (integer plane tests near the eye's side), 1e13 and 1e15 (plane sides
// past the +-2^40 clamp, on both sides, the eye still seen in perspective), 1e17 and 1e30 (past
// 2^52: seen from infinity) and 1e300 must draw exactly what orthographic along d draws. d is
// generic: no plane normal (axis or face diagonal) is perpendicular to it.
TEST(Extract, FarPerspectiveEyeDrawsAsOrthographic) {
  const auto h = MakeHierarchy(5, CayleyField);
  const glm::dvec3 d = glm::normalize(glm::dvec3(0.31, -0.52, 0.79));
  ExtractRequest ortho = Request({0.0f}, 0.004, {0, 0, 0});
  ortho.view.orthographic = true;
  ortho.view.direction = d;
  const auto want = RunExtract(*h, ortho);
  ASSERT_GT(want.mesh.triangle_count(), 1000u);
  for (double far : {1e6, 1e13, 1e15, 1e17, 1e30, 1e300}) {
    const auto got = RunExtract(*h, Request({0.0f}, 0.004, glm::dvec3(16.0) - far * d));
    EXPECT_EQ(got.mesh.triangles, want.mesh.triangles) << far;
    EXPECT_EQ(got.mesh.positions, want.mesh.positions) << far;
  }
  // Finite eyes whose grid coordinates overflow (world spacing 1e-200; an eye at 1e307 with
  // spacing 1/32): the plane sides would turn to +-inf or NaN and the frame come out
  // mis-ordered; they draw as the orthographic view does.
  GridToWorld tiny;
  tiny.spacing = glm::dvec3(1e-200);
  const auto overflow = RunExtract(*h, Request({0.0f}, 0.004, -1e200 * d), tiny);
  EXPECT_EQ(overflow.mesh.triangles, RunExtract(*h, ortho, tiny).mesh.triangles);
  GridToWorld fine;
  fine.spacing = glm::dvec3(1.0 / 32);
  const auto huge = RunExtract(*h, Request({0.0f}, 0.004, -1e307 * d), fine);
  EXPECT_EQ(huge.mesh.triangles, RunExtract(*h, ortho, fine).mesh.triangles);
}

// An orthographic view is ordered by its direction however far the grid lies from the world's
// origin (here 1e17 grid steps: the eye position an orthographic view leaves at the origin
// would be past 2^52 of them): the opposite direction draws in another order, and each
// direction as it does for a grid at the origin.
TEST(Extract, OrthographicOrderFollowsTheDirectionForAGridFarFromTheOrigin) {
  const auto h = MakeHierarchy(5, CayleyField);
  const glm::dvec3 d = glm::normalize(glm::dvec3(0.31, -0.52, 0.79));
  GridToWorld far;
  far.origin = glm::dvec3(1e17, -1e17, 1e17);
  GridToWorld near;
  near.origin = glm::dvec3(1, -1, 1);
  std::vector<std::vector<uint32_t>> orders;
  for (const glm::dvec3& dir : {d, -d}) {
    ExtractRequest ortho = Request({0.0f}, 0.004, {0, 0, 0});
    ortho.view.orthographic = true;
    ortho.view.direction = dir;
    const auto at_origin = RunExtract(*h, ortho, near);
    const auto far_away = RunExtract(*h, ortho, far);
    ASSERT_GT(at_origin.mesh.triangle_count(), 1000u);
    EXPECT_EQ(far_away.mesh.triangle_count(), at_origin.mesh.triangle_count());
    EXPECT_EQ(far_away.mesh.surface, at_origin.mesh.surface);
    orders.push_back(far_away.mesh.triangles);
  }
  EXPECT_NE(orders[0], orders[1]);
}

TEST(Extract, BudgetFindsTheSmallestEpsThatFits) {
  const auto h = MakeHierarchy(5, BlobsField);
  for (int64_t budget : {500, 3000, 20000}) {
    ExtractRequest r = Request({0.2f, 0.5f, 0.8f}, 0, {50, 50, 50});
    r.budget = budget;
    const auto res = RunExtract(*h, r);
    EXPECT_LE(int64_t(res.mesh.triangle_count()), budget);
    EXPECT_GT(res.stats.budget_passes, 0);
    if (res.stats.eps_used > 0) {
      auto finer = CountTriangles(*h, kGrid, r, res.stats.eps_used * 0.99);
      ASSERT_TRUE(finer.ok());
      EXPECT_GT(*finer, budget) << "a smaller eps would also have fit";
    }
  }
}

// An orthographic direction is a sense, not a length: 1e307 per component (which overflowed
// once divided by a small spacing) draws what (1, 1, 1) draws, byte for byte.
TEST(Extract, HugeViewDirectionDrawsAsItsUnitDirection) {
  const auto h = MakeHierarchy(4, BlobsField);
  const GridToWorld fine{glm::dvec3(-1.0), glm::dvec3(0.03125)};
  ExtractRequest unit = Request({0.2f, 0.5f}, 0, {0, 0, 0});
  unit.view.orthographic = true;
  unit.view.direction = {1, 1, 1};
  ExtractRequest huge = unit;
  huge.view.direction = {1e307, 1e307, 1e307};
  const auto a = RunExtract(*h, unit, fine), b = RunExtract(*h, huge, fine);
  EXPECT_GT(a.mesh.triangle_count(), 0u);
  EXPECT_EQ(a.mesh.triangles, b.mesh.triangles);
  huge.view.direction = {1e308, 1, 1};
  unit.view.direction = {1, 1e-308, 1e-308};
  EXPECT_EQ(RunExtract(*h, unit, fine).mesh.triangles, RunExtract(*h, huge, fine).mesh.triangles);
  // Subnormal components are a direction too (their squares underflow to a zero length).
  ExtractRequest tiny = unit;
  tiny.view.direction = {1e-320, 1e-320, 1e-320};
  unit.view.direction = {1, 1, 1};
  EXPECT_EQ(RunExtract(*h, tiny, fine).mesh.triangles, a.mesh.triangles);
}

// A budget larger than any frame (up to the largest int64) means everything: the eps 0 mesh.
TEST(Extract, BudgetPastAnyFrameGivesTheFullResolutionMesh) {
  const auto h = MakeHierarchy(4, BlobsField);
  ExtractRequest r = Request({0.2f, 0.5f}, 0, {50, 50, 50});
  const auto full = RunExtract(*h, r);
  for (int64_t budget :
       {int64_t{1} << 40, (int64_t{1} << 61) + 1, std::numeric_limits<int64_t>::max()}) {
    r.budget = budget;
    const auto res = RunExtract(*h, r);
    EXPECT_EQ(res.stats.eps_used, 0) << budget;
    EXPECT_EQ(res.mesh.triangles, full.mesh.triangles) << budget;
  }
}

// A budget of 3000 triangles whose eps is remembered in `memo`.
ExtractRequest RememberingBudgetRequest(std::vector<float> isovalues, BudgetMemo* memo) {
  ExtractRequest r = Request(std::move(isovalues), 0, {50, 50, 50});
  r.budget = 3000;
  r.budget_memo = memo;
  return r;
}

// A cancelled or late request stops inside the budget search too (not only between the
// subtrees of the final extraction), and its unfinished search is not remembered.
TEST(Extract, BudgetSearchStopsWhenCancelledOrPastItsDeadline) {
  const auto h = MakeHierarchy(5, BlobsField);
  BudgetMemo memo;
  const ExtractRequest r = RememberingBudgetRequest({0.2f, 0.5f}, &memo);
  std::atomic<bool> cancel{true};
  ExtractObserver cancelled;
  cancelled.cancel = &cancel;
  auto a = Extract(*h, kGrid, r, &cancelled);
  ASSERT_FALSE(a.ok());
  EXPECT_EQ(a.status().code(), absl::StatusCode::kCancelled) << a.status();
  ExtractObserver late;
  late.deadline = std::chrono::steady_clock::now() - std::chrono::milliseconds(1);
  auto b = Extract(*h, kGrid, r, &late);
  ASSERT_FALSE(b.ok());
  EXPECT_EQ(b.status().code(), absl::StatusCode::kDeadlineExceeded) << b.status();
  EXPECT_FALSE(memo.Find(r.isovalues, r.budget).has_value());
  ExtractObserver in_time;
  in_time.deadline = std::chrono::steady_clock::now() + std::chrono::hours(1);
  auto c = Extract(*h, kGrid, r, &in_time);
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_GT(c->stats.budget_passes, 0);
  EXPECT_TRUE(memo.Find(r.isovalues, r.budget).has_value());
}

// The eps for a budget does not depend on the view, so a memo answers later views without
// counting passes, and gives exactly what a new search gives.
TEST(Extract, BudgetMemoSkipsTheSearchForLaterViews) {
  const auto h = MakeHierarchy(5, BlobsField);
  BudgetMemo memo;
  const ExtractRequest r = RememberingBudgetRequest({0.5f, 0.2f}, &memo);
  const auto first = RunExtract(*h, r);
  EXPECT_GT(first.stats.budget_passes, 0);

  ExtractRequest other_view = r;
  other_view.view.eye = {-30, 12, 70};
  const auto remembered = RunExtract(*h, other_view);
  EXPECT_EQ(remembered.stats.budget_passes, 0);
  EXPECT_EQ(remembered.stats.eps_used, first.stats.eps_used);
  other_view.budget_memo = nullptr;
  const auto searched = RunExtract(*h, other_view);
  EXPECT_EQ(searched.stats.eps_used, remembered.stats.eps_used);
  EXPECT_EQ(searched.mesh.triangles, remembered.mesh.triangles);

  ExtractRequest reordered = r;  // the same isovalue set in another order hits too
  reordered.isovalues = {0.2f, 0.5f};
  EXPECT_EQ(RunExtract(*h, reordered).stats.budget_passes, 0);
  ExtractRequest new_budget = r;
  new_budget.budget = 1000;
  EXPECT_GT(RunExtract(*h, new_budget).stats.budget_passes, 0);
  ExtractRequest new_iso = r;
  new_iso.isovalues = {0.5f};
  EXPECT_GT(RunExtract(*h, new_iso).stats.budget_passes, 0);
}

// The output is reserved for the frame the budget search counted, not for the budget: a budget
// of 2^24 triangles must not reserve ~400 MB for a frame of a few thousand.
TEST(Extract, BudgetSearchReservesTheFrameNotTheBudget) {
  const auto h = MakeHierarchy(5, BlobsField);
  ExtractRequest r = Request({0.2f, 0.5f, 0.8f}, 0, {50, 50, 50});
  r.budget = int64_t{1} << 24;
  const auto res = RunExtract(*h, r);
  EXPECT_EQ(res.stats.eps_used, 0.0);  // everything fits
  const size_t t = res.mesh.triangle_count();
  ASSERT_GT(t, 1000u);
  EXPECT_LT(res.mesh.triangles.capacity(), 2 * 3 * t);
  EXPECT_LT(res.mesh.surface.capacity(), 2 * t);
  EXPECT_LT(res.mesh.positions.capacity(), 2 * 3 * (t / 2 + 1024));
}

TEST(Extract, WorldPositionsFollowSpacingAndOrigin) {
  const auto h = MakeHierarchy(4, SphereField);
  const GridToWorld xf{{-1, -2, -3}, {0.5, 0.25, 2.0}};
  ExtractRequest r = Request({0.7f}, 0.0, xf.origin + xf.spacing * glm::dvec3(40, 8, 8));
  const auto grid = RunExtract(*h, Request({0.7f}, 0.0, {40, 8, 8}));
  const auto world = RunExtract(*h, r, xf);
  // Same view in both spaces: the same traversal, so the same vertices in the same order (quad
  // diagonals may differ: they follow world-space lengths).
  ASSERT_EQ(grid.mesh.vertex_count(), world.mesh.vertex_count());
  ASSERT_EQ(grid.mesh.surface, world.mesh.surface);
  for (size_t i = 0; i < grid.mesh.vertex_count(); ++i)
    for (int a = 0; a < 3; ++a)
      EXPECT_NEAR(world.mesh.positions[3 * i + a],
                  xf.origin[a] + xf.spacing[a] * grid.mesh.positions[3 * i + a], 1e-5);
}

TEST(Extract, BadRequestsGiveClearErrors) {
  const auto h = MakeHierarchy(3, SphereField);
  auto code = [&](ExtractRequest r) { return Extract(*h, kGrid, r).status(); };
  ExtractRequest ok = Request({0.5f}, 0.1, {0, 0, 0});
  EXPECT_TRUE(code(ok).ok());
  ExtractRequest r = ok;
  r.eps = -1;
  EXPECT_EQ(code(r).code(), absl::StatusCode::kInvalidArgument);
  r.eps = std::nan("");
  EXPECT_EQ(code(r).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(code(r).message().find("eps"), std::string::npos);
  r = ok;
  r.isovalues.clear();
  for (int i = 0; i < 16; ++i) r.isovalues.push_back(0.05f * float(i + 1));
  EXPECT_TRUE(code(r).ok()) << code(r);  // 16 are allowed: the limit is checked at its edge
  r.isovalues.push_back(0.9f);
  EXPECT_EQ(code(r).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(code(r).message().find("16"), std::string::npos);
  r = ok;
  r.threads = -1;
  EXPECT_EQ(code(r).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(code(r).message().find("threads"), std::string::npos);
  r = ok;
  r.isovalues.clear();
  EXPECT_EQ(code(r).code(), absl::StatusCode::kInvalidArgument);
  r = ok;
  r.isovalues = {std::nanf("")};
  EXPECT_EQ(code(r).code(), absl::StatusCode::kInvalidArgument);
  r = ok;
  r.isovalues = {0.5f, 0.25f, 0.5f};
  EXPECT_EQ(code(r).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(code(r).message().find("twice"), std::string::npos);
  r = ok;
  r.view.orthographic = true;
  r.view.direction = {0, 0, 0};
  EXPECT_EQ(code(r).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(code(r).message().find("direction"), std::string::npos);
  r = ok;
  r.budget = -5;
  EXPECT_EQ(code(r).code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace isostream

namespace isostream {
namespace {

// Streaming: the observer sees contiguous, growing prefixes whose vertices already exist, and
// the prefixes add up to the final mesh; every vertex is used (no duplicates left by the join).
TEST(ExtractStreaming, ObserverSeesOrderedPrefixesAndCancelStops) {
  const auto h = testing::MakeHierarchy(5, testing::BlobsField);
  ExtractRequest r = Request({0.2f, 0.5f, 0.8f}, 0.001, {50, 40, 30});
  size_t expected_first = 0, calls = 0;
  std::vector<uint32_t> seen;
  ExtractObserver observer;
  observer.on_ready = [&](const OrderedMesh& m, size_t first, size_t end) {
    EXPECT_EQ(first, expected_first);
    EXPECT_GE(end, first);
    for (size_t i = 3 * first; i < 3 * end; ++i) {
      EXPECT_LT(m.triangles[i], m.vertex_count());
      seen.push_back(m.triangles[i]);
    }
    expected_first = end;
    ++calls;
  };
  auto res = Extract(*h, kGrid, r, &observer);
  ASSERT_TRUE(res.ok());
  EXPECT_GT(calls, 10u);
  EXPECT_EQ(expected_first, res->mesh.triangle_count());
  EXPECT_EQ(seen, res->mesh.triangles);
  std::vector<char> used(res->mesh.vertex_count(), 0);
  for (uint32_t v : res->mesh.triangles) used[v] = 1;
  EXPECT_EQ(std::count(used.begin(), used.end(), 0), 0) << "unreferenced vertices";

  std::atomic<bool> cancel{true};
  ExtractObserver stop;
  stop.cancel = &cancel;
  EXPECT_EQ(Extract(*h, kGrid, r, &stop).status().code(), absl::StatusCode::kCancelled);
}

}  // namespace
}  // namespace isostream
