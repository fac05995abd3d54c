// Built-in generators: samples equal the documented closed forms, and the facts later stages
// rely on (plateau values, atom count, value ranges, determinism) hold.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>
#include <vector>

#include "server/volume/generators.h"
#include "server/volume/load.h"
#include "server/volume/padding.h"

namespace isostream {
namespace {

VolumePtr Load(const std::string& spec) {
  absl::StatusOr<VolumePtr> v = LoadVolume(spec);
  EXPECT_TRUE(v.ok()) << v.status();
  return v.ok() ? *v : nullptr;
}

float Sample(const Volume& v, int i, int j, int k) {
  return v.grid->getConstAccessor().getValue(
      openvdb::Coord(v.index_min[0] + i, v.index_min[1] + j, v.index_min[2] + k));
}

double Coord(int i, int n) { return -1.0 + 2.0 * i / (n - 1); }

// Every sample equals F at its world position (as float), and min/max are the sample extremes.
template <typename F>
void ExpectSamplesMatch(const Volume& v, F f, double tolerance) {
  const int n = v.dims[0];
  float lo = INFINITY, hi = -INFINITY;
  auto acc = v.grid->getConstAccessor();
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const float s = acc.getValue(openvdb::Coord(i, j, k));
        const double expected = f(Coord(i, n), Coord(j, n), Coord(k, n));
        ASSERT_NEAR(s, static_cast<float>(expected), tolerance)
            << "at " << i << "," << j << "," << k;
        lo = std::min(lo, s);
        hi = std::max(hi, s);
      }
  EXPECT_EQ(v.min_value, lo);
  EXPECT_EQ(v.max_value, hi);
}

TEST(VolumeGenerators, NamesAreListed) {
  std::set<std::string> names;
  for (const char* const* g = GeneratorNames(); *g != nullptr; ++g) names.insert(*g);
  EXPECT_EQ(names, (std::set<std::string>{"cayley", "buckyball", "sphere", "shells", "noise"}));
}

TEST(VolumeGenerators, CayleyGeometryAndValues) {
  VolumePtr v = Load("cayley:9");
  ASSERT_NE(v, nullptr);
  EXPECT_EQ(v->name, "cayley:9");
  EXPECT_EQ(v->grid->getName(), "cayley");
  EXPECT_EQ(v->dims, (std::array<int, 3>{9, 9, 9}));
  EXPECT_EQ(v->index_min, (std::array<int, 3>{0, 0, 0}));
  EXPECT_EQ(v->spacing, (std::array<double, 3>{0.25, 0.25, 0.25}));
  EXPECT_EQ(v->origin, (std::array<double, 3>{-1, -1, -1}));
  EXPECT_EQ(v->voxel_count(), 729);
  // The transform agrees with spacing and origin.
  const openvdb::Vec3d corner = v->grid->indexToWorld(openvdb::Coord(8, 8, 8));
  EXPECT_DOUBLE_EQ(corner.x(), 1.0);
  EXPECT_DOUBLE_EQ(corner.z(), 1.0);
  EXPECT_DOUBLE_EQ(v->grid->indexToWorld(openvdb::Coord(2, 0, 0)).x(), -0.5);
  // Known points of 16xyz + 4(x+y+z) - 1.
  EXPECT_EQ(Sample(*v, 4, 4, 4), -1.0f);   // centre
  EXPECT_EQ(Sample(*v, 8, 8, 8), 27.0f);   // (1, 1, 1)
  EXPECT_EQ(Sample(*v, 0, 0, 0), -29.0f);  // (-1, -1, -1)
  EXPECT_EQ(Sample(*v, 8, 8, 0), -13.0f);  // (1, 1, -1)
  EXPECT_EQ(Sample(*v, 6, 4, 4), 1.0f);    // (0.5, 0, 0)
  EXPECT_EQ(v->grid->activeVoxelCount(), 729u);
  ExpectSamplesMatch(*v, CayleyValue, 0.0);
  EXPECT_EQ(v->min_value, -29.0f);
  EXPECT_EQ(v->max_value, 27.0f);
}

TEST(VolumeGenerators, CayleyAtSizesThatSplitLeaves) {
  // 2 is the smallest volume; 17 leaves a one-sample-thick leaf layer on each axis.
  for (int n : {2, 17}) {
    VolumePtr v = Load("cayley:" + std::to_string(n));
    ASSERT_NE(v, nullptr);
    EXPECT_EQ(v->grid->evalActiveVoxelBoundingBox(),
              openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(n - 1)));
    ExpectSamplesMatch(*v, CayleyValue, 0.0);
  }
}

