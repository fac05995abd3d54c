// Server-wide counters, updated lock-free by the streams and read by GetServerStats.
#pragma once

#include <atomic>
#include <cstdint>

namespace isostream::service {

struct ServerCounters {
  std::atomic<int64_t> sessions_open{0};
  std::atomic<int64_t> sessions_total{0};
  std::atomic<int64_t> sessions_closed{0};
  std::atomic<int64_t> sessions_rejected{0};
  std::atomic<int64_t> sessions_idle_closed{0};
  std::atomic<int64_t> streams_stalled{0};  // ended: the client took no data for a deadline
  std::atomic<int64_t> frames_started{0};
  std::atomic<int64_t> frames_sent{0};
  std::atomic<int64_t> frames_cancelled{0};
  std::atomic<int64_t> frames_failed{0};  // started, ended by the server with an error
  std::atomic<int64_t> frames_reordered{0};  // drawn from a stream's retained frame
  std::atomic<int64_t> chunks_sent{0};
  std::atomic<int64_t> bytes_sent{0};
};

}  // namespace isostream::service
