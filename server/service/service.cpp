#include "server/service/service.h"

#include <spdlog/spdlog.h>

#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "server/service/chunk_stream.h"
#include "server/service/raw_messages.h"
#include "server/service/service_core.h"

namespace isostream::service {

// Extract: one request, its frame(s), then OK.
class ExtractStream final : public ChunkStream<grpc::ServerWriteReactor<grpc::ByteBuffer>> {
 public:
  // A single view: recording its cut for a next one would cost ~4% more instructions and
  // retain_mb memory, and could push Session streams' retained frames out, for nothing.
  ExtractStream(ServiceCore* core, grpc::CallbackServerContext* context)
      : ChunkStream(core, context, false) {}

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
      : ChunkStream(core, context, true) {}

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
  core_->catalogue.Stop();           // which gives up at its next check
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
    auto served = core->catalogue.Get(name, [context] { return context->IsCancelled(); });
    if (context->IsCancelled()) return finish(gone);
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
    info.set_orientation(v.orientation);
    info.set_meters_per_unit(v.meters_per_unit);
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
  // Views waiting for a preparation end now with UNAVAILABLE, and the preparation stops: it
  // may take minutes, far past the grace period and a service manager's stop timeout.
  core_->catalogue.Stop();
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

int IsostreamService::WaitForPreparations(std::chrono::milliseconds timeout) {
  return core_->catalogue.WaitForPreparations(timeout);
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
  s.set_frames_failed(c.frames_failed.load());
  s.set_frames_reordered(c.frames_reordered.load());
  s.set_retained_bytes(core_->retain_budget.used());
  s.set_chunks_sent(c.chunks_sent.load());
  s.set_bytes_sent(c.bytes_sent.load());
  s.set_volumes_prepared(core_->catalogue.prepared_count());
  s.set_serving(!core_->shutting_down.load());
  return s;
}

}  // namespace isostream::service
