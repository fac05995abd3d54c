// The loaders' row statistics: the SSE2 form and the portable scalar form (the only one on
// targets without SSE2) give the same minimum, maximum and "not finite" flag, and both equal a
// direct computation over the finite samples.
#include "server/volume/row_stats.h"

#include <gtest/gtest.h>

#include <cfloat>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace isostream::volume_internal {
namespace {

struct Stats {
  float lo, hi;
  bool bad;
};

template <typename Rows>
Stats Reduce(const std::vector<float>& samples) {
  Rows rows;
  Stats s{std::numeric_limits<float>::max(), std::numeric_limits<float>::lowest(), false};
  rows.Reset(s.lo, s.hi);
  for (size_t r = 0; r + 8 <= samples.size(); r += 8) rows.Add(samples.data() + r);
  rows.Finish(&s.lo, &s.hi, &s.bad);
  return s;
}

TEST(RowStats, FormsAgreeWithEachOtherAndADirectPass) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> value(-1e6f, 1e6f);
  std::uniform_int_distribution<int> pick(0, 99);
  const float specials[] = {std::numeric_limits<float>::quiet_NaN(),
                            std::numeric_limits<float>::infinity(),
                            -std::numeric_limits<float>::infinity(),
                            FLT_MAX,
                            -FLT_MAX,
                            -0.0f,
                            std::numeric_limits<float>::denorm_min()};
  int with_bad = 0;
  for (int trial = 0; trial < 500; ++trial) {
    std::vector<float> samples(8 * (1 + trial % 16));
    for (float& v : samples) {
      const int p = pick(rng);
      v = p < 3 ? specials[(p + trial) % 7] : value(rng);
    }
    Stats direct{std::numeric_limits<float>::max(), std::numeric_limits<float>::lowest(), false};
    for (float v : samples) {
      if (!std::isfinite(v)) {
        direct.bad = true;
        continue;
      }
      direct.lo = std::min(direct.lo, v);
      direct.hi = std::max(direct.hi, v);
    }
    with_bad += direct.bad;
    const Stats scalar = Reduce<RowStatsScalar>(samples);
    EXPECT_EQ(scalar.bad, direct.bad) << trial;
    // With a non-finite sample the file is refused, and what lo and hi hold does not matter.
    if (!direct.bad) {
      EXPECT_EQ(scalar.lo, direct.lo) << trial;
      EXPECT_EQ(scalar.hi, direct.hi) << trial;
    }
#ifdef __SSE2__
    const Stats sse2 = Reduce<RowStatsSse2>(samples);
    EXPECT_EQ(sse2.bad, scalar.bad) << trial;
    // Lane for lane the same selection, so the same bits even where infinities took part.
    EXPECT_EQ(sse2.lo, scalar.lo) << trial;
    EXPECT_EQ(sse2.hi, scalar.hi) << trial;
    EXPECT_EQ(std::signbit(sse2.lo), std::signbit(scalar.lo)) << trial;
#endif
  }
  EXPECT_GT(with_bad, 50);  // both kinds of trial ran
  EXPECT_LT(with_bad, 450);
}

}  // namespace
}  // namespace isostream::volume_internal
