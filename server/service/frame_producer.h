// Turns one view request into frames on the wire: extraction, cutting into chunks in draw
// order, parallel encoding, and release to the stream in order.
//
// Pipelining: the extractor reports draw-order prefixes as they complete (ExtractObserver);
// each time enough triangles are final a chunk is cut (copied out, with the vertices it uses)
// and handed to the encoder pool, and encoded chunks are released to the stream strictly in
// chunk order. The first chunks of a frame are small (first_chunk_triangles, doubling up to
// chunk_triangles) so that the farthest triangles leave within milliseconds of the request.
//
// Bounded memory: at most max_queued_chunks chunks per frame are cut, encoding, or waiting to
// be written. When the client reads slowly the extractor's progress callback waits, which
// stalls the extraction itself: back-pressure reaches the producer instead of piling up.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include "proto/isostream.pb.h"
#include "server/extract/extractor.h"
#include "server/service/catalogue.h"
#include "server/service/config.h"
#include "server/service/retained_frame.h"
#include "server/service/stats.h"
#include "server/service/worker_pool.h"

namespace isostream::service {

namespace pb = ::isostream::v1;

// Largest encoded chunk put on the wire, below gRPC's default 4 MiB message limit with room
// for the message's other fields.
inline constexpr size_t kMaxChunkBytes = (4u << 20) - (64u << 10);
// Raw chunks need up to 88 bytes per triangle (three unshared vertices); this many stay under
// kMaxChunkBytes.
inline constexpr int kMaxRawChunkTriangles = 45000;

// Where chunks go: the stream reactors. Push returns false once the stream no longer wants
// chunks of `generation` (a newer view arrived, or the stream ended).
class ChunkSink {
 public:
  virtual bool Push(uint64_t generation, pb::FrameChunk&& chunk) = 0;
  // Chunks pushed and not yet written.
  virtual size_t Queued() const = 0;

 protected:
  ~ChunkSink() = default;
};

// Maps a wire request to an extraction request. INVALID_ARGUMENT for malformed requests (with
// ValidateRequest's message), RESOURCE_EXHAUSTED for requests over the daemon's limits.
absl::StatusOr<ExtractRequest> ToExtractRequest(const pb::ViewRequest& view, const Limits& limits,
                                                int threads);

// What a stream remembers between views so that the coarse frame of a progressive request
// can skip the budget search: after a camera move over the same volume and isovalues, the eps
// that gave the last coarse frame its size gives about the same size again.
struct CoarseHint {
  std::string volume;
  std::vector<float> isovalues;
  double eps = -1;  // < 0: none yet
};

struct FrameSettings {
  int chunk_triangles = 65536;
  int first_chunk_triangles = 8192;
  int max_queued_chunks = 8;
  int coarse_triangles = 20000;
  int64_t max_triangles = 4'000'000;
  int64_t deadline_ms = 30'000;
};

class FrameProducer {
 public:
  FrameProducer(FrameSettings settings, WorkerPool* encoders, ServerCounters* counters)
      : settings_(settings), encoders_(encoders), counters_(counters) {}

  // Streams the frame(s) answering `view` into `sink` as `generation`: with view.progressive
  // a coarse frame first (skipped when the requested frame is no bigger, or its budget at most
  // twice the coarse one), then the requested one. Blocks until every chunk is queued on the sink or the work stops. `cancel` may be set
  // by another thread at any time (a newer view, the client leaving); the producer also sets it
  // itself to stop early. Returns OK, CANCELLED, DEADLINE_EXCEEDED (limits.deadline_ms),
  // RESOURCE_EXHAUSTED (a frame over max_triangles) or the extractor's error.
  // `hint` (may be null) is read and updated; one stream's views run one at a time, so it
  // needs no lock. So is `retained` (may be null; the caller holds its mutex): a refined frame
  // of the mesh it holds is re-ordered from it (no coarse frame first: the refined one comes as
  // quickly); a refined frame of another mesh is recorded into it in its place, unless the
  // stream is sliding through meshes (retained_frame.h says when, and when it is freed).
  // `received` is when the view was read (FrameStats.frame_ms counts from it); the deadline
  // runs from `deadline_from`, which is later by the time the view waited for its volume to
  // be prepared: preparing a 1025^3 volume takes 36-49 s, and is no frame's work.
  absl::Status Run(const ServedVolume& volume, const pb::ViewRequest& view,
                   const ExtractRequest& request, uint64_t generation, std::atomic<bool>* cancel,
                   ChunkSink* sink, std::chrono::steady_clock::time_point received,
                   std::chrono::steady_clock::time_point deadline_from, CoarseHint* hint = nullptr,
                   RetainedFrame* retained = nullptr) const;

 private:
  absl::Status ProduceFrame(const ServedVolume& volume, const pb::ViewRequest& view,
                            const ExtractRequest& request, bool coarse, uint64_t generation,
                            std::atomic<bool>* cancel, ChunkSink* sink,
                            std::chrono::steady_clock::time_point received,
                            std::chrono::steady_clock::time_point deadline_from,
                            ExtractStats* stats_out, RetainedFrame* retained = nullptr,
                            const RetainedCut* same_mesh = nullptr) const;

  FrameSettings settings_;
  WorkerPool* encoders_;
  ServerCounters* counters_;
};

}  // namespace isostream::service
