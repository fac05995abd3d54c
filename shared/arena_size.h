// The size of a TBB arena for a request's thread count: 0 (or less) is all cores, and a count
// past the cores is clamped to them (more threads only contend, and TBB warns on stderr that it
// ignores them). One rule for the hierarchy build and the extractor.
#pragma once

#include <tbb/info.h>
#include <tbb/task_arena.h>

#include <algorithm>

namespace isostream {

inline int ArenaSize(int threads) {
  return threads > 0 ? std::min(threads, tbb::info::default_concurrency())
                     : int(tbb::task_arena::automatic);
}

}  // namespace isostream
