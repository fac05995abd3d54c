// The count curve's edges (count_curve.h, CountTrianglesPerEtaCode): which stops it notes, a
// curve of one code, one reaching the infinite code, and stops one level above the finest.
#include "server/extract/count_curve.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "server/extract/extractor.h"
#include "test_volumes.h"

namespace isostream {
namespace {

using extract_internal::CountCurve;
using testing::CayleyField;
using testing::MakeHierarchy;

ExtractRequest Request(std::vector<float> iso) { return testing::CountingRequest(std::move(iso)); }

// Only a stop below the curve's first code says where the count first changes below it: a
// node at or above it (a culled one) says nothing, and must not shorten the claim to the
// curve's own first code.
TEST(CountCurve, NotesOnlyStopsBelowItsFirstCode) {
  CountCurve curve(10, 20);
  curve.NoteStop(10);
  curve.NoteStop(15);
  curve.NoteStop(20);
  EXPECT_EQ(curve.largest_stop(), -1);
  curve.NoteStop(3);
  curve.NoteStop(9);
  curve.NoteStop(7);
  EXPECT_EQ(curve.largest_stop(), 9);
}

// A curve of a single code is a count at that code.
TEST(CountCurve, OfOneCodeIsTheCountThere) {
  const auto h = MakeHierarchy(4, CayleyField);
  const ExtractRequest r = Request({0.0f, 0.3f});
  for (uint32_t code : {0u, EtaCodeAtLeast(0.05), CoarsestEtaCode(*h)}) {
    const auto curve = CountTrianglesPerEtaCode(*h, GridToWorld{}, r, code, code);
    ASSERT_TRUE(curve.ok()) << curve.status();
    ASSERT_EQ(curve->size(), 1u);
    const auto direct = CountTriangles(*h, GridToWorld{}, r, EtaCodeEps(code));
    ASSERT_TRUE(direct.ok());
    EXPECT_EQ((*curve)[0], *direct) << "code " << code;
  }
}

// Up to the infinite code (eps FLT_MAX): the six roots are leaves at every code past the
// coarsest, the last one included.
TEST(CountCurve, ReachesTheInfiniteCode) {
  const auto h = MakeHierarchy(4, CayleyField);
  const ExtractRequest r = Request({0.0f, 0.3f});
  const uint32_t top = CoarsestEtaCode(*h);
  ASSERT_LT(top, kInfiniteEtaCode);
  const auto curve = CountTrianglesPerEtaCode(*h, GridToWorld{}, r, top, kInfiniteEtaCode);
  ASSERT_TRUE(curve.ok()) << curve.status();
  ASSERT_EQ(curve->size(), size_t(kInfiniteEtaCode - top + 1));
  const auto roots = CountTriangles(*h, GridToWorld{}, r, EtaCodeEps(kInfiniteEtaCode));
  ASSERT_TRUE(roots.ok());
  ASSERT_GT(*roots, 0) << "the roots should cross the surfaces";
  EXPECT_EQ(curve->back(), *roots);
  EXPECT_EQ(curve->front(), *roots);
  EXPECT_EQ(*std::min_element(curve->begin(), curve->end()), *roots);
  EXPECT_EQ(*std::max_element(curve->begin(), curve->end()), *roots);
}

// Where a count pass says its count stays the same below its eps comes from every node that
// stopped above the finest level, those one level above it included: on small wavy fields,
// where at fine eps the largest such eta is often a leaf's one level up, the budget's code is
// exact (it fits, the code below it does not) for every budget.
TEST(CountCurve, StopsOneLevelAboveTheFinestBoundTheBudgetsCode) {
  struct Wave {
    int k;
    double a, b, c, p, q;
  };
  int cases = 0;
  for (const Wave& w :
       {Wave{2, -1.2, -0.03, -0.34, 0.66, 0.17}, Wave{3, -1.04, -2.67, -1.15, -0.72, 0.41}}) {
    const auto h = MakeHierarchy(w.k, [&](double x, double y, double z) {
      return float(std::sin(w.a * x + w.p) * std::cos(w.b * y + w.q) + 0.5 * std::sin(w.c * z * x) +
                   0.3 * x);
    });
    ASSERT_NE(h, nullptr);
    for (float iso : {-0.4f, 0.0f, 0.3f}) {
      ExtractRequest r = Request({iso});
      const int64_t full = *CountTriangles(*h, GridToWorld{}, r, 0.0);
      for (int64_t budget = 1; budget <= full; budget = budget * 5 / 4 + 1) {
        SCOPED_TRACE(::testing::Message() << "k " << w.k << " iso " << iso << " budget " << budget);
        r.budget = budget;
        const auto res = Extract(*h, GridToWorld{}, r);
        ASSERT_TRUE(res.ok()) << res.status();
        const uint32_t code = EtaCodeAtLeast(res->stats.eps_used);
        const int64_t at = *CountTriangles(*h, GridToWorld{}, r, EtaCodeEps(code));
        if (code != CoarsestEtaCode(*h)) {
          EXPECT_LE(at, budget);
        }
        if (code > 0 && at <= budget) {
          EXPECT_GT(*CountTriangles(*h, GridToWorld{}, r, EtaCodeEps(code - 1)), budget);
        }
        ++cases;
      }
    }
  }
  EXPECT_GT(cases, 100);
}

}  // namespace
}  // namespace isostream
