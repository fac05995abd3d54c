// Volumes smaller than the hierarchy's cube, prepared as the CLI and the daemon prepare them:
// leaves that straddle the data box are clipped there. The count passes count what the emitter
// appends (so a budget bounds the frame, and every eps `info` prints gives its count back), no
// vertex is left unused, no triangle has two corners in one place, and normals stay finite.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "mesh_test_meshes.h"
#include "server/extract/data_box_clip.h"
#include "server/extract/extractor.h"
#include "server/hierarchy/prepared_volume.h"
#include "shared/mesh_validate.h"

namespace isostream {
namespace {

struct RawVolume {
  std::string name;
  int dims[3];
  std::vector<float> values;  // x fastest
};

// Integer values 0..4 (crossings land on grid points and on the box's faces exactly).
RawVolume RandomIntegers(int nx, int ny, int nz, unsigned seed) {
  RawVolume v{
      "integers " + std::to_string(nx) + "x" + std::to_string(ny) + "x" + std::to_string(nz),
      {nx, ny, nz},
      {}};
  std::mt19937 rng(seed);
  for (int i = 0; i < nx * ny * nz; ++i) v.values.push_back(float(rng() % 5));
  return v;
}

RawVolume Smooth(int nx, int ny, int nz, double fx = 0.21, double fy = 0.17, double fz = 0.23) {
  RawVolume v{"smooth " + std::to_string(nx) + "x" + std::to_string(ny) + "x" + std::to_string(nz),
              {nx, ny, nz},
              {}};
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x)
        v.values.push_back(float(std::sin(fx * x) + std::cos(fy * y) * std::sin(fz * z)));
  return v;
}

// Zero but for a few integer values at the +x face of the box: at iso 3 and eps 0.5 a clipped
// crossing falls between two vertices whose normals are opposite (their blend was NaN).
RawVolume OppositeNormalsAtTheBox() {
  RawVolume v{"opposite normals", {7, 7, 12}, std::vector<float>(7 * 7 * 12, 0.0f)};
  const int set[][4] = {{6, 4, 9, 3},  {6, 3, 10, 1}, {5, 4, 10, 4}, {6, 4, 10, 3}, {6, 5, 10, 2},
                        {6, 3, 11, 4}, {5, 4, 11, 1}, {6, 4, 11, 3}, {6, 5, 11, 2}};
  for (const auto& s : set) v.values[size_t(s[0] + 7 * (s[1] + 7 * s[2]))] = float(s[3]);
  return v;
}

PreparedVolume Prepare(const RawVolume& raw, const testing::ScratchDir& dir) {
  const std::string path = dir.File("v.f32");
  FILE* f = std::fopen(path.c_str(), "wb");
  EXPECT_NE(f, nullptr);
  if (f) {
    std::fwrite(raw.values.data(), sizeof(float), raw.values.size(), f);
    std::fclose(f);
  }
  const std::string spec = "raw:" + path + ":" + std::to_string(raw.dims[0]) + "x" +
                           std::to_string(raw.dims[1]) + "x" + std::to_string(raw.dims[2]) +
                           ":float32";
  auto prepared =
      PrepareVolume(spec, VolumeLimits{}, HierarchyCacheOptions{}, HierarchyBuildOptions{});
  EXPECT_TRUE(prepared.ok()) << prepared.status();
  return prepared.ok() ? std::move(*prepared) : PreparedVolume{};
}

ExtractRequest Request(const std::vector<float>& iso, double eps, int64_t budget) {
  ExtractRequest r;
  r.isovalues = iso;
  r.eps = eps;
  r.budget = budget;
  r.view.eye = {-9.0, 31.0, 17.0};
  return r;
}

void ExpectCleanMesh(const OrderedMesh& m, const RawVolume& raw, const GridToWorld& xf,
                     const std::string& what) {
  EXPECT_TRUE(ValidateMesh(m).ok()) << what << ": " << ValidateMesh(m);
  std::vector<char> used(m.vertex_count(), 0);
  for (uint32_t i : m.triangles) used[i] = 1;
  size_t unused = 0, coincident = 0, outside = 0, bad_normals = 0;
  for (char u : used) unused += !u;
  for (size_t t = 0; t < m.triangle_count(); ++t) {
    const float* p[3];
    for (int i = 0; i < 3; ++i) p[i] = &m.positions[3 * size_t(m.triangles[3 * t + i])];
    auto same = [](const float* a, const float* b) {
      return a[0] == b[0] && a[1] == b[1] && a[2] == b[2];
    };
    coincident += same(p[0], p[1]) || same(p[1], p[2]) || same(p[0], p[2]);
  }
  for (size_t v = 0; v < m.vertex_count(); ++v) {
    for (int a = 0; a < 3; ++a) {  // the box, in single precision as positions are
      const float lo = float(xf.origin[a]);
      const float hi = float(xf.origin[a]) + float(xf.spacing[a]) * float(raw.dims[a] - 1);
      outside += !(m.positions[3 * v + a] >= lo && m.positions[3 * v + a] <= hi);
    }
    const float* n = &m.normals[3 * v];
    const double length =
        std::sqrt(double(n[0]) * n[0] + double(n[1]) * n[1] + double(n[2]) * n[2]);
    bad_normals += !(std::abs(length - 1) < 1e-4 || length == 0);
  }
  EXPECT_EQ(unused, 0u) << what;
  EXPECT_EQ(coincident, 0u) << what;
  EXPECT_EQ(outside, 0u) << what;
  EXPECT_EQ(bad_normals, 0u) << what;
}

// The clipping itself: a crossing of the box's face between ends with opposite normals (their
// blend is zero) takes the normal of the end inside the box, never that of the end outside it;
// elsewhere the blend, normalized. The crossings are on the face exactly, and made by the clip.
TEST(ExtractDataBox, AClippedCrossingTakesItsNormalFromInside) {
  using extract_internal::ClipVertex;
  extract_internal::Context c;
  c.world_origin = glm::vec3(0.0f);
  c.world_spacing = glm::vec3(1.0f);
  c.data_max = glm::ivec3(4, 8, 8);  // the face x = 4
  ClipVertex poly[9] = {{glm::vec3(3, 1, 1), glm::dvec3(1, 0, 0), 0},
                        {glm::vec3(5, 1, 1), glm::dvec3(-1, 0, 0), 1},
                        {glm::vec3(3, 3, 1), glm::dvec3(0, 1, 0), 2}};
  ASSERT_EQ(extract_internal::ClipToDataBox(c, poly, 3), 4);
  int made = 0;
  for (int i = 0; i < 4; ++i) {
    if (poly[i].id != EdgeVertexTable::kMissing) continue;
    ++made;
    EXPECT_EQ(poly[i].p.x, 4.0f);
    if (poly[i].p == glm::vec3(4, 1, 1)) {
      EXPECT_EQ(poly[i].n, glm::dvec3(1, 0, 0));  // opposite ends: the inside one's
    } else {
      EXPECT_EQ(poly[i].p, glm::vec3(4, 2, 1));
      EXPECT_NEAR(poly[i].n.x, -std::sqrt(0.5), 1e-12);
      EXPECT_NEAR(poly[i].n.y, std::sqrt(0.5), 1e-12);
    }
  }
  EXPECT_EQ(made, 2);
}

// The surfaces are closed but where the data box cuts them: every half-edge has its reverse in
// another triangle of its surface, once, unless both its ends lie on one face of the box. A
// vertex the clipping made once per triangle (two at one place) left the edges through it open.
// For volumes whose samples miss the isovalues (where 3 corners of a face are at the isovalue,
// both tetrahedra beside it may draw it).
void ExpectClosedButAtTheBox(const OrderedMesh& m, const RawVolume& raw, const GridToWorld& xf,
                             const std::string& what) {
  std::map<std::tuple<int, uint32_t, uint32_t>, int> directed;
  for (size_t t = 0; t < m.triangle_count(); ++t)
    for (int e = 0; e < 3; ++e)
      ++directed[{m.surface[t], m.triangles[3 * t + e], m.triangles[3 * t + (e + 1) % 3]}];
  auto on_one_face = [&](uint32_t a, uint32_t b) {
    for (int axis = 0; axis < 3; ++axis) {
      const float lo = float(xf.origin[axis]);
      const float hi = float(xf.origin[axis]) + float(xf.spacing[axis]) * float(raw.dims[axis] - 1);
      const float pa = m.positions[3 * size_t(a) + axis], pb = m.positions[3 * size_t(b) + axis];
      if ((pa == lo && pb == lo) || (pa == hi && pb == hi)) return true;
    }
    return false;
  };
  size_t open = 0;
  for (const auto& [edge, count] : directed) {
    const auto& [s, a, b] = edge;
    const auto back = directed.find({s, b, a});
    const bool matched = count == 1 && back != directed.end() && back->second == 1;
    open += !matched && !on_one_face(a, b);
  }
  EXPECT_EQ(open, 0u) << what << ": " << open << " of " << directed.size()
                      << " half-edges open inside the box";
}

// Extracts at eps, checks that the count pass gives the emitted count back and that the mesh is
// clean (ExpectCleanMesh), and returns the count (0 after a failure).
int64_t CountedExtraction(const PreparedVolume& v, const RawVolume& raw, const GridToWorld& xf,
                          const std::vector<float>& iso, double eps, const std::string& what) {
  const auto res = Extract(*v.hierarchy, xf, Request(iso, eps, 0));
  EXPECT_TRUE(res.ok()) << what << ": " << res.status();
  const auto counted = CountTriangles(*v.hierarchy, xf, Request(iso, eps, 0), eps);
  EXPECT_TRUE(counted.ok()) << what;
  if (!res.ok() || !counted.ok()) return 0;
  EXPECT_EQ(*counted, int64_t(res->mesh.triangle_count())) << what;
  ExpectCleanMesh(res->mesh, raw, xf, what);
  if (raw.name.rfind("smooth", 0) == 0) ExpectClosedButAtTheBox(res->mesh, raw, xf, what);
  return *counted;
}

TEST(ExtractDataBox, CountsWhatItEmitsAndBudgetsBoundTheFrame) {
  testing::ScratchDir dir;
  // (30x22x10 at iso -0.3, 0.6, eps 0.3 counted 1550 triangles and emitted 1551 when the counts
  // clipped each triangle in the other corner order.)
  std::vector<RawVolume> volumes = {RandomIntegers(19, 12, 2, 5), RandomIntegers(9, 14, 6, 8),
                                    Smooth(23, 9, 14), OppositeNormalsAtTheBox(),
                                    Smooth(30, 22, 10, 0.1552, 0.398, 0.0936)};
  // More odd shapes and frequencies.
  std::mt19937 rng(12);
  for (int i = 0; i < 8; ++i) {
    auto f = [&] { return 0.05 + 0.4 * double(rng() % 1000) / 1000.0; };
    const int nx = 2 + int(rng() % 40), ny = 2 + int(rng() % 40), nz = 2 + int(rng() % 20);
    const double fx = f(), fy = f(), fz = f();
    volumes.push_back(Smooth(nx, ny, nz, fx, fy, fz));
  }
  for (const RawVolume& raw : volumes) {
    const PreparedVolume v = Prepare(raw, dir);
    ASSERT_NE(v.hierarchy, nullptr) << raw.name;
    // Unit voxels at the origin, and odd ones elsewhere (crossings then round differently).
    GridToWorld odd;
    odd.spacing = {0.37, 1.9, 0.83};
    odd.origin = {-3.1, 7.7, 0.4};
    for (const GridToWorld& xf : {v.grid_to_world, odd})
      for (const std::vector<float>& iso :
           {std::vector<float>{0.5f, 3.0f}, {-0.3f, 0.6f}, {3.0f}}) {
        int64_t largest = 0;
        for (double eps : {0.0, 0.02, 0.1, 0.3, 0.5, 0.7, 1.5, 3.0}) {
          const std::string what = raw.name + " spacing " + std::to_string(xf.spacing.x) + " iso " +
                                   std::to_string(iso[0]) + ".. eps " + std::to_string(eps);
          largest = std::max(largest, CountedExtraction(v, raw, xf, iso, eps, what));
        }
        for (int64_t budget : {largest / 7, largest / 3, largest / 2}) {
          if (budget <= 0) continue;
          const std::string what = raw.name + " spacing " + std::to_string(xf.spacing.x) + " iso " +
                                   std::to_string(iso[0]) + ".. budget " + std::to_string(budget);
          const auto res = Extract(*v.hierarchy, xf, Request(iso, 0, budget));
          ASSERT_TRUE(res.ok()) << what << ": " << res.status();
          EXPECT_LE(int64_t(res->mesh.triangle_count()), budget) << what;
          ExpectCleanMesh(res->mesh, raw, xf, what);
        }
      }
  }
}

// Isovalues on, and one to three float steps off, integer samples, in volumes that need
// clipping at the data box, under unit voxels and under spacings from 1e-3 to 7 per axis with
// origins up to 2e5 (crossings round onto corners on some coordinates or all): counts equal
// emitted triangles at every eps tried, at every eta code (the count curve against single
// counts), and within budgets; no triangle has two corners in one place.
TEST(ExtractDataBox, IsovaluesNextToIntegerSamplesCountWhatTheyEmit) {
  testing::ScratchDir dir;
  auto steps = [](float v, int n) {
    for (int i = 0; i < std::abs(n); ++i) v = std::nextafter(v, n > 0 ? 10.0f : -10.0f);
    return v;
  };
  const std::vector<float> iso = {steps(1, 1), steps(2, -2), 2, steps(3, 3), steps(2, 1)};
  GridToWorld far, fine;
  far.origin = {1e5, -2e5, 5e4};
  far.spacing = {0.3, 7, 0.3};
  fine.origin = {-700, 300, 1000};
  fine.spacing = {1e-3, 0.3, 7};
  for (const RawVolume& raw : {RandomIntegers(19, 12, 5, 5), RandomIntegers(9, 14, 6, 8)}) {
    const PreparedVolume v = Prepare(raw, dir);
    ASSERT_NE(v.hierarchy, nullptr) << raw.name;
    for (const GridToWorld& xf : {v.grid_to_world, far, fine}) {
      const std::string name = raw.name + " spacing " + std::to_string(xf.spacing.x);
      int64_t largest = 0;
      for (double eps : {0.0, 0.1, 0.5, 1.5}) {
        const std::string what = name + " eps " + std::to_string(eps);
        largest = std::max(largest, CountedExtraction(v, raw, xf, iso, eps, what));
      }
      EXPECT_GT(largest, 500) << name;
      const uint32_t first = EtaCodeAtLeast(1e-3), last = CoarsestEtaCode(*v.hierarchy);
      const auto curve =
          CountTrianglesPerEtaCode(*v.hierarchy, xf, Request(iso, 0, 0), first, last);
      ASSERT_TRUE(curve.ok()) << name;
      for (uint32_t code = first; code <= last; code += 97) {
        const double eps = EtaCodeEps(code);
        const auto counted = CountTriangles(*v.hierarchy, xf, Request(iso, eps, 0), eps);
        ASSERT_TRUE(counted.ok());
        EXPECT_EQ((*curve)[code - first], *counted) << name << " code " << code;
      }
      for (int64_t budget : {largest / 5, largest / 2}) {
        const auto res = Extract(*v.hierarchy, xf, Request(iso, 0, budget));
        ASSERT_TRUE(res.ok()) << name;
        EXPECT_LE(int64_t(res->mesh.triangle_count()), budget) << name;
        ExpectCleanMesh(res->mesh, raw, xf, name + " budget " + std::to_string(budget));
      }
    }
  }
}

}  // namespace
}  // namespace isostream
