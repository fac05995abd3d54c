#include "server/service/service.h"

#include <grpcpp/impl/codegen/proto_utils.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <map>
#include <mutex>
#include <optional>
#include <thread>

#include "server/service/catalogue.h"
#include "server/service/frame_producer.h"
#include "server/service/stats.h"
#include "server/service/worker_pool.h"

namespace isostream::service {

using Clock = std::chrono::steady_clock;

grpc::Status ToGrpc(const absl::Status& s) {
  // absl and gRPC share the canonical code numbering.
  return grpc::Status(grpc::StatusCode(int(s.code())), std::string(s.message()));
}

class StreamBase;

struct ServiceCore {
  explicit ServiceCore(const DaemonConfig& c)
      : config(c),
        retain_budget(c.retain_mb << 20),
        catalogue([&] {
          CatalogueOptions o;
          o.volumes = c.volumes;
          o.max_generator_dim = c.limits.max_dim;
          o.limits.max_dim = c.volumes.empty() ? c.limits.max_dim : VolumeLimits{}.max_dim;
          if (!c.no_cache) o.cache.dir = c.cache_dir.empty() ? DefaultCacheDir() : c.cache_dir;
          o.cache.max_bytes = uint64_t(c.cache_max_mb) << 20;
          o.build_threads = c.threads;
          return o;
        }()),
        encoders(std::make_unique<WorkerPool>(
            c.threads > 0 ? c.threads : int(std::max(1u, std::thread::hardware_concurrency())))),
        // One thread per admissible stream: a frame job blocks while its client reads slowly,
        // and must not hold up other streams' frames.
        frames(std::make_unique<WorkerPool>(c.limits.max_sessions + 1)),
        producer(
            [&] {
              FrameSettings f;
              f.chunk_triangles = c.chunk_triangles;
              f.first_chunk_triangles = c.first_chunk_triangles;
              f.max_queued_chunks = c.max_queued_chunks;
              f.coarse_triangles = c.coarse_triangles;
              f.max_triangles = c.limits.max_triangles;
              f.deadline_ms = c.limits.deadline_ms;
              return f;
            }(),
            encoders.get(), &counters) {}

  bool Authorized(const grpc::CallbackServerContext* ctx) const {
    if (config.token.empty()) return true;
    const auto& md = ctx->client_metadata();
    auto it = md.find("authorization");
    if (it == md.end()) return false;
    const std::string given(it->second.data(), it->second.size());
    const std::string expected = "Bearer " + config.token;
    // Constant time in the token's content, so timing does not reveal a matching prefix.
    unsigned diff = given.size() != expected.size();
    for (size_t i = 0; i < std::min(given.size(), expected.size()); ++i)
      diff |= unsigned(given[i] ^ expected[i]);
    return diff == 0;
  }

