// The daemon's state behind every call: configuration, counters, the volume catalogue, the
// worker pools and frame producer, admission (session slots), the registry of open streams
// that shutdown and the idle reaper walk, and the catalogue preload. Private to server/service.
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "absl/status/status.h"
#include "server/service/catalogue.h"
#include "server/service/config.h"
#include "server/service/frame_producer.h"
#include "server/service/retained_frame.h"
#include "server/service/stats.h"
#include "server/service/worker_pool.h"

namespace isostream::service {

using Clock = std::chrono::steady_clock;

inline grpc::Status ToGrpc(const absl::Status& s) {
  // absl and gRPC share the canonical code numbering.
  return grpc::Status(grpc::StatusCode(int(s.code())), std::string(s.message()));
}

// What every frame stream shares, independent of its gRPC reactor type.
class StreamBase : public ChunkSink, public std::enable_shared_from_this<StreamBase> {
 public:
  virtual ~StreamBase() = default;
  virtual void Drain() = 0;
  virtual void RunJobs() = 0;
  // Ends the stream with DEADLINE_EXCEEDED if it is subject to the idle timeout (`idle`, 0:
  // none) and has had no request and nothing in flight since `now - idle`, or if the client
  // has not taken a write for `stall` (it stopped reading).
  virtual void Reap(Clock::time_point now, std::chrono::milliseconds idle,
                    std::chrono::milliseconds stall) = 0;
};

struct ServiceCore {
  explicit ServiceCore(const DaemonConfig& c);

  // Whether the call carries the configured bearer token (any call, when none is set).
  bool Authorized(const grpc::CallbackServerContext* ctx) const;
  // Takes a stream slot, or says why not.
  absl::Status Admit();

  void Register(StreamBase* s, std::weak_ptr<StreamBase> w) {
    std::lock_guard<std::mutex> lock(streams_mu);
    streams[s] = std::move(w);
  }
  // Forgets a stream gRPC is done with.
  void Unregister(StreamBase* s) {
    {
      std::lock_guard<std::mutex> lock(streams_mu);
      streams.erase(s);
    }
    streams_cv.notify_all();
  }
  // Gives back what Admit took: as a stream finishes (or its frame job ends, if that outlived
  // the finish), or before a volume-info call finishes.
  void ReleaseSlot() {
    counters.sessions_open.fetch_sub(1);
    counters.sessions_closed.fetch_add(1);
  }

  // Ends Session streams that have been idle for config.limits.idle_timeout_s: a thread that
  // checks every open stream each tenth of the timeout (between 0.05 and 1 s). Not started
  // when the timeout is 0.
  void StartIdleReaper();
  void StopIdleReaper();
  // config.preload: prepares the catalogue's volumes one by one on a thread of its own, until
  // done or shutting down (VolumeCatalogue::Stop ends the one in progress).
  void StartPreload();
  void JoinPreload();

  DaemonConfig config;
  ServerCounters counters;
  // Streams' retained frames (declared before the pools: the last stream may go with them).
  RetainBudget retain_budget;
  VolumeCatalogue catalogue;
  std::atomic<bool> shutting_down{false};
  std::mutex streams_mu;
  std::condition_variable streams_cv;
  std::map<StreamBase*, std::weak_ptr<StreamBase>> streams;
  std::thread preloader;
  std::thread idle_reaper;
  std::mutex reaper_mu;
  std::condition_variable reaper_cv;
  bool reaper_stop = false;
  // Frame jobs wait for encoder jobs: the frame pool is declared last so it is destroyed
  // (drained and joined) first.
  std::unique_ptr<WorkerPool> encoders;
  std::unique_ptr<WorkerPool> frames;
  FrameProducer producer;
};

}  // namespace isostream::service
