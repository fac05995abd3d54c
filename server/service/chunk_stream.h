// The reactor shared by Extract and Session streams: the chunk write queue, the frame jobs
// (latest view wins), finishing exactly once, the session slot, and the idle and stall checks
// the reaper runs. Private to server/service.
#pragma once

#include <grpcpp/grpcpp.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <chrono>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>

#include "absl/status/status.h"
#include "server/service/frame_producer.h"
#include "server/service/retained_frame.h"
#include "server/service/service_core.h"

namespace isostream::service {

// A stream of frame chunks: the write queue (one write in flight), the latest-view-wins frame
// job, and finishing exactly once after the last write. Reactor is ServerWriteReactor (Extract)
// or ServerBidiReactor (Session); both have the same write and finish calls.
//
// Ownership: the reactor owns itself through `self_` until gRPC calls OnDone; frame jobs hold
// their own reference, so whichever of the two finishes last destroys the stream.
//
// Locking: every state change happens under mu_; gRPC calls (StartWrite, Finish, StartRead)
// are made after releasing it, because gRPC may run a reaction inline on the calling thread.
template <class Reactor>
class ChunkStream : public Reactor, public StreamBase {
 public:
  // `retains`: the stream keeps its last refined frame's cut to re-order it for the next view
  // of the same mesh (Session streams; an Extract call has no next view).
  ChunkStream(ServiceCore* core, grpc::CallbackServerContext* context, bool retains)
      : core_(core), context_(context), peer_(context->peer()), retains_(retains) {}

  // Creates a stream owned by itself (until OnDone) and registered for shutdown.
  template <class Derived, class... Args>
  static Derived* Create(ServiceCore* core, Args&&... args) {
    auto s = std::make_shared<Derived>(core, std::forward<Args>(args)...);
    s->self_ = s;
    core->Register(s.get(), s);
    return s.get();
  }

  bool Push(uint64_t generation, pb::FrameChunk&& chunk) override {
    bool start;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (finishing_ || generation != generation_) return false;
      queue_.push_back(std::move(chunk));
      start = TakeNextWriteLocked();
    }
    if (start) StartChunkWrite();
    return true;
  }

  size_t Queued() const override {
    std::lock_guard<std::mutex> lock(mu_);
    return queue_.size() + (write_in_flight_ ? 1 : 0);
  }

  void OnWriteDone(bool ok) override {
    if (ok) {
      core_->counters.chunks_sent.fetch_add(1);
      core_->counters.bytes_sent.fetch_add(int64_t(writing_.data().size()));
      if (writing_.last()) core_->counters.frames_sent.fetch_add(1);
    } else if (writing_.last()) {
      core_->counters.frames_cancelled.fetch_add(1);  // its last chunk never arrived
    }
    bool start;
    std::optional<grpc::Status> finish;
    {
      std::lock_guard<std::mutex> lock(mu_);
      write_in_flight_ = false;
      last_activity_ = Clock::now();
      // A failed write means the stream is broken (the client went away).
      if (!ok) FailLocked(grpc::Status(grpc::StatusCode::CANCELLED, "write failed"));
      start = TakeNextWriteLocked();
      CompleteIfIdleLocked();
      finish = TakeFinishLocked();
    }
    if (start) StartChunkWrite();
    if (finish) this->Finish(*finish);
  }

  void OnCancel() override {
    std::optional<grpc::Status> finish;
    {
      std::lock_guard<std::mutex> lock(mu_);
      FailLocked(grpc::Status(grpc::StatusCode::CANCELLED, "cancelled by the client"));
      finish = TakeFinishLocked();
    }
    if (finish) this->Finish(*finish);
  }

  void OnDone() override {
    if (admitted_) spdlog::debug("{}: stream closed ({})", peer_, finish_status_.error_message());
    {
      std::lock_guard<std::mutex> lock(mu_);
      done_ = true;
      if (!job_running_) ReleaseSlotLocked();  // already, once Finish was taken
    }
    core_->Unregister(this);
    std::shared_ptr<StreamBase> keep = std::move(self_);  // may destroy *this on return
  }