  // Takes a stream slot, or says why not.
  absl::Status Admit() {
    if (shutting_down.load()) return absl::UnavailableError("the server is shutting down");
    int64_t open = counters.sessions_open.load();
    do {
      if (open >= config.limits.max_sessions) {
        counters.sessions_rejected.fetch_add(1);
        return absl::ResourceExhaustedError("the server has its maximum of " +
                                            std::to_string(config.limits.max_sessions) +
                                            " sessions open; try again later");
      }
    } while (!counters.sessions_open.compare_exchange_weak(open, open + 1));
    counters.sessions_total.fetch_add(1);
    return absl::OkStatus();
  }

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
  // done or shutting down (a preparation in progress is not interrupted).
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

void ServiceCore::StartIdleReaper() {
  const std::chrono::milliseconds idle = std::chrono::seconds(config.limits.idle_timeout_s);
  // A write the client has not taken for a whole frame deadline will not be: the frame that
  // made it has failed by then (it waits that long for room in the stream at most).
  const std::chrono::milliseconds stall(config.limits.deadline_ms);
  // A stream ends at most a tenth of its timeout (or a second) after it became idle enough.
  const auto shortest = idle.count() > 0 ? std::min(idle, stall) : stall;
  const auto period = std::clamp<std::chrono::milliseconds>(
      shortest / 10, std::chrono::milliseconds(50), std::chrono::milliseconds(1000));
  idle_reaper = std::thread([this, idle, stall, period] {
    std::unique_lock<std::mutex> lock(reaper_mu);
    while (!reaper_cv.wait_for(lock, period, [&] { return reaper_stop; })) {
      std::vector<std::shared_ptr<StreamBase>> open;
      {
        std::lock_guard<std::mutex> streams_lock(streams_mu);
        for (auto& [ptr, weak] : streams)
          if (auto s = weak.lock()) open.push_back(std::move(s));
      }
      const Clock::time_point now = Clock::now();
      for (auto& s : open) s->Reap(now, idle, stall);
    }
  });
}

void ServiceCore::StartPreload() {
  if (!config.preload || config.volumes.empty()) return;
  preloader = std::thread([this] {
    const auto t0 = Clock::now();
    int prepared = 0;
    for (const std::string& name : catalogue.Names()) {
      if (shutting_down.load()) return;
      if (catalogue.Get(name).ok()) ++prepared;  // failures are logged by the catalogue
    }
    spdlog::info("preloaded {} of {} catalogue volumes in {:.1f} s", prepared,
                 config.volumes.size(), std::chrono::duration<double>(Clock::now() - t0).count());
  });
}

void ServiceCore::JoinPreload() {
  if (preloader.joinable()) preloader.join();
}

void ServiceCore::StopIdleReaper() {
  {
    std::lock_guard<std::mutex> lock(reaper_mu);
    reaper_stop = true;
  }
  reaper_cv.notify_all();
  if (idle_reaper.joinable()) idle_reaper.join();
}

// Requests arrive as bytes (service.h, ServiceBase): parsed here, so one that does not parse
// gets INVALID_ARGUMENT naming the message type expected.
template <class Message>
absl::Status Parse(const grpc::ByteBuffer& bytes, Message* message) {
  grpc::ByteBuffer copy(bytes);  // shares the slices; Deserialize consumes its buffer
  message->Clear();
  if (grpc::SerializationTraits<Message>::Deserialize(&copy, message).ok()) return absl::OkStatus();
  return absl::InvalidArgumentError("the request is not an " + Message::descriptor()->full_name());
}

// The start of every unary call: the token, then the request. False once it has finished the
// call with the reason.
template <class Request>
bool AcceptUnary(const ServiceCore& core, grpc::CallbackServerContext* context,
                 grpc::ServerUnaryReactor* reactor, const grpc::ByteBuffer& bytes,
                 Request* request) {
  if (!core.Authorized(context)) {
    reactor->Finish(grpc::Status(grpc::StatusCode::UNAUTHENTICATED, "missing or wrong token"));
    return false;
  }
  const absl::Status parsed = Parse(bytes, request);
  if (!parsed.ok()) reactor->Finish(ToGrpc(parsed));
  return parsed.ok();
}

// Finishes a unary call OK with `response`, sent as bytes.
template <class Message>
void FinishWith(grpc::ServerUnaryReactor* reactor, const Message& response,
                grpc::ByteBuffer* bytes) {
  bool own = false;
  if (!grpc::SerializationTraits<Message>::Serialize(response, bytes, &own).ok())
    return reactor->Finish(
        grpc::Status(grpc::StatusCode::INTERNAL, "cannot serialize the response"));
  reactor->Finish(grpc::Status::OK);
}

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
  ChunkStream(ServiceCore* core, grpc::CallbackServerContext* context)
      : core_(core), context_(context), peer_(context->peer()) {}

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
    for (const auto& c : queue_)
      if (c.last()) core_->counters.frames_cancelled.fetch_add(1);
    queue_.clear();
    // A view replaced before its frame started counts as a cancelled frame too.
    if (pending_) core_->counters.frames_cancelled.fetch_add(1);
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
    queue_.clear();
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
    auto volume = core_->catalogue.Get(view.volume());
    if (!volume.ok()) return volume.status();
    if (cancel->load()) return absl::CancelledError("superseded");
    // The retained frame is this stream's for the view (other streams may free it between
    // views, when their own frames need the memory).
    std::lock_guard<std::mutex> using_retained(retained_.mutex());
    return core_->producer.Run(**volume, view, request, generation, cancel, this, received,
                               &coarse_hint_, &retained_);
  }

  ServiceCore* core_;
  grpc::CallbackServerContext* context_;  // valid until OnDone; jobs may outlive it
  const std::string peer_;
  std::shared_ptr<StreamBase> self_;
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

// Extract: one request, its frame(s), then OK.
class ExtractStream final : public ChunkStream<grpc::ServerWriteReactor<grpc::ByteBuffer>> {
 public:
  ExtractStream(ServiceCore* core, grpc::CallbackServerContext* context)
      : ChunkStream(core, context) {}