TEST(VolumeGenerators, SphereIsDistanceFromCentre) {
  VolumePtr v = Load("sphere:11");
  ASSERT_NE(v, nullptr);
  EXPECT_EQ(Sample(*v, 10, 10, 10), static_cast<float>(std::sqrt(3.0)));
  EXPECT_EQ(Sample(*v, 0, 10, 0), static_cast<float>(std::sqrt(3.0)));
  EXPECT_EQ(Sample(*v, 5, 5, 5), 0.0f);
  EXPECT_FLOAT_EQ(Sample(*v, 8, 5, 5), 0.6f);
  ExpectSamplesMatch(*v, SphereValue, 0.0);
}

TEST(VolumeGenerators, ShellsHaveTheirPlateaus) {
  EXPECT_EQ(kShellPlateauValues.size(), kShellTransitionRadii.size() + 1);
  // Plateau centres: the origin, midway between transitions, beyond the last one.
  const double centres[kShellCount] = {0.0, 0.3, 0.5, 0.7, 0.9};
  for (int p = 0; p < kShellCount; ++p) {
    EXPECT_EQ(ShellsValue(centres[p]), kShellPlateauValues[p]) << "plateau " << p;
  }
  EXPECT_DOUBLE_EQ(ShellsValue(0.2 - kShellTransitionHalfWidth), 1.0);
  EXPECT_DOUBLE_EQ(ShellsValue(0.2 + kShellTransitionHalfWidth), 0.75);
  EXPECT_DOUBLE_EQ(ShellsValue(0.4), 0.625);  // the smoothstep is symmetric about its radius
  for (double r = 0; r < 1.8; r += 0.001) EXPECT_LE(ShellsValue(r + 0.001), ShellsValue(r));

  // N = 101: spacing 0.02, so the x axis from the centre hits every plateau exactly.
  VolumePtr v = Load("shells:101");
  ASSERT_NE(v, nullptr);
  for (int p = 0; p < kShellCount; ++p) {
    const int i = 50 + static_cast<int>(std::lround(centres[p] / 0.02));
    EXPECT_EQ(Sample(*v, i, 50, 50), kShellPlateauValues[p]) << "plateau " << p;
  }
  EXPECT_EQ(v->max_value, 1.0f);
  EXPECT_EQ(v->min_value, 0.0f);
  ExpectSamplesMatch(
      *v, [](double x, double y, double z) { return ShellsValue(SphereValue(x, y, z)); }, 0.0);
}

TEST(VolumeGenerators, NoiseIsSeededAndBounded) {
  VolumePtr a = Load("noise:21");
  VolumePtr a1 = Load("noise:21:1");
  VolumePtr b = Load("noise:21:2");
  ASSERT_TRUE(a && a1 && b);
  int differing = 0;
  for (int k = 0; k < 21; ++k)
    for (int j = 0; j < 21; ++j)
      for (int i = 0; i < 21; ++i) {
        ASSERT_EQ(Sample(*a, i, j, k), Sample(*a1, i, j, k));  // default seed is 1
        differing += Sample(*a, i, j, k) != Sample(*b, i, j, k);
      }
  EXPECT_GT(differing, 21 * 21 * 21 * 9 / 10);
  for (const VolumePtr& v : {a, b}) {
    EXPECT_GE(v->min_value, -1.0f);
    EXPECT_LE(v->max_value, 1.0f);
    EXPECT_GT(v->max_value - v->min_value, 0.5f);  // not flat
  }
  ExpectSamplesMatch(
      *a, [](double x, double y, double z) { return NoiseValue(x, y, z, 1); }, 0.0);
  ExpectSamplesMatch(
      *b, [](double x, double y, double z) { return NoiseValue(x, y, z, 2); }, 0.0);
  // Same field at any resolution: sample 10 of 21 and sample 20 of 41 are both the centre.
  VolumePtr fine = Load("noise:41:2");
  ASSERT_NE(fine, nullptr);
  EXPECT_EQ(Sample(*fine, 20, 20, 20), Sample(*b, 10, 10, 10));
  // Smooth: neighbouring samples at spacing 0.05 differ by far less than the range.
  float max_step = 0;
  for (int i = 0; i + 1 < 41; ++i) {
    max_step = std::max(max_step, std::fabs(Sample(*fine, i + 1, 7, 3) - Sample(*fine, i, 7, 3)));
  }
  EXPECT_LT(max_step, 0.3f);
}

