// Thin volumes store stand-ins for the cube's planes deep in the padding (stored_planes.h): every
// cube point must read the same sample and eta bits as from the whole cube, extraction must
// give the same mesh, and the cache must keep such a store.
#include <gtest/gtest.h>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "server/extract/extractor.h"
#include "server/hierarchy/hierarchy.h"
#include "server/hierarchy/hierarchy_cache.h"
#include "server/hierarchy/prepared_volume.h"
#include "server/volume/padding.h"
#include "server/volume/stored_planes.h"

namespace isostream {
namespace {

// A volume of `dims` samples: a smooth field with noise, so eta differs from point to point
// (the noise stands in the wavelets of every scale), at an index box not at the origin.
VolumePtr NoisyVolume(const std::array<int, 3>& dims, unsigned seed) {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(0.0f);
  auto acc = grid->getAccessor();
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> noise(-0.05f, 0.05f);
  const openvdb::Coord lo(-3, 5, 2);
  for (int z = 0; z < dims[2]; ++z)
    for (int y = 0; y < dims[1]; ++y)
      for (int x = 0; x < dims[0]; ++x)
        acc.setValue(
            lo.offsetBy(x, y, z),
            float(std::sin(0.31 * x) + std::cos(0.23 * y) * std::sin(0.4 * z + 0.5)) + noise(rng));
  auto v = std::make_shared<Volume>();
  v->name = "noisy";
  v->grid = grid;
  v->dims = dims;
  v->index_min = {lo.x(), lo.y(), lo.z()};
  return v;
}

struct Pair {
  PaddedSamples whole, stand_ins;
  HierarchyPtr whole_h, stand_in_h;
};

Pair BuildBoth(const std::array<int, 3>& dims, unsigned seed) {
  const VolumePtr v = NoisyVolume(dims, seed);
  Pair p;
  auto whole = PadToHierarchyDomain(*v, nullptr, CubePlanes::kAll);
  auto stand_ins = PadToHierarchyDomain(*v);
  EXPECT_TRUE(whole.ok() && stand_ins.ok());
  if (!whole.ok() || !stand_ins.ok()) return p;
  p.whole = *whole;
  p.stand_ins = *stand_ins;
  auto a = BuildHierarchy(std::move(*whole));
  auto b = BuildHierarchy(std::move(*stand_ins));
  EXPECT_TRUE(a.ok() && b.ok());
  if (a.ok() && b.ok()) p.whole_h = *a, p.stand_in_h = *b;
  return p;
}

std::string Shape(const std::array<int, 3>& d) {
  return std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]);
}

TEST(StoredPlanes, DataPlanesFirstAndStandInsOfTheSameKind) {
  for (const int k : {1, 3, 6, 9, 12})
    for (const int data : {2, 3, 5, 17, 40, 100, 1000}) {
      if (data > (1 << k) + 1) continue;
      const AxisPlanes axis = StoredPlanesOf(k, data);
      const int last = 1 << k;
      ASSERT_EQ(axis.plane_of.size(), size_t(last) + 1);
      for (int c = 0; c < data; ++c) ASSERT_EQ(axis.plane_of[c], c) << "data planes are stored";
      EXPECT_EQ(axis.planes.back(), last) << "the far face is stored";
      for (int c = data; c <= last; ++c) {
        const int s = axis.planes[axis.plane_of[c]];
        if (s == c) continue;
        // A stand-in: deep in the padding as c is, with the same trailing zero bits.
        EXPECT_EQ(__builtin_ctz(s), __builtin_ctz(c))
            << "k " << k << " data " << data << " c " << c;
        EXPECT_GE(s - 4 * (1 << __builtin_ctz(c)), data - 1);
        EXPECT_GE(c - 4 * (1 << __builtin_ctz(c)), data - 1);
      }
    }
  // What it saves: a 2049 x 2049 x 50 stack keeps its 50 data planes and 30 more along z.
  const AxisPlanes z = StoredPlanesOf(11, 50);
  EXPECT_EQ(z.planes.size(), 80u);
  EXPECT_TRUE(UseStandIns(11, {2049, 2049, 50}));
  EXPECT_LT(StoredPointCount(11, {2049, 2049, 50}), int64_t(2049) * 2049 * 160);
  EXPECT_FALSE(UseStandIns(8, {257, 257, 257}));
  EXPECT_FALSE(UseStandIns(8, {200, 240, 250}));  // 81% of the cube: the whole cube's builder
  EXPECT_TRUE(UseStandIns(9, {300, 400, 500}));   // 50.6%
}

