#include "server/extract/budget_search.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>


namespace isostream::extract_internal {

namespace {

constexpr int kMaxPasses = 60;
// Aiming has failed this often when a pass has not landed yet: bisect the codes from then on
// (at most ~15 more passes over the 2^15 codes).
constexpr int kAimedPasses = 8;

// Slopes measured or bounded are kept within these: a cliff or a plateau in the curve says
// little about the next octave.
constexpr double kSteepest = -6.0, kShallowest = -0.3;

double LogCount(int64_t n) { return std::log(double(std::max<int64_t>(n, 1))); }

}  // namespace

BudgetSearchResult FindBudgetCode(int64_t budget, int64_t limit, uint32_t top,
                                  const CountPass& count) {
  BudgetSearchResult res;
  auto pass = [&](uint32_t code, CountCurve* curve) {
    ++res.passes;
    const std::optional<int64_t> n = count(code, curve);
    if (!n) res.stopped = true;
    return n;
  };
  uint32_t hi;       // the smallest code known to fit
  int64_t count_hi;  // its count
  // A pass that fits also shows how far below its code the count stays the same: from there.
  auto fits = [&](uint32_t code, int64_t n, const CountCurve& curve) {
    hi = curve.largest_stop() < 0 ? 0 : std::min(code, uint32_t(curve.largest_stop()) + 1);
    count_hi = n;
  };
  CountCurve at_top_curve(top, top);
  const std::optional<int64_t> at_top = pass(top, &at_top_curve);
  if (!at_top) return res;
  res.code = top;
  if (*at_top > budget) return res;  // even the coarsest mesh is over budget: it is the answer
  fits(top, *at_top, at_top_curve);
  std::optional<uint32_t> lo;  // a code known not to fit
  // d log(count) / d log(eps), negative. Steep at first (coarse levels refine fast), aimed
  // low: the first probe costs little and its curve measures the real slope.
  double slope = -2.0;
  double aim = std::log(std::max(double(budget) / 16.0, 1.0));
  while (hi > 0 && !(lo && hi - *lo <= 1) && res.passes < kMaxPasses) {
    const uint32_t floor = lo ? *lo + 1 : 0;
    uint32_t k;
    if (res.passes > kAimedPasses) {
      k = floor + (hi - floor) / 2;
    } else {
      const double x_hi = std::log(EtaCodeEps(hi));
      k = EtaCodeAtLeast(std::exp(x_hi + (aim - LogCount(count_hi)) / slope));
      // Once a code past the limit is known, at least halve the codes between it and hi (the
      // upper half is also the cheaper one): a cliff in the count cannot hold the search.
      if (lo) k = std::max(k, *lo + (hi - *lo) / 2);
    }
    k = std::clamp(k, floor, hi - 1);
    CountCurve curve(k, hi);
    const std::optional<int64_t> n = pass(k, &curve);
    if (!n) return res;
    aim = std::log(2.0 * double(budget));  // between the budget and the limit ends the search
    if (*n > limit) {
      // Steeper than this between k and hi: aim again with it.
      lo = k;
      const double dx = std::log(EtaCodeEps(k)) - std::log(EtaCodeEps(hi));
      const double bound = (std::log(double(limit)) - LogCount(count_hi)) / dx;
      if (std::isfinite(bound) && bound < 0) slope = std::clamp(bound, kSteepest, slope);
      continue;
    }
    const std::vector<int64_t> counts = curve.Counts();
    if (*n > budget) {
      // The curve runs from over budget (at k) to within it (at hi): the first code within it
      // is the answer.
      for (size_t j = 1; j < counts.size(); ++j)
        if (counts[j] <= budget) {
          res.code = k + uint32_t(j);
          res.count = counts[j];
          return res;
        }
      lo = k;  // unreachable while passes are deterministic: the curve ends at count_hi
      continue;
    }
    // Fits. The slope over an octave or more (single codes step), to where the count halves.
    size_t j = std::min<size_t>(size_t{kEtaCodesPerOctave}, counts.size() - 1);
    while (j + 1 < counts.size() && counts[j] * 2 > *n) ++j;
    if (k > 0 && counts[j] < *n && counts[j] > 0) {
      const double measured = (LogCount(counts[j]) - LogCount(*n)) /
                              (std::log(EtaCodeEps(k + uint32_t(j))) - std::log(EtaCodeEps(k)));
      if (std::isfinite(measured)) slope = std::clamp(measured, kSteepest, kShallowest);
    }
    fits(k, *n, curve);
  }
  res.code = hi;
  res.count = count_hi;
  return res;
}

}  // namespace isostream::extract_internal
