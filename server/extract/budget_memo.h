// Remembers the eps the budget search found, per (isovalues, budget), for one hierarchy.
//
// The triangle count at an eps does not depend on the view (only the order does), so the eps
// for a budget is the same for every view of a volume: a session orbiting with a budget
// searches once (1-6 counting passes) instead of on every frame. The owner of a hierarchy
// owns its memo; entries are the search's own results, so a hit gives exactly the mesh a new
// search would.
#pragma once

#include <algorithm>
#include <cstdint>
#include <mutex>
#include <optional>
#include <vector>

namespace isostream {

class BudgetMemo {
 public:
  std::optional<double> Find(std::vector<float> isovalues, int64_t budget) const {
    std::sort(isovalues.begin(), isovalues.end());
    std::lock_guard<std::mutex> lock(mu_);
    for (const Entry& e : entries_)
      if (e.budget == budget && e.isovalues == isovalues) return e.eps;
    return std::nullopt;
  }

  // Most recent first; the oldest entry goes past kCapacity.
  void Store(std::vector<float> isovalues, int64_t budget, double eps) {
    std::sort(isovalues.begin(), isovalues.end());
    std::lock_guard<std::mutex> lock(mu_);
    entries_.erase(std::remove_if(entries_.begin(), entries_.end(),
                                  [&](const Entry& e) {
                                    return e.budget == budget && e.isovalues == isovalues;
                                  }),
                   entries_.end());
    entries_.insert(entries_.begin(), Entry{std::move(isovalues), budget, eps});
    if (entries_.size() > kCapacity) entries_.pop_back();
  }

 private:
  static constexpr size_t kCapacity = 64;
  struct Entry {
    std::vector<float> isovalues;  // sorted
    int64_t budget;
    double eps;
  };
  mutable std::mutex mu_;
  std::vector<Entry> entries_;
};

}  // namespace isostream
