// The volumes a daemon serves, by name. Clients name catalogue entries only, never paths: the
// spec behind a name (a file or a generator) comes from the daemon's own configuration. With
// no catalogue configured, built-in generator specs ("buckyball:129") are accepted as names,
// up to a size limit, so a daemon serves something with no data at all.
//
// Volumes are prepared (loaded, padded, hierarchy built or read from the cache) on first use
// and kept. Concurrent first requests for one volume wait for a single build, which runs on the
// catalogue's own threads: a caller that gives up stops waiting at once (its session slot is
// free again), and the build goes on for the next one.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "server/extract/budget_memo.h"
#include "server/hierarchy/prepared_volume.h"
#include "server/service/volume_histogram.h"
#include "server/service/worker_pool.h"
#include "server/volume/quantization.h"
#include "shared/frame_codec.h"

namespace isostream::service {

// A prepared volume plus what frames of it are encoded with.
struct ServedVolume {
  std::string name;
  PreparedVolume prepared;
  // Positions of every frame are quantized on this one box (the volume's world bounds with a
  // small margin) so that vertices repeated across chunks and frames decode identically, at
  // enough bits for 1/64 of the smallest voxel step (see QuantizationFor).
  QuantizationBox box;
  int position_bits = 14;
  float position_error = 0;  // PositionErrorBound(box, position_bits), world units
  // The eps each (isovalues, budget) needed: views of one volume share it. Thread-safe.
  mutable BudgetMemo budget_memo;
  // GetVolumeInfo's sample histograms, per bin count. Thread-safe.
  VolumeHistograms histograms;
};

using ServedVolumePtr = std::shared_ptr<const ServedVolume>;

struct CatalogueOptions {
  std::map<std::string, std::string> volumes;  // empty: generators by spec name
  int max_generator_dim = 257;
  VolumeLimits limits;
  HierarchyCacheOptions cache;
  int build_threads = 0;
  // Generator volumes kept prepared at once (without a catalogue any client can name up to
  // 5 x max_generator_dim of them): at most this many, and stores (nearly all a prepared
  // volume holds: 105 MiB at 257^3, 805 MiB at 513^3, 6.1 GiB at 1025^3) of at most
  // max_generator_bytes together; a count alone let the clients of a --max-dim 1025 daemon make
  // it hold 8 x 6.6 GB. The least recently used idle volumes are dropped to make room; a volume
  // that does not fit even then (the others are being prepared, or it is larger than the
  // budget) is refused with RESOURCE_EXHAUSTED. Frames in progress keep a dropped volume alive
  // until they end, so the memory held can pass the budget for that long.
  int max_generator_volumes = 8;
  uint64_t max_generator_bytes = uint64_t{8} << 30;
  // Test hook: every preparation first sleeps this long, so daemon tests can have a volume
  // that is slow to prepare without big data (isostreamd takes it from the environment
  // variable ISOSTREAMD_TEST_PREPARE_DELAY_MS).
  std::chrono::milliseconds prepare_delay{0};
  // Test hook: every preparation first sleeps this long without looking at the stop flag, as a
  // step that cannot be interrupted does (ISOSTREAMD_TEST_PREPARE_STUCK_MS).
  std::chrono::milliseconds prepare_stuck{0};
  // How long a catalogue entry that failed to prepare answers with that failure before it is
  // tried again (a test hook shortens it: ISOSTREAMD_TEST_RETRY_FAILED_MS).
  std::chrono::milliseconds retry_failed_after{30000};
};

class VolumeCatalogue {
 public:
  explicit VolumeCatalogue(CatalogueOptions options);
  ~VolumeCatalogue();  // stops preparations in progress and waits for them to give up

  // OK if `name` may be asked for (it may still fail to load); NOT_FOUND otherwise, with a
  // message saying what names are accepted.
  // `canonical`, if given, becomes the name the volume is held under (noise:N:1 is noise:N).
  absl::Status Check(const std::string& name, std::string* canonical = nullptr) const;

  // Prepares on first use; later calls return the same object. While the volume is being
  // prepared the caller waits, until `cancelled` (may be empty; polled, so it must not block)
  // says it gave up: then CANCELLED, and the preparation goes on without it. After Stop, a
  // volume not prepared yet is UNAVAILABLE.
  absl::StatusOr<ServedVolumePtr> Get(const std::string& name,
                                      const std::function<bool()>& cancelled = {});

  // The daemon is shutting down: callers waiting for a preparation get UNAVAILABLE now,
  // preparations in progress give up at their next check (between steps, between the
  // hierarchy's tiles), and none start. Prepared volumes are still served.
  void Stop();
  // After Stop: waits until no preparation runs, at most `timeout`, and returns how many still
  // do (inside a step that cannot look at the stop flag, such as a file being read).
  int WaitForPreparations(std::chrono::milliseconds timeout);

