// Process-wide allocator setting for programs that extract frame after frame (isostreamd) or
// decode chunk after chunk (isostream fetch, isostream-view: each chunk's decode buffers are a
// few hundred KB, which glibc would otherwise map and unmap per chunk).
//
// A 1 M-triangle frame's mesh is ~25 MB in a few large vectors. By default glibc serves such
// blocks with mmap and returns them with munmap, so every frame faults in fresh zeroed pages
// (~6 k faults, 20-30 ms on a VM) while it appends its parts. Serving blocks up to 32 MB from
// the heap and never trimming it keeps freed frame memory for the next frame: the ordered
// join of a 1 M-triangle frame went from 34-42 ms to 13-21 ms (BENCHMARKS.md). The cost is
// that the process keeps its peak heap; long-lived blocks above 32 MB (hierarchy bricks) still
// come from mmap and go back when freed.
//
// It keeps it per arena, though: glibc gives threads up to 8 heaps per core, and each kept the
// peak of the frames and preparations its threads happened to run. isostreamd's RSS climbed from
// 230 MB to 600-700 MB over 24-45 prepare/evict cycles of 257^3 volumes with --generator-mb 150
// (tests/bench/daemon_rss_cycles.sh); with 2 arenas (this 2-core machine's cores) it stays at
// 170-250 MB, the held volume plus one frame's buffers. One arena per core, and never more than
// 8: on a large host one per core would again be about one per thread (frame jobs, encoders,
// preparations, TBB and gRPC), which is what let the peaks pile up. The hot paths do not
// allocate: bench_stream's frame times with 2 arenas were within its run-to-run spread of the
// default's; more threads than arenas may wait on malloc's locks, but only between nodes'
// work, when a frame, chunk or preparation starts or grows.
#pragma once

#include <malloc.h>

#include <algorithm>
#include <thread>

namespace isostream {

inline void KeepFreedMemoryForReuse() {
  mallopt(M_MMAP_THRESHOLD, 32 << 20);  // glibc's largest allowed value on 64-bit
  mallopt(M_TRIM_THRESHOLD, 1 << 30);
  mallopt(M_ARENA_MAX, int(std::clamp(std::thread::hardware_concurrency(), 2u, 8u)));
}

// Gives the heap's free pages back to the system now: after a rare event that freed much more
// than frames reuse (a volume's grid once its hierarchy is built: 540 MB at 513^3, in 2 KB
// leaves; or whatever a preparation that failed had made). The next frame faults its buffers in
// again once (~10 ms).
inline void ReturnFreedMemory() { malloc_trim(0); }

}  // namespace isostream