  void Reap(Clock::time_point now, std::chrono::milliseconds idle,
            std::chrono::milliseconds stall) override {
    std::optional<grpc::Status> finish;
    bool cancel_call = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (write_in_flight_ && !finish_called_ && !call_cancelled_ &&
          now - write_started_ >= stall) {
        // Finishing waits for the write in flight, which a client that stopped reading never
        // takes: the call is cancelled instead (the write then fails, and the stream finishes
        // with the status set here).
        spdlog::info("{}: the client took no data for {} ms, ending the stream", peer_,
                     stall.count());
        core_->counters.streams_stalled.fetch_add(1);
        FailLocked(
            grpc::Status(grpc::StatusCode::DEADLINE_EXCEEDED,
                         "the client read nothing for " + std::to_string(stall.count()) + " ms"));
        cancelling_ = true;  // no Finish (so no OnDone: context_ stays valid) until TryCancel
        call_cancelled_ = cancel_call = true;
      } else if (idle.count() > 0 && idle_timeout_applies_ && !finishing_ && !job_running_ &&
                 !pending_ && queue_.empty() && !write_in_flight_ && now - last_activity_ >= idle) {
        const auto seconds = std::chrono::duration_cast<std::chrono::seconds>(idle).count();
        spdlog::info("{}: session idle for {} s, closing it", peer_, seconds);
        core_->counters.sessions_idle_closed.fetch_add(1);
        FailLocked(grpc::Status(grpc::StatusCode::DEADLINE_EXCEEDED,
                                "session idle for " + std::to_string(seconds) +
                                    " s (no view request); open a new session to continue"));
        finish = TakeFinishLocked();
      }
    }
    if (cancel_call) {
      context_->TryCancel();
      std::lock_guard<std::mutex> lock(mu_);
      cancelling_ = false;
      finish = TakeFinishLocked();
    }
    if (finish) this->Finish(*finish);
  }

  void Drain() override {
    std::optional<grpc::Status> finish;
    {
      std::lock_guard<std::mutex> lock(mu_);
      draining_ = true;
      CompleteIfIdleLocked();
      finish = TakeFinishLocked();
    }
    if (finish) this->Finish(*finish);
  }

  // Runs the pending view, then any view that arrived meanwhile (only the latest is kept),
  // on a frame-pool thread. One job per stream at a time.
  void RunJobs() override {
    bool gone = false;  // gRPC is done with the call
    for (;;) {
      pb::ViewRequest view;
      ExtractRequest request;
      Clock::time_point received;
      uint64_t generation;
      std::shared_ptr<std::atomic<bool>> cancel;
      {
        std::lock_guard<std::mutex> lock(mu_);
        if (!pending_ || finishing_) {
          pending_.reset();
          job_running_ = false;
          if (finish_called_ || done_) ReleaseSlotLocked();  // the stream left it to this job
          gone = done_;
          last_activity_ = Clock::now();
          CompleteIfIdleLocked();
          break;
        }
        view = std::move(pending_->view);
        request = std::move(pending_->request);
        received = pending_->received;
        pending_.reset();
        generation = generation_;
        cancel = cancel_;
      }
      const absl::Status s = RunView(view, request, generation, cancel.get(), received);
      if (!s.ok()) {
        std::lock_guard<std::mutex> lock(mu_);
        // CANCELLED from a newer view or from the client leaving is not an error of the
        // stream; anything else ends it with that status.
        const bool superseded = generation != generation_;
        if (!superseded && s.code() != absl::StatusCode::kCancelled) {
          spdlog::info("{}: request {} failed: {}", peer_, view.request_id(), s.ToString());
          FailLocked(ToGrpc(s));
        }
      }
    }
    if (gone) return;  // nothing to finish
    std::optional<grpc::Status> finish;
    {
      std::lock_guard<std::mutex> lock(mu_);
      finish = TakeFinishLocked();
    }
    if (finish) this->Finish(*finish);
  }

 protected:
  struct Pending {
    pb::ViewRequest view;
    ExtractRequest request;
    Clock::time_point received;
  };

  // Ends the stream now, before admission or on a rejected request.
  void Reject(const absl::Status& why) {
    std::optional<grpc::Status> finish;
    {
      std::lock_guard<std::mutex> lock(mu_);
      FailLocked(ToGrpc(why));
      finish = TakeFinishLocked();
    }
    if (finish) this->Finish(*finish);
  }

  // Replaces the frame in progress by `p`: the old frame's cancel flag is set and its queued
  // chunks dropped (a write already in flight completes). Returns true if the caller must
  // start a job (none running).
  bool StartViewLocked(Pending p) {
    ++generation_;
    cancel_->store(true);
    cancel_ = std::make_shared<std::atomic<bool>>(false);
    // A view replaced before its frame started counts as a cancelled frame too.
    DropQueuedLocked();
    pending_ = std::move(p);
    if (job_running_) return false;
    job_running_ = true;
    return true;
  }

  void SubmitJob() {
    std::shared_ptr<StreamBase> self = shared_from_this();
    core_->frames->Submit([self] { self->RunJobs(); });
  }

  // Records an error finish: drops what is queued and stops the frame in progress.
  void FailLocked(grpc::Status status) {
    if (finishing_) return;
    finishing_ = true;
    finish_status_ = std::move(status);
    cancel_->store(true);
    DropQueuedLocked();
  }

  // Drops the queued chunks and the view waiting for a job: both frames count as cancelled (a
  // running frame counts itself when it stops).
  void DropQueuedLocked() {
    for (const auto& c : queue_)
      if (c.last()) core_->counters.frames_cancelled.fetch_add(1);
    queue_.clear();
    if (pending_) core_->counters.frames_cancelled.fetch_add(1);
    pending_.reset();
  }

  // Finishes normally once there is nothing left to do and nothing more will come.
  void CompleteIfIdleLocked() {
    if (finishing_ || job_running_ || pending_ || !queue_.empty() || write_in_flight_) return;
    if (draining_ && !reads_done_) {
      finishing_ = true;
      finish_status_ = grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server is shutting down");
    } else if (reads_done_) {
      finishing_ = true;
      finish_status_ = grpc::Status::OK;
    }
  }

  std::optional<grpc::Status> TakeFinishLocked() {
    if (!finishing_ || finish_called_ || write_in_flight_ || cancelling_) return std::nullopt;
    finish_called_ = true;
    if (!job_running_) ReleaseSlotLocked();
    return finish_status_;
  }

  // The slot goes back as the stream is finished, before the client can see its status (gRPC
  // calls OnDone only after that, and a client opening its next session at once was refused
  // for a slot still held), but not while a frame job runs: a cancelled job keeps it until it
  // ends, or clients that leave at once could keep any number of jobs running.
  void ReleaseSlotLocked() {
    if (!admitted_ || slot_released_) return;
    slot_released_ = true;
    core_->ReleaseSlot();
  }

  // Writes writing_'s bytes (gRPC reads them until OnWriteDone; every call writes bytes,
  // service.h).
  void StartChunkWrite() {
    bool own = false;
    writing_bytes_.Clear();  // the writer wants an empty buffer; the last write is done
    const grpc::Status s =
        grpc::SerializationTraits<pb::FrameChunk>::Serialize(writing_, &writing_bytes_, &own);
    // Only a message past 2 GB fails (chunks are a few MB): the client then sees bytes that
    // do not parse, not a stream that stops.
    if (!s.ok()) spdlog::error("{}: cannot serialize a chunk: {}", peer_, s.error_message());
    this->StartWrite(&writing_bytes_);
  }

  bool TakeNextWriteLocked() {
    if (write_in_flight_ || queue_.empty() || finishing_) return false;
    writing_ = std::move(queue_.front());
    queue_.pop_front();
    write_in_flight_ = true;
    write_started_ = Clock::now();
    return true;
  }

  absl::Status RunView(const pb::ViewRequest& view, const ExtractRequest& request,
                       uint64_t generation, std::atomic<bool>* cancel, Clock::time_point received) {
    // The wait for a preparation ends as soon as the view is superseded or the client leaves:
    // the job, and with it the stream's slot, is not held until the preparation ends.
    auto volume = core_->catalogue.Get(view.volume(), [cancel] { return cancel->load(); });
    // Superseded while the volume was being prepared, whether or not that succeeded (a failed
    // one was counted nowhere).
    if (cancel->load()) {
      core_->counters.frames_cancelled.fetch_add(1);
      return absl::CancelledError("superseded");
    }
    if (!volume.ok()) return volume.status();
    // The deadline runs from here, once the volume is ready: waiting for a preparation (the
    // preload's, this view's own, or the one a view it superseded was waiting for) is no
    // frame's work, and a 1025^3 volume takes longer to prepare than the default 30 s. (Measured
    // from the wait in Get alone, a view read while its predecessor waited was charged the rest
    // of that wait.) The preparation is bounded by the loader's limits instead, and a client that
    // gave up meanwhile stopped waiting for it (checked above).
    const Clock::time_point deadline_from = Clock::now();
    if (!retains_)
      return core_->producer.Run(**volume, view, request, generation, cancel, this, received,
                                 deadline_from, &coarse_hint_, nullptr);
    // The retained frame is this stream's for the view (other streams may free it between
    // views, when their own frames need the memory).
    std::lock_guard<std::mutex> using_retained(retained_.mutex());
    return core_->producer.Run(**volume, view, request, generation, cancel, this, received,
                               deadline_from, &coarse_hint_, &retained_);
  }

  ServiceCore* core_;
  grpc::CallbackServerContext* context_;  // valid until OnDone; jobs may outlive it
  const std::string peer_;
  std::shared_ptr<StreamBase> self_;
  const bool retains_;
  bool admitted_ = false;  // holds a session slot (set before any other thread sees the stream)
  bool idle_timeout_applies_ = false;              // Session streams, once admitted; under mu_
  CoarseHint coarse_hint_;                         // used by the one running job only
  RetainedFrame retained_{&core_->retain_budget};  // likewise

  mutable std::mutex mu_;
  std::deque<pb::FrameChunk> queue_;
  pb::FrameChunk writing_;          // the chunk in flight
  grpc::ByteBuffer writing_bytes_;  // its bytes, which gRPC reads until OnWriteDone
  bool write_in_flight_ = false;
  Clock::time_point write_started_;  // of the write in flight
  bool cancelling_ = false;          // Reap is cancelling the call: Finish waits
  bool call_cancelled_ = false;      // by Reap, once
  uint64_t generation_ = 0;
  std::shared_ptr<std::atomic<bool>> cancel_ = std::make_shared<std::atomic<bool>>(false);
  std::optional<Pending> pending_;
  bool job_running_ = false;
  bool done_ = false;        // gRPC called OnDone
  bool reads_done_ = false;  // no more requests will come
  bool draining_ = false;
  bool finishing_ = false;
  bool finish_called_ = false;
  bool slot_released_ = false;
  grpc::Status finish_status_;
  // Last request read, write completed or frame job ended; the idle clock runs from here.
  Clock::time_point last_activity_ = Clock::now();
};

}  // namespace isostream::service
