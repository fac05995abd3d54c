// Test helper: caps the calling process's address space at what it maps now plus `extra` bytes,
// so that an allocation past that fails as it would on a machine out of memory. For death-test
// children only (the cap cannot be raised again); exits with status 3 if it cannot be set.
#pragma once

#include <sys/resource.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>

namespace isostream::testing {

inline void CapAddressSpaceAbove(rlim_t extra) {
  long pages = 0;
  std::ifstream("/proc/self/statm") >> pages;
  rlimit limit;
  limit.rlim_cur = limit.rlim_max = rlim_t(pages) * rlim_t(sysconf(_SC_PAGESIZE)) + extra;
  if (setrlimit(RLIMIT_AS, &limit) != 0) std::_Exit(3);
}

}  // namespace isostream::testing