TEST(HierarchyStandIns, EveryCubePointReadsTheWholeCubesSampleAndEta) {
  const std::vector<std::array<int, 3>> shapes = {
      {2, 40, 3}, {65, 5, 9}, {129, 129, 3}, {65, 3, 3}, {5, 129, 7}, {100, 10, 40}, {130, 9, 6}};
  unsigned seed = 1;
  for (const auto& dims : shapes) {
    const Pair p = BuildBoth(dims, seed++);
    ASSERT_TRUE(p.whole_h && p.stand_in_h) << Shape(dims);
    ASSERT_FALSE(p.stand_ins.whole_cube()) << Shape(dims) << " should store stand-ins";
    EXPECT_LE(4 * p.stand_in_h->stored_point_count(), 3 * p.whole_h->stored_point_count())
        << Shape(dims);
    EXPECT_LT(p.stand_in_h->total_bytes(), p.whole_h->total_bytes()) << Shape(dims);
    const std::vector<float> samples = p.whole_h->LinearSamples();
    const auto codes = p.whole_h->LinearEtaCodes();
    ASSERT_EQ(samples, p.stand_in_h->LinearSamples()) << Shape(dims);
    const auto stand_in_codes = p.stand_in_h->LinearEtaCodes();
    const int n = p.whole_h->n();
    size_t differ = 0, nonzero = 0;
    for (size_t i = 0; i < codes.size(); ++i) {
      differ += codes[i] != stand_in_codes[i];
      nonzero += codes[i] != 0;
      if (codes[i] != stand_in_codes[i] && differ <= 3)
        ADD_FAILURE() << Shape(dims) << ": eta code at cube point " << i % n << "," << i / n % n
                      << "," << i / n / n << " is " << stand_in_codes[i] << ", the whole cube's "
                      << codes[i];
    }
    EXPECT_EQ(differ, 0u) << Shape(dims);
    EXPECT_GT(nonzero, codes.size() / 8) << Shape(dims) << ": the field should have wavelets";
  }
}

// Samples are checked as the whole cube's builder checks them: a non-finite one anywhere, in the
// data's planes or a stand-in's, is refused rather than made into eta.
TEST(HierarchyStandIns, NonFiniteSamplesAreRefused) {
  const VolumePtr v = NoisyVolume({40, 6, 3}, 5);
  for (const bool in_stand_in : {false, true}) {
    auto samples = PadToHierarchyDomain(*v);
    ASSERT_TRUE(samples.ok());
    ASSERT_FALSE(samples->whole_cube());
    const size_t at = in_stand_in ? samples->values.size() - 2 : 7;
    samples->values[at] = in_stand_in ? INFINITY : std::nanf("");
    const auto h = BuildHierarchy(std::move(*samples));
    EXPECT_EQ(h.status().code(), absl::StatusCode::kInvalidArgument) << h.status();
    EXPECT_NE(h.status().message().find("non-finite sample"), std::string::npos) << h.status();
  }
}

// Random shapes, k 3 to 7, some axes filling their cube, some thin, some near the cube's far
// face: every cube point reads the whole cube's sample and eta bits.
TEST(HierarchyStandIns, RandomShapesReadTheWholeCubesBits) {
  std::mt19937 rng(19);
  int compared = 0;
  for (int trial = 0; trial < 400 && compared < 120; ++trial) {
    const int k = 3 + int(rng() % 5), n = (1 << k) + 1;
    std::array<int, 3> dims;
    for (int a = 0; a < 3; ++a) {
      const int kind = int(rng() % 4);
      dims[a] = kind == 0 ? n : kind == 1 ? 2 + int(rng() % 4) : 2 + int(rng() % (n - 1));
    }
    dims[rng() % 3] = std::max(dims[0], (1 << (k - 1)) + 2);  // the longest side sets k
    if (HierarchyLevelFor(dims) != k || !UseStandIns(k, dims)) continue;
    ++compared;
    const Pair p = BuildBoth(dims, unsigned(trial));
    ASSERT_TRUE(p.whole_h && p.stand_in_h) << Shape(dims);
    ASSERT_EQ(p.whole_h->LinearSamples(), p.stand_in_h->LinearSamples()) << Shape(dims);
    ASSERT_EQ(p.whole_h->LinearEtaCodes(), p.stand_in_h->LinearEtaCodes()) << Shape(dims);
  }
  EXPECT_GT(compared, 40);
}

// Stored planes that cannot be a store (not ascending, a map out of range or of the wrong size)
// are refused, not read out of bounds.
TEST(HierarchyStandIns, InconsistentPlanesAreRefused) {
  const VolumePtr v = NoisyVolume({40, 6, 3}, 9);
  auto good = PadToHierarchyDomain(*v);
  ASSERT_TRUE(good.ok());
  ASSERT_FALSE(good->whole_cube());
  const std::function<void(PaddedSamples*)> damages[] = {
      [](PaddedSamples* s) { std::swap(s->planes[1][0], s->planes[1][1]); },
      [](PaddedSamples* s) { s->plane_of[2][5] = int(s->planes[2].size()); },
      [](PaddedSamples* s) { s->plane_of[0].pop_back(); },
      [](PaddedSamples* s) { s->planes[2].back() = s->n; },
      [](PaddedSamples* s) { s->values.resize(s->values.size() - 1); }};
  for (size_t i = 0; i < std::size(damages); ++i) {
    PaddedSamples s = *good;
    damages[i](&s);
    const auto h = BuildHierarchy(std::move(s));
    EXPECT_EQ(h.status().code(), absl::StatusCode::kInvalidArgument) << i << ": " << h.status();
  }
  EXPECT_TRUE(BuildHierarchy(*good).ok());
}