TEST(VolumeGenerators, BuckyballAtomsFormATruncatedIcosahedron) {
  const auto& atoms = BuckyballAtoms();
  ASSERT_EQ(atoms.size(), 60u);
  const auto distance = [](const std::array<double, 3>& a, const std::array<double, 3>& b) {
    return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                     (a[2] - b[2]) * (a[2] - b[2]));
  };
  const double edge = 2 * kBuckyballCageRadius / std::sqrt(1 + 9 * 2.618033988749895);
  for (size_t a = 0; a < atoms.size(); ++a) {
    EXPECT_NEAR(distance(atoms[a], {0, 0, 0}), kBuckyballCageRadius, 1e-12);
    int bonded = 0;
    for (size_t b = 0; b < atoms.size(); ++b) {
      if (a == b) continue;
      const double d = distance(atoms[a], atoms[b]);
      EXPECT_GT(d, edge - 1e-9) << "atoms " << a << " and " << b << " closer than a bond";
      bonded += std::fabs(d - edge) < 1e-9;
    }
    EXPECT_EQ(bonded, 3) << "atom " << a;
  }
}

TEST(VolumeGenerators, BuckyballFieldHasTheDocumentedLevels) {
  const auto& atoms = BuckyballAtoms();
  for (const auto& a : atoms) EXPECT_NEAR(BuckyballValue(a[0], a[1], a[2]), 1.0, 1e-12);
  // Bond saddle between 0.15 and 0.25: atoms join at 0.15 and separate at 0.25.
  int partner = -1;
  double best = 1e9;
  for (int b = 1; b < 60; ++b) {
    const double d =
        std::hypot(atoms[b][0] - atoms[0][0], atoms[b][1] - atoms[0][1], atoms[b][2] - atoms[0][2]);
    if (d < best) best = d, partner = b;
  }
  const double bond =
      BuckyballValue((atoms[0][0] + atoms[partner][0]) / 2, (atoms[0][1] + atoms[partner][1]) / 2,
                     (atoms[0][2] + atoms[partner][2]) / 2);
  EXPECT_GT(bond, 0.17);
  EXPECT_LT(bond, 0.23);
  // Faces: the highest value along the ray through a hexagon (1,1,1) or pentagon (0,1,phi)
  // centre lies between 0.05 and 0.15, so faces are closed at 0.05 and open at 0.15.
  const double phi = (1 + std::sqrt(5.0)) / 2;
  for (const std::array<double, 3>& dir :
       {std::array<double, 3>{1, 1, 1}, std::array<double, 3>{0, 1, phi}}) {
    const double len = std::sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
    double ray_max = 0;
    for (double t = 0; t < 1; t += 0.001) {
      ray_max =
          std::max(ray_max, BuckyballValue(dir[0] / len * t, dir[1] / len * t, dir[2] / len * t));
    }
    EXPECT_GT(ray_max, 0.07);
    EXPECT_LT(ray_max, 0.13);
  }
  EXPECT_LT(BuckyballValue(0, 0, 0), 0.03);  // hollow at 0.05
  for (const auto& a : atoms) {
    // Outward from each atom, the field is negligible well inside the cube.
    const double s = 0.95 / kBuckyballCageRadius;
    EXPECT_LT(BuckyballValue(a[0] * s, a[1] * s, a[2] * s), 0.002);
  }
}