  void Start(const grpc::ByteBuffer& bytes) {
    if (!core_->Authorized(context_))
      return Reject(absl::UnauthenticatedError("missing or wrong bearer token"));
    pb::ViewRequest view;
    const absl::Status parsed = Parse(bytes, &view);
    if (!parsed.ok()) return Reject(parsed);
    auto request = ToExtractRequest(view, core_->config.limits, core_->config.threads);
    if (!request.ok()) return Reject(request.status());
    const absl::Status known = core_->catalogue.Check(view.volume());
    if (!known.ok()) return Reject(known);
    const absl::Status admitted = core_->Admit();
    if (!admitted.ok()) return Reject(admitted);
    bool submit;
    {
      std::lock_guard<std::mutex> lock(mu_);
      admitted_ = true;
      reads_done_ = true;  // the one request is all there is
      submit = StartViewLocked({view, std::move(*request), Clock::now()});
    }
    if (submit) SubmitJob();
  }
};

// Session: views in, frames out, latest view wins.
class SessionStream final
    : public ChunkStream<grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>> {
 public:
  SessionStream(ServiceCore* core, grpc::CallbackServerContext* context)
      : ChunkStream(core, context) {}

  void Start() {
    if (!core_->Authorized(context_))
      return Reject(absl::UnauthenticatedError("missing or wrong bearer token"));
    const absl::Status admitted = core_->Admit();
    if (!admitted.ok()) return Reject(admitted);
    {
      std::lock_guard<std::mutex> lock(mu_);
      admitted_ = true;
      idle_timeout_applies_ = true;
      last_activity_ = Clock::now();
    }
    spdlog::debug("{}: session opened", peer_);
    StartRead(&incoming_bytes_);
  }

  void OnReadDone(bool ok) override {
    const Clock::time_point received = Clock::now();
    std::optional<grpc::Status> finish;
    if (!ok) {
      std::lock_guard<std::mutex> lock(mu_);
      reads_done_ = true;
      CompleteIfIdleLocked();
      finish = TakeFinishLocked();
    } else {
      const absl::Status parsed = Parse(incoming_bytes_, &incoming_);
      incoming_bytes_.Clear();
      absl::StatusOr<ExtractRequest> request =
          parsed.ok() ? ToExtractRequest(incoming_, core_->config.limits, core_->config.threads)
                      : absl::StatusOr<ExtractRequest>(parsed);
      if (request.ok()) {
        const absl::Status known = core_->catalogue.Check(incoming_.volume());
        if (!known.ok()) request = known;
      }
      bool submit = false, read_more = false;
      {
        std::lock_guard<std::mutex> lock(mu_);
        last_activity_ = received;
        if (!request.ok()) {
          FailLocked(ToGrpc(request.status()));
        } else if (!finishing_ && !draining_) {
          submit = StartViewLocked({incoming_, std::move(*request), received});
          read_more = true;
        }
        finish = TakeFinishLocked();
      }
      if (read_more) StartRead(&incoming_bytes_);
      if (submit) SubmitJob();
    }
    if (finish) Finish(*finish);
  }

 private:
  grpc::ByteBuffer incoming_bytes_;
  pb::ViewRequest incoming_;
};

IsostreamService::IsostreamService(const DaemonConfig& config)
    : core_(std::make_shared<ServiceCore>(config)) {
  core_->StartIdleReaper();
  core_->StartPreload();
}

IsostreamService::~IsostreamService() {
  core_->shutting_down.store(true);  // a preload stops after the volume in progress
  core_->JoinPreload();
  core_->StopIdleReaper();
  // Jobs first (they use the encoders), then the encoders.
  core_->frames.reset();
  core_->encoders.reset();
}

grpc::ServerUnaryReactor* IsostreamService::ListVolumes(grpc::CallbackServerContext* context,
                                                        const grpc::ByteBuffer* request_bytes,
                                                        grpc::ByteBuffer* response_bytes) {
  auto* reactor = context->DefaultReactor();
  pb::ListVolumesRequest request;
  if (!AcceptUnary(*core_, context, reactor, *request_bytes, &request)) return reactor;
  pb::ListVolumesResponse response;
  for (const auto& name : core_->catalogue.Names()) response.add_names(name);
  response.set_generators_allowed(core_->catalogue.generators_allowed());
  response.set_max_generator_dim(core_->catalogue.max_generator_dim());
  FinishWith(reactor, response, response_bytes);
  return reactor;
}

grpc::ServerUnaryReactor* IsostreamService::GetVolumeInfo(grpc::CallbackServerContext* context,
                                                          const grpc::ByteBuffer* request_bytes,
                                                          grpc::ByteBuffer* response_bytes) {
  auto* reactor = context->DefaultReactor();
  pb::GetVolumeInfoRequest request;
  if (!AcceptUnary(*core_, context, reactor, *request_bytes, &request)) return reactor;
  const int bins = request.histogram_bins() == 0 ? 64 : request.histogram_bins();
  absl::Status known = core_->catalogue.Check(request.name());
  if (known.ok() && (bins < 1 || bins > 4096))
    known = absl::InvalidArgumentError("histogram_bins must be in 1..4096");
  // Preparing may build a hierarchy (seconds) and the histogram reads every sample: the call
  // takes a stream slot like a frame (so a flood of them is refused, not queued ahead of
  // frames), and a caller that gives up stops it.
  if (known.ok()) known = core_->Admit();
  if (!known.ok()) {
    reactor->Finish(ToGrpc(known));
    return reactor;
  }
  ServiceCore* core = core_.get();
  const std::string name = request.name();
  core_->frames->Submit([core, name, bins, reactor, response_bytes, context] {
    pb::VolumeInfo info;
    const auto finish = [&](const grpc::Status& status) {
      core->ReleaseSlot();
      if (status.ok()) return FinishWith(reactor, info, response_bytes);
      reactor->Finish(status);
    };
    const grpc::Status gone(grpc::StatusCode::CANCELLED, "cancelled by the client");
    if (context->IsCancelled()) return finish(gone);
    auto served = core->catalogue.Get(name);
    if (!served.ok()) return finish(ToGrpc(served.status()));
    const Volume& v = *(*served)->prepared.volume;
    const Hierarchy& h = *(*served)->prepared.hierarchy;
    info.set_name(name);
    for (int a = 0; a < 3; ++a) info.add_dims(v.dims[a]);
    info.mutable_spacing()->set_x(v.spacing[0]);
    info.mutable_spacing()->set_y(v.spacing[1]);
    info.mutable_spacing()->set_z(v.spacing[2]);
    info.mutable_origin()->set_x(v.origin[0]);
    info.mutable_origin()->set_y(v.origin[1]);
    info.mutable_origin()->set_z(v.origin[2]);
    info.set_min_value(v.min_value);
    info.set_max_value(v.max_value);
    info.set_position_error((*served)->position_error);
    const auto counts =
        (*served)->histograms.Get(v, h, bins, [context] { return context->IsCancelled(); });
    if (!counts) return finish(gone);
    for (uint64_t c : *counts) info.add_histogram(c);
    finish(grpc::Status::OK);
  });
  return reactor;
}

grpc::ServerUnaryReactor* IsostreamService::GetServerStats(grpc::CallbackServerContext* context,
                                                           const grpc::ByteBuffer* request_bytes,
                                                           grpc::ByteBuffer* response_bytes) {
  auto* reactor = context->DefaultReactor();
  pb::GetServerStatsRequest request;
  if (!AcceptUnary(*core_, context, reactor, *request_bytes, &request)) return reactor;
  FinishWith(reactor, Stats(), response_bytes);
  return reactor;
}

grpc::ServerWriteReactor<grpc::ByteBuffer>* IsostreamService::Extract(
    grpc::CallbackServerContext* context, const grpc::ByteBuffer* request) {
  auto* s = ExtractStream::Create<ExtractStream>(core_.get(), context);
  s->Start(*request);
  return s;
}

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* IsostreamService::Session(
    grpc::CallbackServerContext* context) {
  auto* s = SessionStream::Create<SessionStream>(core_.get(), context);
  s->Start();
  return s;
}

void IsostreamService::BeginShutdown() {
  core_->shutting_down.store(true);
  std::vector<std::shared_ptr<StreamBase>> open;
  {
    std::lock_guard<std::mutex> lock(core_->streams_mu);
    for (auto& [ptr, weak] : core_->streams)
      if (auto s = weak.lock()) open.push_back(std::move(s));
  }
  for (auto& s : open) s->Drain();
}

bool IsostreamService::WaitForStreams(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(core_->streams_mu);
  return core_->streams_cv.wait_for(lock, timeout, [&] { return core_->streams.empty(); });
}

pb::ServerStats IsostreamService::Stats() const {
  const ServerCounters& c = core_->counters;
  pb::ServerStats s;
  s.set_sessions_open(c.sessions_open.load());
  s.set_sessions_total(c.sessions_total.load());
  s.set_sessions_closed(c.sessions_closed.load());
  s.set_sessions_rejected(c.sessions_rejected.load());
  s.set_sessions_idle_closed(c.sessions_idle_closed.load());
  s.set_streams_stalled(c.streams_stalled.load());
  s.set_frames_started(c.frames_started.load());
  s.set_frames_sent(c.frames_sent.load());
  s.set_frames_cancelled(c.frames_cancelled.load());
  s.set_frames_reordered(c.frames_reordered.load());
  s.set_retained_bytes(core_->retain_budget.used());
  s.set_chunks_sent(c.chunks_sent.load());
  s.set_bytes_sent(c.bytes_sent.load());
  s.set_volumes_prepared(core_->catalogue.prepared_count());
  s.set_serving(!core_->shutting_down.load());
  return s;
}

}  // namespace isostream::service
