// The search for the smallest eps whose mesh fits a triangle budget, over eta codes
// (count_curve.h: the count changes only at codes, so the answer is the smallest code k with
// count(EtaCodeEps(k)) <= budget, exactly). Private to server/extract; separate from the passes it
// drives so that its logic can be tested on synthetic count functions.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>

#include "server/extract/count_curve.h"
#include "server/extract/extractor.h"

namespace isostream::extract_internal {

// One count pass at the eps of `code`: the triangle count, or any value past the search's limit if
// the count passes it; when `curve` is given (range [code, curve->last()]) and the count is
// within the limit, the pass also fills it. nullopt: the pass was stopped (cancelled, or past
// a deadline); the search then ends at once.
using CountPass = std::function<std::optional<int64_t>(uint32_t code, CountCurve* curve)>;

struct BudgetSearchResult {
  uint32_t code = 0;
  std::optional<int64_t> count;  // at `code`, unless nothing fits (then the coarsest mesh)
  int passes = 0;
  bool stopped = false;
};

// Counts at `top` (the coarsest mesh; nothing fits if it is over budget), then probes below
// the smallest code known to fit: each pass that completes gathers the count at every code
// from its own up to that one, so a pass landing between the budget and the limit holds the
// answer. A pass that fits moves the top down and shows the local slope of log count over
// log eps, which aims the next pass at twice the budget; a pass past the limit marks a code
// that does not fit. The first probe aims at a sixteenth of the budget with a steep slope, so
// it is cheap whatever the volume.
BudgetSearchResult FindBudgetCode(int64_t budget, int64_t limit, uint32_t top,
                                  const CountPass& count);

}  // namespace isostream::extract_internal
