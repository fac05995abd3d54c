// Saturated error bounds: monotone, closed under refinement (no hanging nodes for any eps),
// and a true bound on |f_adaptive - f_full|.
#include "server/hierarchy/hierarchy.h"

#include <gtest/gtest.h>

#include <cmath>
#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>
#include <map>
#include <random>
#include <set>
#include <tuple>

#include "address_space_cap.h"
#include "server/hierarchy/refinement_vertex.h"
#include "test_volumes.h"
#include "tree_walk.h"

namespace isostream {
namespace {

using testing::AdaptiveLeaves;
using testing::TetNode;
using testing::WalkTree;

using testing::MakeSamples;

struct Volume {
  const char* name;
  std::function<float(double, double, double)> f;
};

std::vector<Volume> TestVolumes() {
  auto noise = std::make_shared<std::mt19937>(11);
  return {
      {"cayley",
       [](double x, double y, double z) { return float(16 * x * y * z + 4 * (x + y + z) - 1); }},
      {"sphere",
       [](double x, double y, double z) { return float(std::sqrt(x * x + y * y + z * z)); }},
      {"waves", [](double x, double y,
                   double z) { return float(std::sin(5 * x) * std::cos(3 * y) + z * z); }},
      {"random", [noise](double, double,
                         double) { return std::uniform_real_distribution<float>(-1, 1)(*noise); }},
  };
}

HierarchyPtr Build(int k, const Volume& v, int threads = 0) {
  HierarchyBuildOptions options;
  options.threads = threads;
  auto h = BuildHierarchy(MakeSamples(k, v.f), options);
  EXPECT_TRUE(h.ok()) << h.status();
  return *h;
}

double Wavelet(const Hierarchy& h, const TetNode& t) {
  const glm::ivec3 x = RefinementPoint(t.v);
  return h.sample(x.x, x.y, x.z) - 0.5 * (double(h.sample(t.v[0].x, t.v[0].y, t.v[0].z)) +
                                          h.sample(t.v[3].x, t.v[3].y, t.v[3].z));
}

// eta(x) is |w(x)| + max eta over the refinement vertices of the children of the
// tetrahedra in x's diamond, as read off the tree itself. This pins the builder's stencils to
// the bisection tree: a missing child would make eta too small, an extra one too large.
TEST(Hierarchy, EtaIsAdditiveSaturationOverTreeChildren) {
  for (const auto& vol : TestVolumes()) {
    const int k = 4;
    const HierarchyPtr h = Build(k, vol);
    std::map<std::tuple<int, int, int>, float> child_max;
    std::map<std::tuple<int, int, int>, double> wavelet;
    WalkTree(k, [&](const TetNode& t) {
      if (t.level >= 3 * k - 1) return t.level < 3 * k;
      const glm::ivec3 x = RefinementPoint(t.v);
      auto& m = child_max[{x.x, x.y, x.z}];
      wavelet[{x.x, x.y, x.z}] = std::abs(Wavelet(*h, t));
      const ReferenceTet& rt = ReferenceTets::Get()[t.cls];
      for (int c = 0; c < 2; ++c) {
        TetVertices cv;
        ChildVertices(rt, t.v, c, &cv);
        const glm::ivec3 y = RefinementPoint(cv);
        m = std::max(m, h->eta(y.x, y.y, y.z));
      }
      return true;
    });
    size_t checked = 0;
    for (const auto& [p, m] : child_max) {
      // eta is stored rounded up to bfloat16 (8 significant bits): allow that, and no more.
      const double expect = wavelet[p] + m;
      const float got = h->eta(std::get<0>(p), std::get<1>(p), std::get<2>(p));
      EXPECT_GE(double(got), expect * (1 - 1.0 / 128)) << vol.name;
      EXPECT_LE(double(got), expect * (1 + 1.0 / 128) + 1e-12) << vol.name;
      ++checked;
    }
    EXPECT_GT(checked, 1000u);
  }
}

// The stored eta, bit for bit, against a straightforward evaluation of its definition over the
// bisection tree: children and wavelets read off the tree, eta computed in float rounded up
// (|w| in double plus the children's float eta), finest diamonds first, and only the final
// value rounded up to bfloat16. Any change to the builder's stencils, pass order, rounding or
// brick layout that changes a single stored bit fails here, for every cube size from one
// brick (k = 1..3) to several with partial bricks at the far faces (k = 4, 5).
TEST(Hierarchy, StoredEtaEqualsReferenceRecursionBitForBit) {
  auto round_up = [](double v) {
    float f = static_cast<float>(v);
    if (static_cast<double>(f) < v) f = std::nextafter(f, INFINITY);
    return f;
  };
  for (const auto& vol : TestVolumes()) {
    for (int k = 1; k <= 5; ++k) {
      for (int threads : {1, 2}) {
        const HierarchyPtr h = Build(k, vol, threads);
        const int n = (1 << k) + 1;
        auto id = [n](const glm::ivec3& p) { return (size_t(p.z) * n + p.y) * n + p.x; };
        std::map<size_t, std::set<size_t>> children;
        std::map<size_t, double> wavelet;
        std::map<size_t, int> level;
        WalkTree(k, [&](const TetNode& t) {
          if (t.level == 3 * k) return false;
          const size_t x = id(RefinementPoint(t.v));
          wavelet[x] = std::abs(Wavelet(*h, t));
          level[x] = t.level;
          auto& c = children[x];
          if (t.level + 1 < 3 * k) {
            const ReferenceTet& rt = ReferenceTets::Get()[t.cls];
            for (int i = 0; i < 2; ++i) {
              TetVertices cv;
              ChildVertices(rt, t.v, i, &cv);
              c.insert(id(RefinementPoint(cv)));
            }
          }
          return true;
        });
        ASSERT_EQ(children.size(), size_t(n) * n * n - 8) << "every point but the corners";
        std::vector<std::pair<int, size_t>> order;
        for (const auto& [x, l] : level) order.push_back({-l, x});
        std::sort(order.begin(), order.end());  // finest level first
        std::map<size_t, float> eta;
        for (const auto& [neg_level, x] : order) {
          float worst = 0;
          for (size_t c : children[x]) worst = std::max(worst, eta.at(c));
          eta[x] = round_up(wavelet[x] + worst);
        }
        for (int z = 0; z < n; ++z)
          for (int y = 0; y < n; ++y)
            for (int x = 0; x < n; ++x) {
              const size_t i = h->index(x, y, z);
              const uint16_t stored = h->bricks()[i >> 9].eta[i & 511];
              const auto it = eta.find(id({x, y, z}));
              const uint16_t expect = it == eta.end() ? 0 : EncodeEtaRoundingUp(it->second);
              ASSERT_EQ(stored, expect) << vol.name << " k " << k << " threads " << threads
                                        << " at " << x << " " << y << " " << z;
            }
      }
    }
  }
}

// The extractor addresses the store through the per-axis byte-offset tables: their sums must
// land on exactly the sample and eta the index names, for every point, including the points of
// partial bricks at the far faces (k = 4, 5), and the index must give every point its own slot.
TEST(Hierarchy, ByteOffsetTablesAddressTheIndexedSampleAndEta) {
  const auto& vol = TestVolumes().front();
  for (int k = 1; k <= 5; ++k) {
    const HierarchyPtr h = Build(k, vol, 1);
    const int n = h->n();
    const char* store = reinterpret_cast<const char*>(h->bricks());
    const auto& vb = h->value_byte_offsets();
    const auto& eb = h->eta_byte_offsets();
    std::set<size_t> slots;
    for (int z = 0; z < n; ++z)
      for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
          const size_t i = h->index(x, y, z);
          ASSERT_TRUE(slots.insert(i).second) << "k " << k << " at " << x << " " << y << " " << z;
          const char* value = store + vb[0][x] + vb[1][y] + vb[2][z];
          const char* eta = store + eb[0][x] + eb[1][y] + eb[2][z];
          ASSERT_EQ(value, reinterpret_cast<const char*>(&h->bricks()[i >> 9].value[i & 511]))
              << "k " << k << " at " << x << " " << y << " " << z;
          ASSERT_EQ(eta, reinterpret_cast<const char*>(&h->bricks()[i >> 9].eta[i & 511]))
              << "k " << k << " at " << x << " " << y << " " << z;
          ASSERT_EQ(*reinterpret_cast<const float*>(value), h->sample(x, y, z));
        }
  }
}

// Inside a brick, points are grouped by coordinate parity (all-even first) so that a cache
// line holds 16 points of one class: what the traversal reads above the last levels.
TEST(Hierarchy, BricksGroupPointsByParity) {
  const HierarchyPtr h = Build(4, TestVolumes().front(), 1);
  for (int z = 0; z < h->n(); ++z)
    for (int y = 0; y < h->n(); ++y)
      for (int x = 0; x < h->n(); ++x) {
        const size_t local = h->index(x, y, z) & 511;
        const int lx = x & 7, ly = y & 7, lz = z & 7;
        const size_t group = (lx & 1) | (ly & 1) << 1 | (lz & 1) << 2;
        const size_t place = (lx >> 1) | (ly >> 1) << 2 | (lz >> 1) << 4;
        ASSERT_EQ(local, group * 64 + place) << x << " " << y << " " << z;
        // The brick is the one the coordinates' high bits name.
        ASSERT_EQ(h->index(x, y, z) >> 9, h->index(x & ~7, y & ~7, z & ~7) >> 9);
      }
}

TEST(Hierarchy, SaturationIsMonotoneAlongTheTree) {
  for (const auto& vol : TestVolumes()) {
    const int k = 4;
    const HierarchyPtr h = Build(k, vol);
    size_t pairs = 0;
    WalkTree(k, [&](const TetNode& t) {
      if (t.level >= 3 * k - 1) return t.level < 3 * k;
      const glm::ivec3 x = RefinementPoint(t.v);
      const ReferenceTet& rt = ReferenceTets::Get()[t.cls];
      for (int c = 0; c < 2; ++c) {
        TetVertices cv;
        ChildVertices(rt, t.v, c, &cv);
        const glm::ivec3 y = RefinementPoint(cv);
        EXPECT_LE(h->eta(y.x, y.y, y.z), h->eta(x.x, x.y, x.z)) << vol.name;
        ++pairs;
      }
      return true;
    });
    EXPECT_GT(pairs, 10000u);
  }
}

TEST(Hierarchy, SameEtaWithOneAndTwoThreads) {
  const auto vols = TestVolumes();
  const HierarchyPtr a = Build(5, vols[2], 1), b = Build(5, vols[2], 2);
  ASSERT_EQ(a->point_count(), b->point_count());
  EXPECT_EQ(a->LinearEta(), b->LinearEta());
}

// No hanging node: in the adaptive leaf mesh every face is shared by exactly two leaves, except
// faces on the domain boundary, which belong to one.
TEST(Hierarchy, AdaptiveMeshIsConformingForRandomEps) {
  std::mt19937 rng(5);
  for (const auto& vol : TestVolumes()) {
    const int k = 4, size = 1 << k;
    const HierarchyPtr h = Build(k, vol);
    const float top = h->eta(size / 2, size / 2, size / 2);
    std::uniform_real_distribution<double> frac(0, 1);
    for (int trial = 0; trial < 6; ++trial) {
      const double eps = top * std::pow(frac(rng), 3.0);
      const auto leaves = AdaptiveLeaves(*h, eps);
      std::map<std::array<std::tuple<int, int, int>, 3>, int> faces;
      for (const auto& t : leaves)
        for (int skip = 0; skip < 4; ++skip) {
          std::array<std::tuple<int, int, int>, 3> f;
          int j = 0;
          for (int i = 0; i < 4; ++i)
            if (i != skip) f[j++] = {t.v[i].x, t.v[i].y, t.v[i].z};
          std::sort(f.begin(), f.end());
          ++faces[f];
        }
      size_t boundary = 0;
      for (const auto& [f, count] : faces) {
        bool on_boundary = false;
        for (int a = 0; a < 3; ++a) {
          const int c0 = a == 0   ? std::get<0>(f[0])
                         : a == 1 ? std::get<1>(f[0])
                                  : std::get<2>(f[0]);
          bool same = true;
          for (const auto& p : f) {
            const int c = a == 0 ? std::get<0>(p) : a == 1 ? std::get<1>(p) : std::get<2>(p);
            same &= c == c0;
          }
          on_boundary |= same && (c0 == 0 || c0 == size);
        }
        boundary += on_boundary;
        ASSERT_EQ(count, on_boundary ? 1 : 2) << vol.name << " eps " << eps << ": hanging node";
      }
      EXPECT_GT(boundary, 0u);
    }
  }
}

glm::dvec4 Barycentric(const TetVertices& v, const glm::dvec3& p) {
  const glm::dmat3 e(glm::dvec3(v[1] - v[0]), glm::dvec3(v[2] - v[0]), glm::dvec3(v[3] - v[0]));
  const glm::dvec3 l = glm::inverse(e) * (p - glm::dvec3(v[0]));
  return {1 - l.x - l.y - l.z, l.x, l.y, l.z};
}

// Finds the leaf containing p when descending while `refine` says so.
TetNode Locate(const glm::dvec3& p, int k, const std::function<bool(const TetNode&)>& refine) {
  const auto& tables = ReferenceTets::Get();
  auto inside = [&](const TetVertices& v) {
    const glm::dvec4 b = Barycentric(v, p);
    return b.x >= -1e-12 && b.y >= -1e-12 && b.z >= -1e-12 && b.w >= -1e-12;
  };
  TetNode t;
  for (int i = 0; i < kNumInitialTets; ++i) {
    const TetVertices v = InitialVertices(tables, i, 1 << k);
    if (inside(v)) {
      t = TetNode{v, tables.initial_class(i), 0};
      break;
    }
  }
  while (t.level < 3 * k && refine(t)) {
    const ReferenceTet& rt = tables[t.cls];
    TetNode c0{{}, rt.child[0], t.level + 1}, c1{{}, rt.child[1], t.level + 1};
    ChildVertices(rt, t.v, 0, &c0.v);
    ChildVertices(rt, t.v, 1, &c1.v);
    t = inside(c0.v) ? c0 : c1;
  }
  return t;
}

double Interpolate(const Hierarchy& h, const TetNode& t, const glm::dvec3& p) {
  const glm::dvec4 b = Barycentric(t.v, p);
  double s = 0;
  for (int i = 0; i < 4; ++i) s += b[i] * h.sample(t.v[i].x, t.v[i].y, t.v[i].z);
  return s;
}

TEST(Hierarchy, EtaBoundsAdaptiveErrorForRandomEps) {
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> frac(0, 1);
  for (const auto& vol : TestVolumes()) {
    const int k = 5, size = 1 << k;
    const HierarchyPtr h = Build(k, vol);
    const float top = h->eta(size / 2, size / 2, size / 2);
    for (int trial = 0; trial < 5; ++trial) {
      const double eps = top * std::pow(frac(rng), 2.0);
      double worst = 0, worst_eta_gap = 0;
      for (int s = 0; s < 2000; ++s) {
        const glm::dvec3 p(size * frac(rng), size * frac(rng), size * frac(rng));
        const TetNode leaf = Locate(p, k, [&](const TetNode& t) {
          const glm::ivec3 x = RefinementPoint(t.v);
          return h->eta(x.x, x.y, x.z) >= eps;
        });
        const TetNode finest = Locate(p, k, [](const TetNode&) { return true; });
        const double err = std::abs(Interpolate(*h, leaf, p) - Interpolate(*h, finest, p));
        worst = std::max(worst, err);
        if (leaf.level < 3 * k) {
          const glm::ivec3 x = RefinementPoint(leaf.v);
          worst_eta_gap = std::max(worst_eta_gap, err - h->eta(x.x, x.y, x.z));
        }
      }
      EXPECT_LE(worst, eps + 1e-6) << vol.name << " eps " << eps;
      EXPECT_LE(worst_eta_gap, 1e-6) << vol.name;
    }
  }
}

// The bound is not vacuous: on a curved field the root has real error, and eta (a sum over
// all levels) stays within a small factor of the error it bounds. On a linear field it is 0.
TEST(Hierarchy, EtaIsTightEnoughToMatter) {
  const auto vols = TestVolumes();
  const int k = 5, size = 1 << k;
  const HierarchyPtr h = Build(k, vols[1]);  // distance from the centre
  const auto& tables = ReferenceTets::Get();
  double root_error = 0;  // max over grid points of |L_T f - f| on the 6 initial tets
  for (int z = 0; z <= size; ++z)
    for (int y = 0; y <= size; ++y)
      for (int x = 0; x <= size; ++x) {
        const glm::dvec3 p(x, y, z);
        for (int i = 0; i < kNumInitialTets; ++i) {
          TetNode t{InitialVertices(tables, i, size), tables.initial_class(i), 0};
          const glm::dvec4 b = Barycentric(t.v, p);
          if (std::min({b.x, b.y, b.z, b.w}) < -1e-12) continue;
          root_error = std::max(root_error, std::abs(Interpolate(*h, t, p) - h->sample(x, y, z)));
        }
      }
  const double root_eta = h->eta(size / 2, size / 2, size / 2);
  EXPECT_GT(root_error, 1.0);
  EXPECT_GE(root_eta, root_error);
  EXPECT_LE(root_eta, 3.0 * root_error);
  const HierarchyPtr lin = Build(k, {"linear", [](double x, double y, double z) {
                                       return float(0.25 * x - 0.5 * y + 0.125 * z);
                                     }});
  for (float e : lin->LinearEta()) ASSERT_LE(e, 1e-6f);
}

TEST(Hierarchy, RejectsNonFiniteSamplesAndBadShapes) {
  PaddedSamples s = MakeSamples(2, [](double, double, double) { return 0.0f; });
  s.values[7] = std::nanf("");
  EXPECT_EQ(BuildHierarchy(std::move(s)).status().code(), absl::StatusCode::kInvalidArgument);
  PaddedSamples bad;
  bad.k = 2;
  bad.n = 4;  // not 2^k + 1
  bad.values.resize(64);
  EXPECT_EQ(BuildHierarchy(std::move(bad)).status().code(), absl::StatusCode::kInvalidArgument);
}

// A store the process cannot allocate is a ResourceExhausted status naming its size, not a
// throw past the caller (the CLI and the daemon report it and go on). Run in a child process
// whose address space is capped 32 MB above what it already uses: the 257^3 store needs 100 MB.
void BuildUnderAddressSpaceCap(PaddedSamples s) {
  testing::CapAddressSpaceAbove(rlim_t{32} << 20);
  const auto h = BuildHierarchy(std::move(s));
  const bool ok = !h.ok() && h.status().code() == absl::StatusCode::kResourceExhausted &&
                  h.status().message().find("257^3") != std::string::npos;
  std::_Exit(ok ? 0 : 1);
}

TEST(HierarchyDeathTest, StoreOutOfMemoryIsAStatus) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  PaddedSamples s = MakeSamples(8, [](double x, double, double) { return float(x); });
  EXPECT_EXIT(BuildUnderAddressSpaceCap(std::move(s)), ::testing::ExitedWithCode(0), "");
}

}  // namespace
}  // namespace isostream

namespace isostream {
namespace {

TEST(Hierarchy, StoredEtaRoundsUpWithinOnePartIn128AndKeepsOrder) {
  std::mt19937 rng(2);
  std::uniform_real_distribution<float> mant(1, 2);
  std::uniform_int_distribution<int> expo(-30, 30);
  float previous_value = 0;
  uint16_t previous_code = 0;
  std::vector<float> values = {0.0f, 1e-38f, 1.0f, 3.0e38f};
  for (int i = 0; i < 100000; ++i) values.push_back(std::ldexp(mant(rng), expo(rng)));
  std::sort(values.begin(), values.end());
  for (float v : values) {
    const uint16_t code = EncodeEtaRoundingUp(v);
    const float back = DecodeEta(code);
    ASSERT_GE(back, v);
    ASSERT_LE(back, v * (1 + 1.0f / 128) + 1e-40f);
    ASSERT_GE(code, previous_code) << "rounding must be monotone: " << previous_value << " " << v;
    previous_value = v;
    previous_code = code;
  }
}

}  // namespace
}  // namespace isostream
