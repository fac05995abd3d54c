// The triangle count as a function of eps from one pass (count_curve.h), and the budget search
// that reads it (budget_search.h): the curve equals a separate count at every eta code, and
// the search finds the exact smallest code that fits, on real hierarchies and on synthetic
// count functions (power laws, plateaus over many octaves, cliffs).
#include "server/extract/budget_search.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <optional>
#include <vector>

#include "server/extract/extractor.h"
#include "test_volumes.h"

namespace isostream {
namespace {

using extract_internal::BudgetSearchResult;
using extract_internal::CountCurve;
using extract_internal::FindBudgetCode;
using testing::BlobsField;
using testing::CayleyField;
using testing::MakeHierarchy;
using testing::SphereField;

ExtractRequest Request(std::vector<float> iso) { return testing::CountingRequest(std::move(iso)); }

TEST(EtaCodes, EdgesAndCodesRoundTrip) {
  EXPECT_EQ(EtaCodeEps(0), 0.0);
  EXPECT_EQ(EtaCodeAtLeast(0.0), 0u);
  EXPECT_EQ(EtaCodeAtLeast(1.0), 0x3f80u);
  EXPECT_EQ(EtaCodeEps(0x3f80), 1.0);
  EXPECT_EQ(EtaCodeAtLeast(std::nextafter(1.0, 2.0)), 0x3f81u);  // the next edge up
  EXPECT_EQ(EtaCodeAtLeast(1e300), kInfiniteEtaCode);
  EXPECT_EQ(EtaCodeEps(kInfiniteEtaCode), double(std::numeric_limits<float>::max()));
  for (uint32_t code : {1u, 0x100u, 0x3a12u, 0x7f7fu}) {
    EXPECT_EQ(EtaCodeAtLeast(EtaCodeEps(code)), code);
    EXPECT_EQ(EtaCodeAtLeast(EtaCodeEps(code) * (1 - 1e-9)), code);
    EXPECT_EQ(EtaCodeAtLeast(EtaCodeEps(code) * (1 + 1e-9)), code + 1);
  }
}

TEST(CountCurve, SumsIntervalsClippedToItsRange) {
  CountCurve curve(10, 20);
  curve.Add(0, 12, 5);      // clipped to [10, 12]
  curve.Add(15, 15, 7);     // one code
  curve.Add(18, 100, 1);    // clipped to [18, 20]
  curve.Add(21, 30, 1000);  // outside
  curve.Add(14, 13, 1000);  // empty
  const std::vector<int64_t> want = {5, 5, 5, 0, 0, 7, 0, 0, 1, 1, 1};
  EXPECT_EQ(curve.Counts(), want);
}

// One pass's curve equals a separate count at each code it covers (blocks on, for the counts:
// the curve's node-by-node pass agrees with them), on several surfaces at once too.
TEST(CountCurve, EqualsACountAtEveryCode) {
  const auto h = MakeHierarchy(5, BlobsField);
  for (const std::vector<float>& iso : {std::vector<float>{0.5f}, {0.2f, 0.5f, 0.8f}}) {
    const ExtractRequest r = Request(iso);
    const uint32_t top = CoarsestEtaCode(*h);
    for (uint32_t first : {0u, EtaCodeAtLeast(1e-3), EtaCodeAtLeast(0.05)}) {
      auto curve = CountTrianglesPerEtaCode(*h, GridToWorld{}, r, first, top);
      ASSERT_TRUE(curve.ok()) << curve.status();
      ASSERT_EQ(curve->size(), size_t(top - first + 1));
      int changes = 0;
      for (uint32_t code = first; code <= top; ++code) {
        changes += code > first && (*curve)[code - first] != (*curve)[code - first - 1];
        // From eps 0, every code below 1e-3 (sub-voxel etas, ~8000 codes) would take seconds:
        // the lowest 256 and every 17th.
        if (first == 0 && code > 256 && code < EtaCodeAtLeast(1e-3) && code % 17 != 0) continue;
        auto direct = CountTriangles(*h, GridToWorld{}, r, EtaCodeEps(code));
        ASSERT_TRUE(direct.ok());
        ASSERT_EQ((*curve)[code - first], *direct) << "code " << code << " first " << first;
      }
      EXPECT_GT(changes, 10) << "the curve should step many times over this range";
      // Between two codes the count is that of the upper one (a node stops where eta < eps).
      const uint32_t mid = first + (top - first) / 2;
      auto between =
          CountTriangles(*h, GridToWorld{}, r, 0.5 * (EtaCodeEps(mid) + EtaCodeEps(mid + 1)));
      ASSERT_TRUE(between.ok());
      EXPECT_EQ(*between, (*curve)[mid + 1 - first]);
      // So is it just above a code's edge: eps is rounded up to a float, never down (a request's
      // eps in double one step above an edge counted as the edge's code).
      if (first == 0) continue;  // the same codes as from 1e-3
      for (uint32_t code = first; code < top; code += 3) {
        const double above = std::nextafter(EtaCodeEps(code), INFINITY);
        auto n = CountTriangles(*h, GridToWorld{}, r, above);
        ASSERT_TRUE(n.ok());
        ASSERT_EQ(*n, (*curve)[code + 1 - first]) << "eps " << above;
      }
    }
  }
  EXPECT_FALSE(CountTrianglesPerEtaCode(*h, GridToWorld{}, Request({0.5f}), 10, 9).ok());
  EXPECT_FALSE(CountTrianglesPerEtaCode(*h, GridToWorld{}, Request({0.5f}), 0, 0x7f81).ok());
}

// The budget's eps is exact: its code fits, the code below does not.
TEST(BudgetSearch, FindsTheExactSmallestCodeOnAHierarchy) {
  const auto h = MakeHierarchy(5, CayleyField);
  const int64_t full = *CountTriangles(*h, GridToWorld{}, Request({0.0f, 0.3f}), 0.0);
  for (int64_t budget : {int64_t{40}, int64_t{300}, int64_t{2500}, int64_t{9000}, full - 1, full}) {
    ExtractRequest r = Request({0.0f, 0.3f});
    r.budget = budget;
    auto res = Extract(*h, GridToWorld{}, r);
    ASSERT_TRUE(res.ok()) << res.status();
    const double eps = res->stats.eps_used;
    EXPECT_LE(res->stats.triangles, budget) << budget;
    EXPECT_LE(res->stats.budget_passes, 12) << budget;
    const uint32_t code = EtaCodeAtLeast(eps);
    ASSERT_EQ(EtaCodeEps(code), eps) << "the answer is an eta code's edge";
    // Passes are deterministic, so the search is too, whatever the thread count.
    for (int threads : {1, 2}) {
      ExtractRequest t = r;
      t.threads = threads;
      auto again = Extract(*h, GridToWorld{}, t);
      ASSERT_TRUE(again.ok());
      EXPECT_EQ(again->stats.eps_used, eps) << threads << " threads";
      EXPECT_EQ(again->stats.budget_passes, res->stats.budget_passes);
    }
    if (code > 0) {
      auto below = CountTriangles(*h, GridToWorld{}, r, EtaCodeEps(code - 1));
      ASSERT_TRUE(below.ok());
      EXPECT_GT(*below, budget) << "eps " << EtaCodeEps(code - 1) << " fits too, budget " << budget;
    }
  }
}

// The same over fields, isovalue sets (near the data's ends too, where coarse leaves without a
// crossing gain some below their eta) and budgets from a few triangles to nearly all: the
// returned code fits (or is the coarsest) and the code below it does not.
TEST(BudgetSearch, ExactOverFieldsIsovaluesAndBudgets) {
  int cases = 0;
  for (auto field : {BlobsField, CayleyField, SphereField}) {
    for (int k : {4, 5}) {
      const auto h = MakeHierarchy(k, field);
      const uint32_t coarsest = CoarsestEtaCode(*h);
      for (const std::vector<float>& iso : {std::vector<float>{0.5f},
                                            {0.2f, 0.5f, 0.8f},
                                            {0.0f, 0.3f},
                                            {-0.5f, 0.1f},
                                            {0.05f},
                                            {0.95f, 1.3f}}) {
        ExtractRequest r = Request(iso);
        const int64_t full = *CountTriangles(*h, GridToWorld{}, r, 0.0);
        for (double share : {0.003, 0.01, 0.03, 0.1, 0.35, 0.7, 0.99}) {
          SCOPED_TRACE(::testing::Message()
                       << "k " << k << " iso[0] " << iso[0] << " share " << share);
          r.budget = std::max<int64_t>(1, int64_t(share * double(full)));
          auto res = Extract(*h, GridToWorld{}, r);
          ASSERT_TRUE(res.ok()) << res.status();
          const uint32_t code = EtaCodeAtLeast(res->stats.eps_used);
          if (code != coarsest) {
            EXPECT_LE(res->stats.triangles, r.budget);
          }
          if (code > 0 && res->stats.triangles <= r.budget) {
            auto below = CountTriangles(*h, GridToWorld{}, r, EtaCodeEps(code - 1));
            ASSERT_TRUE(below.ok());
            EXPECT_GT(*below, r.budget);
          }
          ++cases;
        }
      }
    }
  }
  EXPECT_GT(cases, 200);
}

// A synthetic count function of the code, served to the search as passes would: the count at
// the pass's code (or past the limit), and the curve up to its end. `codes` (if given) hears
// of each pass's code.
BudgetSearchResult Search(const std::function<int64_t(uint32_t)>& count_at, int64_t budget,
                          uint32_t top, std::vector<uint32_t>* codes = nullptr) {
  const int64_t limit = 4 * budget;
  return FindBudgetCode(budget, limit, top,
                        [&](uint32_t code, CountCurve* curve) -> std::optional<int64_t> {
                          if (codes) codes->push_back(code);
                          const int64_t n = count_at(code);
                          if (n > limit) return limit + 1;
                          if (!curve) return n;
                          for (uint32_t k = curve->first(); k <= curve->last(); ++k)
                            curve->Add(k, k, count_at(k));
                          // Where the count first changes below `code` (a pass knows it from
                          // the etas of the nodes that stopped).
                          for (uint32_t k = code; k > 0; --k)
                            if (count_at(k - 1) != n) {
                              curve->NoteStop(k - 1);
                              break;
                            }
                          return n;
                        });
}

uint32_t BruteForce(const std::function<int64_t(uint32_t)>& count_at, int64_t budget,
                    uint32_t top) {
  for (uint32_t k = 0; k <= top; ++k)
    if (count_at(k) <= budget) return k;
  return top;
}

TEST(BudgetSearch, FindsTheExactCodeOnSyntheticCounts) {
  const uint32_t top = 0x4000;  // eps 2
  std::vector<std::pair<const char*, std::function<int64_t(uint32_t)>>> shapes = {
      {"1/eps", [](uint32_t k) { return int64_t(50 + 1e3 / std::max(EtaCodeEps(k), 1e-12)); }},
      {"1/eps^2.5",
       [](uint32_t k) {
         return int64_t(std::min(8 + 1e2 / std::pow(EtaCodeEps(k), 2.5), 1e15));  // inf at 0: 1e15
       }},
      // Flat over 60 octaves, then a cliff: the search must stride over the plateau.
      {"plateau", [](uint32_t k) { return k >= 0x2000 ? int64_t(30) : int64_t(5'000'000); }},
      // Steps: whole regions stop at once.
      {"steps", [](uint32_t k) { return int64_t(1) << std::clamp(int(0x4000 - k) / 300, 0, 40); }},
  };
  for (const auto& [name, f] : shapes)
    for (int64_t budget : {int64_t{60}, int64_t{1000}, int64_t{123456}, int64_t{4'000'000}}) {
      const BudgetSearchResult res = Search(f, budget, top);
      const uint32_t want = BruteForce(f, budget, top);
      EXPECT_EQ(res.code, want) << name << " budget " << budget;
      if (f(want) <= budget) {
        ASSERT_TRUE(res.count.has_value()) << name;
        EXPECT_EQ(*res.count, f(want)) << name;
      }
      EXPECT_LE(res.passes, 12) << name << " budget " << budget;
      EXPECT_FALSE(res.stopped);
    }
}

// A budget equal to a count is met by it ("at most"): at the top, and on the plateaus of
// whole regions stopping at once, where a pass often lands on a code whose count is exactly the
// budget.
TEST(BudgetSearch, ABudgetEqualToACountFitsIt) {
  const uint32_t top = 0x4000;
  auto steps = [](uint32_t k) { return int64_t(1) << std::clamp(int(0x4000 - k) / 300, 0, 40); };
  auto power = [](uint32_t k) { return int64_t(50 + 1e3 / std::max(EtaCodeEps(k), 1e-12)); };
  for (const auto& f :
       {std::function<int64_t(uint32_t)>(steps), std::function<int64_t(uint32_t)>(power)})
    for (uint32_t at : {top, top - 1, top - 700, top - 2000, top - 5000, 0x2000u, 0x1000u}) {
      const int64_t budget = f(at);
      const BudgetSearchResult res = Search(f, budget, top);
      const uint32_t want = BruteForce(f, budget, top);
      EXPECT_EQ(res.code, want) << "budget " << budget << " = count at " << at;
      ASSERT_TRUE(res.count.has_value()) << "budget " << budget;
      EXPECT_EQ(*res.count, budget);
    }
}

// Each pass counts a code no earlier pass counted: a repeated one shows nothing new. Over the
// shapes and budgets above, and with the coarsest count close to the budget (the first probe's
// aim, a sixteenth of the budget, then lies above the top).
TEST(BudgetSearch, NoCodeIsCountedTwice) {
  const uint32_t top = 0x4000;
  std::vector<std::function<int64_t(uint32_t)>> shapes = {
      [](uint32_t k) { return int64_t(50 + 1e3 / std::max(EtaCodeEps(k), 1e-12)); },
      [](uint32_t k) { return k >= 0x2000 ? int64_t(30) : int64_t(5'000'000); },
      [](uint32_t k) { return int64_t(1) << std::clamp(int(0x4000 - k) / 300, 0, 40); },
  };
  for (size_t i = 0; i < shapes.size(); ++i)
    for (int64_t budget : {int64_t{31}, int64_t{60}, int64_t{1000}, int64_t{123456}}) {
      std::vector<uint32_t> codes;
      Search(shapes[i], budget, top, &codes);
      std::vector<uint32_t> sorted = codes;
      std::sort(sorted.begin(), sorted.end());
      EXPECT_EQ(std::adjacent_find(sorted.begin(), sorted.end()), sorted.end())
          << "shape " << i << " budget " << budget << ": " << ::testing::PrintToString(codes);
    }
}

// Counts that defeat the aim: one that barely changes with eps (linear in the code, so its slope
// over log eps is nearly flat) and a cliff from ~1e9 down to a shallow ramp. Aiming fails
// several times; bisecting the codes after that still ends at the exact code, within 8 aimed
// passes and 16 more (2^15 codes).
TEST(BudgetSearch, EndsExactlyWhereAimingFails) {
  const uint32_t top = 0x4000;
  auto shallow = [](uint32_t k) { return int64_t(1e6 / (1 + 0.001 * k)); };
  auto cliff = [](uint32_t k) {
    return k < 0x3000 ? int64_t(1e9 / (1 + k)) : int64_t(100 + (0x4000 - k));
  };
  int bisected = 0;
  for (const auto& [f, budgets] :
       {std::pair<std::function<int64_t(uint32_t)>, std::vector<int64_t>>{
            shallow, {224185, 784647, 2746264}},
        {cliff, {5229, 18301, 224185, 784647, 2746264}}})
    for (int64_t budget : budgets) {
      const BudgetSearchResult res = Search(f, budget, top);
      EXPECT_EQ(res.code, BruteForce(f, budget, top)) << "budget " << budget;
      EXPECT_LE(res.passes, 8 + 16) << "budget " << budget;
      bisected += res.passes > 9;
    }
  EXPECT_GT(bisected, 0) << "aiming never failed long enough to bisect: nothing tested";
}

// A count the same at every code (no node stops above the finest level): the pass at the top
// shows it, and the answer is code 0 after that one pass.
TEST(BudgetSearch, ACountThatNeverChangesTakesOnePass) {
  const BudgetSearchResult res = Search([](uint32_t) { return int64_t(7); }, 10, 0x4000);
  EXPECT_EQ(res.code, 0u);
  ASSERT_TRUE(res.count.has_value());
  EXPECT_EQ(*res.count, 7);
  EXPECT_EQ(res.passes, 1);
}

// Exact over a sweep of budgets (every factor of 1.7 from 3 to 1e12) on power laws, plateaus,
// steps, shallow counts and cliffs: the hardest of them takes 21 passes, so a search cut short
// before 8 aimed passes and 16 bisecting ones ends at a code that fits but is not the smallest.
TEST(BudgetSearch, ExactOverASweepOfBudgets) {
  const uint32_t top = 0x4000;
  std::vector<std::function<int64_t(uint32_t)>> shapes;
  for (double p : {0.5, 1.0, 2.0, 3.0})
    shapes.push_back([p](uint32_t k) {
      return int64_t(std::min(20 + 1e3 / std::pow(std::max(EtaCodeEps(k), 1e-30), p), 1e15));
    });
  shapes.push_back([](uint32_t k) { return k >= 0x2000 ? int64_t(30) : int64_t(5'000'000); });
  shapes.push_back(
      [](uint32_t k) { return int64_t(1) << std::clamp(int(0x4000 - k) / 300, 0, 40); });
  shapes.push_back([](uint32_t k) { return int64_t(1e6 / (1 + 0.001 * k)); });
  shapes.push_back(
      [](uint32_t k) { return k < 0x3000 ? int64_t(1e9 / (1 + k)) : int64_t(100 + (0x4000 - k)); });
  int most = 0;
  for (size_t i = 0; i < shapes.size(); ++i)
    for (double b = 3; b < 1e12; b *= 1.7) {
      const int64_t budget = int64_t(b);
      const BudgetSearchResult res = Search(shapes[i], budget, top);
      EXPECT_EQ(res.code, BruteForce(shapes[i], budget, top))
          << "shape " << i << " budget " << budget;
      EXPECT_LE(res.passes, 1 + 8 + 16) << "shape " << i << " budget " << budget;
      most = std::max(most, res.passes);
    }
  EXPECT_GT(most, 20) << "no budget needed many passes: the sweep tests little";
}

// On a power law the first probe measures the slope, and the next is aimed at twice the
// budget, between the budget and the limit: its curve holds the answer. Three passes (the top,
// the probe, the aimed one), where the count at the top is well under the budget. The first
// probe, aimed at a sixteenth of the budget with a slope at least as steep as the real one,
// counts little.
TEST(BudgetSearch, APowerLawTakesThreePassesAndACheapFirstProbe) {
  const uint32_t top = 0x4000;
  for (double p : {0.5, 1.0, 1.5, 2.0}) {
    auto f = [p](uint32_t k) {
      return int64_t(std::min(1e3 / std::pow(std::max(EtaCodeEps(k), 1e-30), p), 1e15));
    };
    for (int64_t budget : {int64_t{100'000}, int64_t{1'000'000}, int64_t{10'000'000}}) {
      std::vector<uint32_t> codes;
      const BudgetSearchResult res = Search(f, budget, top, &codes);
      EXPECT_EQ(res.code, BruteForce(f, budget, top));
      EXPECT_EQ(res.passes, 3) << "count ~ eps^-" << p << ", budget " << budget;
      ASSERT_GE(codes.size(), 2u);
      EXPECT_LE(f(codes[1]), budget / 14) << "count ~ eps^-" << p << ", budget " << budget;
    }
  }
}

// An empty coarsest mesh (a surface the coarse tetrahedra miss) aims as a one-triangle one
// does: a count of 0 is taken as 1 on the log scale, not as minus infinity.
TEST(BudgetSearch, AnEmptyCoarsestMeshAimsAsOneTriangleDoes) {
  const uint32_t top = 0x4000;
  auto with_top = [](int64_t at_top) {
    return [at_top](uint32_t k) {
      return k >= 0x3f00 ? at_top : int64_t(1e5 / std::max(EtaCodeEps(k), 1e-12));
    };
  };
  for (int64_t budget : {int64_t{10}, int64_t{1000}, int64_t{100'000}, int64_t{10'000'000}}) {
    std::vector<uint32_t> empty_codes, one_codes;
    const BudgetSearchResult empty = Search(with_top(0), budget, top, &empty_codes);
    const BudgetSearchResult one = Search(with_top(1), budget, top, &one_codes);
    EXPECT_EQ(empty.code, one.code) << budget;
    EXPECT_EQ(empty_codes, one_codes) << budget;
  }
}

// A pass whose count is exactly the limit is within it: its curve runs from there to the
// smallest code known to fit and holds the answer, so the search ends with it.
TEST(BudgetSearch, ACountAtTheLimitIsWithinIt) {
  const uint32_t top = 0x4000;
  const int64_t budget = 1000;  // limit 4000
  auto f = [](uint32_t k) {
    return k >= 0x3000 ? int64_t(10) : k >= 0x0800 ? int64_t(4000) : int64_t(1'000'000'000);
  };
  std::vector<uint32_t> codes;
  const BudgetSearchResult res = Search(f, budget, top, &codes);
  EXPECT_EQ(res.code, 0x3000u);
  ASSERT_GE(codes.size(), 2u);
  ASSERT_EQ(f(codes[1]), 4 * budget) << "the first probe should land on the count at the limit";
  EXPECT_EQ(res.passes, 2) << ::testing::PrintToString(codes);
}

TEST(BudgetSearch, NothingFitsEverythingFitsAndAStoppedPass) {
  auto grows = [](uint32_t k) { return int64_t(0x5000 - k); };
  BudgetSearchResult none = Search(grows, 10, 0x4000);  // 4096 at the top: over budget
  EXPECT_EQ(none.code, 0x4000u);
  EXPECT_EQ(none.passes, 1);
  EXPECT_FALSE(none.count.has_value());
  BudgetSearchResult all = Search(grows, 1 << 20, 0x4000);  // even code 0 fits
  EXPECT_EQ(all.code, 0u);
  EXPECT_EQ(*all.count, 0x5000);
  int passes = 0;
  const BudgetSearchResult stopped = FindBudgetCode(
      1000, 4000, 0x4000, [&](uint32_t code, CountCurve* curve) -> std::optional<int64_t> {
        if (curve) curve->NoteStop(code - 1);  // the count may change right below
        return ++passes < 2 ? std::optional<int64_t>(10) : std::nullopt;
      });
  EXPECT_TRUE(stopped.stopped);
  EXPECT_EQ(stopped.passes, 2);
}

}  // namespace
}  // namespace isostream