  std::vector<std::string> Names() const;
  bool generators_allowed() const { return options_.volumes.empty(); }
  int max_generator_dim() const { return options_.max_generator_dim; }
  // Volumes prepared since start (a dropped and re-prepared generator counts twice).
  int prepared_count() const { return prepared_.load(); }
  // Volumes held now.
  int held_count() const;
  // Preparations in line for a preparation thread, and jobs waiting for one.
  size_t queued_preparations() const;

 private:
  // All fields under the catalogue's mu_.
  struct Entry {
    ServedVolumePtr served;
    bool preparing = false;    // a preparation job is queued or running: one per volume
    bool started = false;      // that job got past its queue and the memory gate
    bool abandoned = false;    // dropped before it started (out of line, or off the gate)
    int waiters = 0;           // Get calls waiting for the preparation
    uint64_t store_bytes = 0;  // of a generator volume, known from its spec before preparing
    uint64_t last_use = 0;
    // Why the last preparation failed, for the callers that waited for it. A catalogue entry
    // also keeps it as the answer until retry_failed_after has passed, so that clients asking
    // again do not re-read a bad file and fill the log each time.
    absl::Status failed;
    std::chrono::steady_clock::time_point failed_at;
  };
  // How often a waiting caller asks whether it gave up: well within the second a client that
  // left may wait for its slot.
  static constexpr std::chrono::milliseconds kCancelPoll{50};
  // Preparations run at once (more wait in line). Each uses every core already (TBB); a few
  // keep a small volume from waiting behind a large one. Preparations hold no session slot: a
  // started one goes on for the next client, but one still in line when its last waiter gives
  // up is dropped (AbandonLocked), so clients that come and go cannot queue work beyond these
  // threads.
  static constexpr int kPreparationThreads = 4;
  // The last waiter of a preparation not started yet gave up: the entry goes (a later request
  // starts afresh), out of the line if it is still there.
  void AbandonLocked(const std::string& name, const std::shared_ptr<Entry>& entry);
  // Puts a preparation in line, and a job on the pool to run the line unless enough are on it.
  void EnqueueLocked(const std::string& name, const std::shared_ptr<Entry>& entry);
  // A pool job: prepares what is in line, in order, until the line is empty.
  void RunLine();
  // Removes `entry` from the map unless a later request has put another under its name.
  void EraseIfCurrentLocked(const std::string& name, const std::shared_ptr<Entry>& entry);
  // Runs on a preparation thread: prepares `name` and hands the outcome to `entry`'s waiters.
  void Prepare(const std::string& name, const std::shared_ptr<Entry>& entry);
  // Drops idle generator volumes, least recently used first, until those left (`keep`
  // included) are within max_generator_volumes and max_generator_bytes; RESOURCE_EXHAUSTED if
  // `keep` cannot fit within the bytes.
  absl::Status MakeRoomLocked(const std::string& keep);
  uint64_t HeldBytesLocked() const;
  // Every preparation passes this gate, in arrival order. A generated volume's preparation
  // holds its samples beside the store it builds: it starts once the stores held and the
  // samples of the preparations running fit max_generator_bytes with its own, or when no other
  // one runs (so held stores stay within the budget, and preparations' samples too unless one
  // runs alone); catalogue volumes count no bytes there. False if the catalogue stopped or the
  // preparation was abandoned meanwhile. EndPreparationLocked gives the bytes back.
  bool StartPreparation(const std::string& name, const std::shared_ptr<Entry>& entry,
                        uint64_t sample_bytes);
  void EndPreparationLocked(uint64_t sample_bytes);
  CatalogueOptions options_;
  mutable std::mutex mu_;
  std::condition_variable prepared_cv_;  // a preparation ended
  std::map<std::string, std::shared_ptr<Entry>> entries_;
  std::atomic<int> prepared_{0};
  uint64_t use_clock_ = 0;
  std::atomic<bool> stop_{false};   // set under mu_, so that waiters cannot miss it
  int preparations_running_ = 0;    // running, under mu_
  std::deque<const Entry*> gate_;   // waiting at StartPreparation, in arrival order, under mu_
  uint64_t preparation_bytes_ = 0;  // their samples (StartPreparation), under mu_
  // Preparations not taken by a pool job yet, in arrival order, and how many jobs run the line
  // (at most kPreparationThreads), under mu_. The line, not the pool's queue, holds them, so an
  // abandoned one leaves at once: a client sending view after view for volumes that wait
  // behind long preparations queued a job (and its entry) for each, for as long as those ran.
  std::deque<std::pair<std::string, std::shared_ptr<Entry>>> line_;
  int line_runners_ = 0;
  // Declared last: destroyed (queued preparations run, threads joined) before what they use.
  WorkerPool preparations_{kPreparationThreads};
};

}  // namespace isostream::service