// Connected components, 6- or 26-connected, of the samples at or above ISO (ABOVE) or below it.
int CountComponents(const PaddedSamples& cube, int connectivity, float iso, bool above) {
  const auto inside = [&](float f) { return (f >= iso) == above; };
  const int n = cube.n;
  std::vector<int> label(cube.values.size(), 0);
  std::vector<int> stack;
  int components = 0;
  for (size_t seed = 0; seed < label.size(); ++seed) {
    if (label[seed] != 0 || !inside(cube.values[seed])) continue;
    ++components;
    label[seed] = components;
    stack.clear();
    stack.push_back(static_cast<int>(seed));
    while (!stack.empty()) {
      const int p = stack.back();
      stack.pop_back();
      const int x = p % n, y = p / n % n, z = p / (n * n);
      for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int manhattan = std::abs(dx) + std::abs(dy) + std::abs(dz);
            if (manhattan == 0 || (connectivity == 6 && manhattan > 1)) continue;
            const int qx = x + dx, qy = y + dy, qz = z + dz;
            if (qx < 0 || qy < 0 || qz < 0 || qx >= n || qy >= n || qz >= n) continue;
            const int q = (qz * n + qy) * n + qx;
            if (label[q] == 0 && inside(cube.values[q])) {
              label[q] = components;
              stack.push_back(q);
            }
          }
    }
  }
  return components;
}

// The three documented isovalues give three different topologies. Each count uses the
// connectivity under which the claim is hardest to meet on a lattice: 26 when claiming parts
// are apart, 6 when claiming they are joined.
TEST(VolumeGenerators, BuckyballIsovaluesGiveNestedDistinctSurfaces) {
  absl::StatusOr<VolumePtr> v = LoadVolume("buckyball:129");
  ASSERT_TRUE(v.ok()) << v.status();
  absl::StatusOr<PaddedSamples> cube = PadToHierarchyDomain(**v);  // 129 = 2^7 + 1: no padding
  ASSERT_TRUE(cube.ok()) << cube.status();
  // 0.25: sixty separate atoms.
  EXPECT_EQ(CountComponents(*cube, 26, 0.25f, true), 60);
  // 0.15: one bonded cage whose faces are open, so inside and outside are one region.
  EXPECT_EQ(CountComponents(*cube, 6, 0.15f, true), 1);
  EXPECT_EQ(CountComponents(*cube, 6, 0.15f, false), 1);
  // 0.05: one closed shell; the hollow inside is cut off from the outside.
  EXPECT_EQ(CountComponents(*cube, 6, 0.05f, true), 1);
  EXPECT_EQ(CountComponents(*cube, 26, 0.05f, false), 2);
}

TEST(VolumeGenerators, BuckyballGridMatchesField) {
  VolumePtr v = Load("buckyball:33");
  ASSERT_NE(v, nullptr);
  ExpectSamplesMatch(*v, BuckyballValue, 2e-6);
  EXPECT_GE(v->min_value, 0.0f);
  EXPECT_LE(v->max_value, 1.01f);
  // At N = 129 some sample lies within half a sample diagonal of an atom: close to the peak.
  VolumePtr fine = Load("buckyball:129");
  ASSERT_NE(fine, nullptr);
  EXPECT_GT(fine->max_value, 0.8f);
  const auto& a = BuckyballAtoms()[7];
  const auto nearest = [](double c) {
    return static_cast<int>(std::lround((c + 1) / (2.0 / 128)));
  };
  const int i = nearest(a[0]), j = nearest(a[1]), k = nearest(a[2]);
  EXPECT_NEAR(Sample(*fine, i, j, k), BuckyballValue(Coord(i, 129), Coord(j, 129), Coord(k, 129)),
              2e-6);
  EXPECT_GT(Sample(*fine, i, j, k), 0.8f);
}

}  // namespace
}  // namespace isostream
