// The sample histogram GetVolumeInfo sends: a pass over every sample (0.3-0.7 s at 513^3), so
// it is kept per volume and bin count, and one bin (what a client that wants only the bounds
// asks for) needs no pass at all.
#pragma once

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <vector>

#include "server/hierarchy/hierarchy.h"
#include "server/volume/volume.h"

namespace isostream::service {

class VolumeHistograms {
 public:
  // Counts of the volume's samples in `bins` equal bins over [min_value, max_value] (bin i
  // covers [min + i w, min + (i + 1) w), the last one closed; a constant volume's samples are
  // all in the last), read from the hierarchy (which holds the samples at its cube's origin
  // corner). nullopt if `cancelled` returned true during the pass; then nothing is kept.
  std::optional<std::vector<uint64_t>> Get(const Volume& v, const Hierarchy& h, int bins,
                                          const std::function<bool()>& cancelled) const {
    const auto& d = h.data_dims();
    if (bins == 1) return std::vector<uint64_t>{uint64_t(d[0]) * d[1] * d[2]};
    {
      std::lock_guard<std::mutex> lock(mu_);
      auto it = by_bins_.find(bins);
      if (it != by_bins_.end()) {
        it->second.last_use = ++uses_;
        return it->second.counts;
      }
    }
    const double lo = v.min_value, width = double(v.max_value) - v.min_value;
    const size_t last = size_t(bins) - 1;
    tbb::enumerable_thread_specific<std::vector<uint64_t>> local(size_t(bins), 0);
    std::atomic<bool> stopped{false};
    tbb::parallel_for(0, d[2], [&](int z) {
      if (stopped.load(std::memory_order_relaxed)) return;
      if (cancelled()) {
        stopped = true;
        return;
      }
      std::vector<uint64_t>& counts = local.local();
      for (int y = 0; y < d[1]; ++y)
        for (int x = 0; x < d[0]; ++x) {
          // Multiplied before dividing: (s - lo) * bins is exact for data of one scale (integer
          // data, say), and a correctly rounded quotient lands on a bin edge exactly where the
          // sample does (29 / 100 * 100 gave 28.999...: a bin short at every edge met). A
          // constant volume is all maximum: the last bin, the closed one.
          const double t = width > 0 ? (h.sample(x, y, z) - lo) * bins / width : double(last);
          ++counts[std::min(last, size_t(std::max(0.0, t)))];
        }
    });
    if (stopped) return std::nullopt;
    std::vector<uint64_t> counts(size_t(bins), 0);
    for (const auto& part : local)
      for (size_t i = 0; i < counts.size(); ++i) counts[i] += part[i];
    std::lock_guard<std::mutex> lock(mu_);
    if (by_bins_.size() >= kKept && by_bins_.count(bins) == 0) {
      // The least recently used goes: clearing them all made a client cycling through nine
      // bin counts pay a whole pass on every call.
      auto oldest = by_bins_.begin();
      for (auto it = by_bins_.begin(); it != by_bins_.end(); ++it)
        if (it->second.last_use < oldest->second.last_use) oldest = it;
      by_bins_.erase(oldest);
    }
    by_bins_[bins] = {counts, ++uses_};
    return counts;
  }

 private:
  struct Kept {
    std::vector<uint64_t> counts;
    uint64_t last_use = 0;
  };
  static constexpr size_t kKept = 8;  // bin counts kept per volume (at most 4096 x 8 B each)
  mutable std::mutex mu_;
  mutable std::map<int, Kept> by_bins_;
  mutable uint64_t uses_ = 0;
};

}  // namespace isostream::service