TEST(HierarchyStandIns, ExtractsTheWholeCubesMesh) {
  const Pair p = BuildBoth({100, 10, 40}, 7);
  ASSERT_TRUE(p.whole_h && p.stand_in_h);
  GridToWorld xf;
  xf.spacing = {0.5, 0.5, 0.5};
  for (const double eps : {0.0, 0.02, 0.3}) {
    ExtractRequest r;
    r.isovalues = {-0.4f, 0.1f, 0.7f};
    r.eps = eps;
    r.view.eye = {-9.0, 31.0, 17.0};
    const auto a = Extract(*p.whole_h, xf, r);
    const auto b = Extract(*p.stand_in_h, xf, r);
    ASSERT_TRUE(a.ok() && b.ok());
    ASSERT_GT(a->mesh.triangle_count(), 100u) << "eps " << eps;
    EXPECT_EQ(a->mesh.triangles, b->mesh.triangles) << "eps " << eps;
    EXPECT_EQ(a->mesh.positions, b->mesh.positions) << "eps " << eps;
    EXPECT_EQ(a->mesh.normals, b->mesh.normals) << "eps " << eps;
    EXPECT_EQ(a->mesh.surface, b->mesh.surface) << "eps " << eps;
  }
}

TEST(HierarchyStandIns, TheCacheKeepsAStoreOfStandIns) {
  const std::filesystem::path dir =
      std::filesystem::path(::testing::TempDir()) /
      ("isostream-stand-in-cache-" +
       std::to_string(::testing::UnitTest::GetInstance()->random_seed()));
  std::filesystem::remove_all(dir);
  HierarchyCacheOptions cache;
  cache.dir = dir.string();
  const VolumePtr v = NoisyVolume({70, 6, 11}, 3);
  HierarchyPtr built, read;
  for (const CacheOutcome expected : {CacheOutcome::kMissBuilt, CacheOutcome::kHit}) {
    auto samples = PadToHierarchyDomain(*v);
    ASSERT_TRUE(samples.ok());
    ASSERT_FALSE(samples->whole_cube());
    CacheOutcome outcome;
    auto h = LoadOrBuildHierarchy(std::move(*samples), cache, {}, &outcome);
    ASSERT_TRUE(h.ok()) << h.status();
    EXPECT_EQ(outcome, expected);
    (built ? read : built) = *h;
  }
  EXPECT_EQ(built->stored_dims(), read->stored_dims());
  EXPECT_EQ(built->LinearSamples(), read->LinearSamples());
  EXPECT_EQ(built->LinearEtaCodes(), read->LinearEtaCodes());
  std::filesystem::remove_all(dir);
}

// A 1026-sample side pads to the 2049^3 cube (8.6 G points, past the default limit of 1025^3):
// stored with stand-ins it is ~7 M points, which the limit bounds instead.
TEST(HierarchyStandIns, TheLimitBoundsTheStoredPoints) {
  const std::string path = ::testing::TempDir() + "/isostream-stand-in-long.raw";
  {
    std::ofstream out(path, std::ios::binary);
    for (int i = 0; i < 1026 * 2 * 2; ++i) out.put(char(i % 1026 < 500 ? 10 : 200));
  }
  const std::string spec = "raw:" + path + ":1026x2x2:uint8";
  auto prepared =
      PrepareVolume(spec, VolumeLimits{}, HierarchyCacheOptions{}, HierarchyBuildOptions{});
  ASSERT_TRUE(prepared.ok()) << prepared.status();
  const Hierarchy& h = *prepared->hierarchy;
  EXPECT_EQ(h.n(), 2049);
  EXPECT_LT(h.stored_point_count(), size_t(10'000'000));
  EXPECT_EQ(h.sample(2048, 2048, 2048), 200.0f);  // a stand-in: the last data sample's value
  EXPECT_EQ(h.sample(499, 1000, 7), 10.0f);

  VolumeLimits limits;
  limits.max_voxels = 1'000'000;
  prepared = PrepareVolume(spec, limits, HierarchyCacheOptions{}, HierarchyBuildOptions{});
  ASSERT_EQ(prepared.status().code(), absl::StatusCode::kResourceExhausted) << prepared.status();
  EXPECT_NE(prepared.status().message().find("points of a 2049^3 cube (its longest side, cubed, "
                                             "less the planes deep in its padding), past the "
                                             "limit of 1000000"),
            std::string::npos)
      << prepared.status();
  std::remove(path.c_str());
}

}  // namespace
}  // namespace isostream
