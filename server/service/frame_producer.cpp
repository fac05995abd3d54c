#include "server/service/frame_producer.h"

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <optional>
#include <utility>
#include <vector>

namespace isostream::service {
namespace {

using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

// The state one frame shares between the extractor's callback, the encoder jobs and the
// producer's thread. Lives on the producer's stack: the producer waits for every encoder job
// before returning.
struct FrameState {
  std::mutex mu;
  std::condition_variable cv;
  std::vector<std::optional<pb::FrameChunk>> chunks;  // by index; emptied when released
  size_t released = 0;                                // chunks [0, released) are on the sink
  size_t encoding = 0;                                // encoder jobs not yet finished
  double encode_ms = 0;                               // summed over chunks
  int64_t bytes = 0;
  absl::Status error;       // first internal reason to stop (the frame is then abandoned)
  bool superseded = false;  // the sink refused a chunk: a newer view took over
};

}  // namespace

absl::StatusOr<ExtractRequest> ToExtractRequest(const pb::ViewRequest& v, const Limits& limits,
                                                int threads) {
  ExtractRequest r;
  if (v.volume().empty()) return absl::InvalidArgumentError("no volume named");
  if (v.surfaces_size() == 0)
    return absl::InvalidArgumentError("no surfaces: give at least one isovalue");
  if (v.surfaces_size() > limits.max_isovalues)
    return absl::ResourceExhaustedError("at most " + std::to_string(limits.max_isovalues) +
                                        " isovalues per request, got " +
                                        std::to_string(v.surfaces_size()));
  for (const auto& s : v.surfaces()) r.isovalues.push_back(s.isovalue());
  switch (v.accuracy_case()) {
    case pb::ViewRequest::kEps:
      r.eps = v.eps();
      break;
    case pb::ViewRequest::kTriangleBudget:
      if (v.triangle_budget() <= 0)
        return absl::InvalidArgumentError("triangle budget must be positive");
      // Both are ceilings: a budget over the daemon's frame limit is the limit (refusing it
      // turned away a budget of 5 M whose mesh, whole, had 1 M triangles).
      r.budget = std::min<int64_t>(v.triangle_budget(), limits.max_triangles);
      break;
    default:
      return absl::InvalidArgumentError("set eps or triangle_budget");
  }
  if (!pb::Codec_IsValid(v.codec())) return absl::InvalidArgumentError("unknown codec");
  if (!pb::Projection_IsValid(v.camera().projection()))
    return absl::InvalidArgumentError("unknown projection");
  if (!pb::Normals_IsValid(v.normals())) return absl::InvalidArgumentError("unknown normals mode");
  const auto& eye = v.camera().eye();
  const auto& target = v.camera().target();
  if (v.camera().projection() == pb::ORTHOGRAPHIC) {
    r.view.orthographic = true;
    r.view.direction = {target.x() - eye.x(), target.y() - eye.y(), target.z() - eye.z()};
  } else {
    r.view.eye = {eye.x(), eye.y(), eye.z()};
  }
  r.order = v.unordered() ? DrawOrder::kNone : DrawOrder::kBackToFront;
  r.normals = v.normals() == pb::FLAT ? NormalMode::kFlat : NormalMode::kSmooth;
  r.threads = threads;
  ISOSTREAM_RETURN_IF_ERROR(ValidateRequest(r));
  return r;
}

absl::Status FrameProducer::Run(const ServedVolume& volume, const pb::ViewRequest& view,
                                const ExtractRequest& request, uint64_t generation,
                                std::atomic<bool>* cancel, ChunkSink* sink,
                                Clock::time_point received, Clock::time_point deadline_from,
                                CoarseHint* hint, RetainedFrame* retained) const {
  const RetainedCut* same_mesh = retained ? retained->Find(volume, request) : nullptr;
  // The refined frame's deadline starts after the coarse frame has gone out: delivering that is
  // the client's pace, not this frame's extraction (a client slow to take a coarse frame of
  // many chunks made the refined one miss its deadline).
  Clock::time_point refined_from = deadline_from;
  if (view.progressive() && same_mesh == nullptr) {
    // Never over the frame limit: a coarse budget past it refused a progressive view as if
    // even the coarsest mesh were over the limit.
    const int64_t coarse = std::min<int64_t>(settings_.coarse_triangles, settings_.max_triangles);
    // A count that stops past the coarse budget is cheap, and avoids sending a "coarse" frame
    // that is the requested one (or finer): for an eps, at that eps; for a budget, at eps 0
    // (the whole mesh fits it). A budget of at most twice the coarse one gets no coarse frame:
    // its own frame is as quick, and can be the same mesh (a budget of 20001 drew the 20000
    // triangles of the coarse frame twice).
    const bool budget = request.budget > 0;
    bool want_coarse = !budget || request.budget > 2 * coarse;
    if (want_coarse) {
      auto n = CountTriangles(*volume.prepared.hierarchy, volume.prepared.grid_to_world, request,
                              budget ? 0.0 : request.eps, coarse + 1);
      want_coarse = !n.ok() || *n > coarse;
    }
    if (want_coarse) {
      ExtractRequest c = request;
      const bool hinted = hint && hint->eps >= 0 && hint->volume == view.volume() &&
                          hint->isovalues == request.isovalues;
      if (hinted) {
        c.budget = 0;
        c.eps = std::max(hint->eps, request.eps);
      } else {
        c.budget = coarse;
      }
      ExtractStats stats;
      ISOSTREAM_RETURN_IF_ERROR(ProduceFrame(volume, view, c, true, generation, cancel, sink,
                                             received, deadline_from, &stats));
      refined_from = std::max(deadline_from, Clock::now());
      if (hint) {
        hint->volume = view.volume();
        hint->isovalues = request.isovalues;
        // Keep a hinted eps while the size stays near the budget; search again otherwise.
        const bool near = stats.triangles <= 2 * coarse && 4 * stats.triangles >= coarse;
        hint->eps = !hinted || near ? stats.eps_used : -1.0;
      }
    }
  }
  ExtractStats stats;
  return ProduceFrame(volume, view, request, false, generation, cancel, sink, received,
                      refined_from, &stats, retained, same_mesh);
}

absl::Status FrameProducer::ProduceFrame(const ServedVolume& volume, const pb::ViewRequest& view,
                                         const ExtractRequest& request, bool coarse,
                                         uint64_t generation, std::atomic<bool>* cancel,
                                         ChunkSink* sink, Clock::time_point received,
                                         Clock::time_point deadline_from, ExtractStats* stats_out,
                                         RetainedFrame* retained,
                                         const RetainedCut* same_mesh) const {
  counters_->frames_started.fetch_add(1);
  const auto deadline = deadline_from + std::chrono::milliseconds(settings_.deadline_ms);
  auto past_deadline = [this] {
    return absl::DeadlineExceededError("frame took longer than the daemon's deadline of " +
                                       std::to_string(settings_.deadline_ms) + " ms");
  };
  const bool raw = view.codec() == pb::RAW;
  const size_t max_chunk = size_t(raw ? std::min(settings_.chunk_triangles, kMaxRawChunkTriangles)
                                      : settings_.chunk_triangles);
  CodecOptions codec;
  codec.position_bits = volume.position_bits;
  codec.normal_bits = 10;
  codec.compress_connectivity = true;
  codec.position_box = volume.box;

  FrameState state;
  // Chunks are copied out of the extractor's mesh when cut: the extractor keeps appending to
  // (and reallocating) it while the copies are encoded. The copier's lookup table lives for
  // the frame, so each copy costs O(chunk).
  ChunkCopier copier;
  size_t cut_end = 0;  // triangles [0, cut_end) are cut into chunks

  // Stops the frame for an internal reason; the first reason wins.
  auto stop = [&](absl::Status why) {
    if (state.error.ok()) state.error = std::move(why);
    cancel->store(true);
    state.cv.notify_all();
  };

  // Hands released chunks to the sink in index order. Called with state.mu held.
  auto release_locked = [&] {
    while (state.released < state.chunks.size() && state.chunks[state.released]) {
      pb::FrameChunk chunk = std::move(*state.chunks[state.released]);
      state.chunks[state.released].reset();
      ++state.released;
      if (chunk.last()) {
        pb::FrameStats* st = chunk.mutable_stats();
        st->set_encode_ms(state.encode_ms);
        st->set_bytes(state.bytes);
        st->set_frame_ms(MsSince(received));
      }
      if (!state.superseded && !sink->Push(generation, std::move(chunk))) {
        state.superseded = true;
        cancel->store(true);
      }
    }
    state.cv.notify_all();
  };

  auto chunk_size = [&](size_t index) {
    return std::min(max_chunk, size_t(settings_.first_chunk_triangles)
                                   << std::min<size_t>(index, 20));
  };

  // Cuts triangles [cut_end, cut_end + count) into the next chunk and queues its encoding.
  auto cut = [&](const OrderedMesh& mesh, size_t count, bool last, const ExtractStats* stats) {
    auto piece = std::make_shared<ChunkCopy>();
    const absl::Status copied = copier.Copy(mesh, cut_end, count, piece.get());
    if (!copied.ok()) {
      std::lock_guard<std::mutex> lock(state.mu);
      stop(absl::InternalError("copying a chunk failed: " + std::string(copied.message())));
      return;
    }
    size_t index;
    {
      std::lock_guard<std::mutex> lock(state.mu);
      index = state.chunks.size();
      state.chunks.emplace_back();
      ++state.encoding;
    }
    auto header = std::make_shared<pb::FrameChunk>();
    header->set_frame_id(view.request_id());
    header->set_coarse(coarse);
    header->set_chunk_index(uint32_t(index));
    header->set_first_triangle(cut_end);
    header->set_triangle_count(uint32_t(count));
    if (last) {
      header->set_last(true);
      header->set_chunk_count(uint32_t(index + 1));
      pb::FrameStats* st = header->mutable_stats();
      st->set_triangles(stats->triangles);
      st->set_vertices(stats->vertices);
      st->set_eps_used(stats->eps_used);
      st->set_extract_ms(stats->total_ms);
      st->set_budget_passes(stats->budget_passes);
      st->set_reordered(stats->reordered);
      st->set_triangle_budget(request.budget);
      st->set_chunk_count(int32_t(index + 1));
    }
    cut_end += count;
    encoders_->Submit([&state, &release_locked, &stop, piece, header, index, raw, codec] {
      const Clock::time_point t = Clock::now();
      std::string bytes;
      absl::Status s = raw ? EncodeChunkRaw(*piece, &bytes) : EncodeChunk(*piece, codec, &bytes);
      if (s.ok() && bytes.size() > kMaxChunkBytes)
        s = absl::InternalError("encoded chunk of " + std::to_string(bytes.size()) +
                                " bytes is over the message limit");
      const double ms = MsSince(t);
      std::lock_guard<std::mutex> lock(state.mu);
      --state.encoding;
      if (!s.ok()) {
        stop(absl::InternalError("encoding a chunk failed: " + std::string(s.message())));
        return;
      }
      state.encode_ms += ms;
      state.bytes += int64_t(bytes.size());
      header->set_data(std::move(bytes));
      state.chunks[index] = std::move(*header);
      release_locked();
    });
  };

  // Whether the frame has room for another chunk now: kNo while the client has not taken
  // enough of the queued ones, kStop once the frame must stop. Called with state.mu held.
  // The deadline bounds the extraction, not delivery: once the mesh is extracted, a
  // client that reads slowly but steadily gets the frame (a 3.6 M-triangle frame read at
  // ~200 KB/s was refused as past the deadline, blaming the server's time), and one that stops
  // reading is stopped after a deadline without taking a chunk (wait_for_room; the stall reaper
  // of chunk_stream.h cancels its call then too).
  enum class Room { kYes, kNo, kStop };
  auto room_locked = [&](bool extracting) {
    if (cancel->load()) return Room::kStop;
    if (extracting && Clock::now() > deadline) {
      stop(past_deadline());
      return Room::kStop;
    }
    const size_t outstanding = state.chunks.size() - state.released + sink->Queued();
    return outstanding < size_t(settings_.max_queued_chunks) ? Room::kYes : Room::kNo;
  };
  // Waits until the frame has room for another chunk (or must stop). Polls the sink's queue
  // on a short period: the sink drains on gRPC's threads, which do not notify this frame. A
  // client that takes no chunk for a whole deadline has stopped reading, and the frame stops:
  // the daemon's stall reaper cancels such a call too, but nothing else would end this wait.
  auto wait_for_room = [&] {
    std::unique_lock<std::mutex> lock(state.mu);
    // Progress: a chunk taken by the client, or one finished by the encoders (which the
    // client cannot take before: a busy encoder pool is not the client's stall).
    auto marker = [&] {
      const size_t taken = state.released - std::min(state.released, sink->Queued());
      return std::pair<size_t, size_t>(taken, state.released);
    };
    std::pair<size_t, size_t> marker_before = marker();
    Clock::time_point progress = Clock::now();
    for (;;) {
      const Room room = room_locked(false);
      if (room != Room::kNo) return room == Room::kYes;
      const Clock::time_point now = Clock::now();
      if (marker() != marker_before) {
        marker_before = marker();
        progress = now;
      } else if (now - progress > std::chrono::milliseconds(settings_.deadline_ms)) {
        stop(absl::DeadlineExceededError("the client took no data for " +
                                         std::to_string(settings_.deadline_ms) + " ms"));
        return false;
      }
      state.cv.wait_for(lock, std::chrono::milliseconds(1));
    }
  };
  // Cuts the full chunks of the first `end` triangles not cut yet, while there is room now
  // (`wait`: waiting for it). False if the frame must stop.
  auto cut_full_chunks = [&](const OrderedMesh& mesh, size_t end, bool wait) {
    while (end - cut_end >= chunk_size(state.chunks.size())) {
      if (wait) {
        if (!wait_for_room()) return false;
      } else {
        std::lock_guard<std::mutex> lock(state.mu);
        const Room room = room_locked(true);
        if (room != Room::kYes) return room == Room::kNo;
      }
      cut(mesh, chunk_size(state.chunks.size()), false, nullptr);
    }
    return true;
  };

  ExtractObserver observer;
  observer.cancel = cancel;
  observer.deadline = deadline;  // the budget search and the traversal stop there too
  observer.on_ready = [&](const OrderedMesh& mesh, size_t /*first*/, size_t end) {
    if (cancel->load()) return;
    if (int64_t(end) > settings_.max_triangles) {
      std::lock_guard<std::mutex> lock(state.mu);
      // With a budget, only the coarsest mesh can be over the limit: nothing coarser exists.
      stop(absl::ResourceExhaustedError(
          "the frame has more than " + std::to_string(settings_.max_triangles) +
          " triangles (this daemon's limit): " +
          (request.budget > 0 ? "even the coarsest mesh of these isovalues is over it"
                              : "raise eps or give a triangle budget")));
      return;
    }
    // Never waits for the client here: on_ready runs under the extractor's lock, which every
    // worker of the extraction takes after each subtree, and TBB's workers are shared by all
    // extractions, so one client that stopped reading held the workers of every other frame
    // (each ran on its own thread alone) until its deadline. What has no room yet is cut
    // once the extraction has returned, on this frame's own thread.
    cut_full_chunks(mesh, end, false);
  };

  ExtractRequest remembering = request;  // budget -> eps is the same for every view
  remembering.budget_memo = &volume.budget_memo;
  RetainedCut* recording =
      retained && !same_mesh ? retained->StartRecording(volume, remembering) : nullptr;
  auto result = same_mesh ? Reorder(*same_mesh, request.view, request.order, &observer)
                          : Extract(*volume.prepared.hierarchy, volume.prepared.grid_to_world,
                                    remembering, &observer, recording);
  if (result.ok() && same_mesh) counters_->frames_reordered.fetch_add(1);
  bool last_cut = false;
  if (result.ok()) *stats_out = result->stats;
  if (result.ok() && !cancel->load() &&
      cut_full_chunks(result->mesh, result->mesh.triangle_count(), true) && wait_for_room()) {
    cut(result->mesh, result->mesh.triangle_count() - cut_end, true, &result->stats);
    last_cut = true;
  }

  std::unique_lock<std::mutex> lock(state.mu);
  state.cv.wait(lock, [&] { return state.encoding == 0; });
  const absl::Status error = state.error;
  // A newer view may set `cancel` after the last chunk went out: the frame still counts.
  const bool complete =
      last_cut && error.ok() && !state.superseded && state.released == state.chunks.size();
  lock.unlock();
  // The mesh is whole when the extraction ran to its end and nothing refused the frame after
  // (over max_triangles, say), even if a newer view superseded it on the way out.
  const bool whole_mesh = result.ok() && error.ok();
  if (recording) retained->EndRecording(volume, whole_mesh ? &result->mesh : nullptr);
  if (retained && whole_mesh) retained->Drew(volume, remembering, result->stats.triangles);
  if (complete) return absl::OkStatus();
  // The first reason the server stopped the frame, else the extraction's own (a cancelled
  // extraction is not the server's failure).
  absl::Status failed = error;
  if (failed.ok() && !result.ok()) {
    if (result.status().code() == absl::StatusCode::kDeadlineExceeded)
      failed = past_deadline();
    else if (result.status().code() != absl::StatusCode::kCancelled)
      failed = result.status();
  }
  if (!failed.ok()) {
    counters_->frames_failed.fetch_add(1);
    return failed;
  }
  counters_->frames_cancelled.fetch_add(1);
  return absl::CancelledError("frame cancelled");
}

}  // namespace isostream::service
