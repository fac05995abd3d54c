// The frame producer without a process, against sinks that drain as a client would (never,
// slowly, at once): bounded memory, the deadline and what it bounds, chunk order, and the
// client's frame assembly of what it cuts.
#include "server/service/frame_producer.h"

#include <gtest/gtest.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <chrono>
#include <mutex>
#include <set>
#include <thread>

#include "client/net/session_client.h"
#include "server/extract/extractor.h"
#include "server/service/catalogue.h"
#include "server/service/worker_pool.h"
#include "shared/frame_codec.h"

namespace isostream::service {
namespace {
// Never writes anything: Queued() is everything ever pushed.
class StuckSink : public ChunkSink {
 public:
  bool Push(uint64_t, ::isostream::v1::FrameChunk&& chunk) override {
    std::lock_guard<std::mutex> lock(mu_);
    chunks_.push_back(std::move(chunk));
    return true;
  }
  size_t Queued() const override {
    std::lock_guard<std::mutex> lock(mu_);
    return chunks_.size();
  }
  std::vector<::isostream::v1::FrameChunk> chunks_;
  mutable std::mutex mu_;
};

// A frame producer with `settings` and `encoders` encoding threads, and buckyball:65 from a
// catalogue of its own to produce frames of.
struct ProducerRig {
  ProducerRig(const FrameSettings& settings, int encoders)
      : catalogue(CatalogueOptions{}), pool(encoders), producer(settings, &pool, &counters) {
    auto got = catalogue.Get("buckyball:65");
    EXPECT_TRUE(got.ok()) << got.status();
    if (got.ok()) volume = *got;
  }
  VolumeCatalogue catalogue;
  WorkerPool pool;
  ServerCounters counters;
  FrameProducer producer;
  ServedVolumePtr volume;  // null if it could not be prepared
};

// Runs `view` once through the rig's producer into `sink`, started now, never cancelled.
absl::Status RunNow(ProducerRig& rig, const ::isostream::v1::ViewRequest& view,
                    const ExtractRequest& request, ChunkSink* sink) {
  std::atomic<bool> cancel{false};
  const auto now = std::chrono::steady_clock::now();
  return rig.producer.Run(*rig.volume, view, request, 1, &cancel, sink, now, now);
}

// A view of buckyball:65 at isovalues `isos` and `eps`; callers place the eye.
::isostream::v1::ViewRequest BuckyballView(const std::vector<float>& isos, double eps) {
  ::isostream::v1::ViewRequest view;
  view.set_volume("buckyball:65");
  for (float iso : isos) view.add_surfaces()->set_isovalue(iso);
  view.set_eps(eps);
  return view;
}

// Produces one frame of buckyball:65 (isovalues `isos`, `eps`, the eye at x = 3) in chunks of
// `chunk` triangles, at most `queued` held, with a deadline of `deadline_ms` and `encoders`
// encoding threads, into `sink`, which never drains.
absl::Status ProduceIntoStuckSink(int chunk, int queued, int deadline_ms,
                                  const std::vector<float>& isos, double eps, int encoders,
                                  StuckSink* sink) {
  FrameSettings settings;
  settings.chunk_triangles = chunk;
  settings.first_chunk_triangles = chunk;
  settings.max_queued_chunks = queued;
  settings.deadline_ms = deadline_ms;
  ProducerRig rig(settings, encoders);
  if (!rig.volume) return absl::InternalError("buckyball:65 could not be prepared");
  ::isostream::v1::ViewRequest view = BuckyballView(isos, eps);
  view.mutable_camera()->mutable_eye()->set_x(3);
  auto request = ToExtractRequest(view, Limits{}, 0);
  if (!request.ok()) return request.status();
  return RunNow(rig, view, *request, sink);
}

// Takes its first `slow` chunks one per 100 ms from the first push, the rest at once: a client
// slow but steady through a progressive view's coarse frame.
class SlowStartSink : public ChunkSink {
 public:
  explicit SlowStartSink(size_t slow) : slow_(slow) {}
  bool Push(uint64_t, ::isostream::v1::FrameChunk&& chunk) override {
    std::lock_guard<std::mutex> lock(mu_);
    if (chunks_.empty()) first_ = std::chrono::steady_clock::now();
    chunks_.push_back(std::move(chunk));
    return true;
  }
  size_t Queued() const override {
    std::lock_guard<std::mutex> lock(mu_);
    if (chunks_.empty()) return 0;
    const auto taken =
        size_t((std::chrono::steady_clock::now() - first_) / std::chrono::milliseconds(100));
    const size_t held = std::min(chunks_.size(), slow_);
    return held > taken ? held - taken : 0;
  }
  std::vector<::isostream::v1::FrameChunk> chunks_;

 private:
  const size_t slow_;
  mutable std::mutex mu_;
  std::chrono::steady_clock::time_point first_;
};

// A progressive view's refined frame has its own deadline, from when the coarse frame has gone
// out: a client taking the coarse frame's chunks slowly (~2 s here, past the 500 ms deadline,
// but never silent for one) had the refined frame fail at once.
TEST(FrameProducer, TheRefinedFrameIsNotChargedForTheCoarseFramesDelivery) {
  FrameSettings settings;
  settings.chunk_triangles = settings.first_chunk_triangles = 256;
  settings.max_queued_chunks = 2;
  settings.coarse_triangles = 5000;
  settings.deadline_ms = 500;
  ProducerRig rig(settings, 2);
  ASSERT_TRUE(rig.volume);
  ::isostream::v1::ViewRequest view = BuckyballView({0.05f, 0.15f, 0.25f}, 0.002);
  view.set_progressive(true);
  view.set_codec(::isostream::v1::RAW);
  view.mutable_camera()->mutable_eye()->set_x(3);
  auto request = ToExtractRequest(view, Limits{}, 0);
  ASSERT_TRUE(request.ok());
  SlowStartSink sink(20);
  std::atomic<bool> cancel{false};
  const auto now = std::chrono::steady_clock::now();
  const absl::Status s = rig.producer.Run(*rig.volume, view, *request, 1, &cancel, &sink, now, now);
  EXPECT_TRUE(s.ok()) << s;
  ASSERT_FALSE(sink.chunks_.empty());
  EXPECT_TRUE(sink.chunks_.front().coarse());
  EXPECT_GT(std::chrono::steady_clock::now() - now, std::chrono::milliseconds(1000))
      << "the coarse frame went out quickly: nothing tested";
  EXPECT_FALSE(sink.chunks_.back().coarse());
  EXPECT_TRUE(sink.chunks_.back().last());
}

TEST(FrameProducer, StopsAtTheQueueBoundAndHitsTheDeadline) {
  StuckSink sink;
  const absl::Status s = ProduceIntoStuckSink(2048, 4, 300, {0.05f, 0.15f}, 0.002, 2, &sink);
  EXPECT_EQ(s.code(), absl::StatusCode::kDeadlineExceeded) << s;
  EXPECT_LE(sink.chunks_.size(), 4u);  // never more than max_queued_chunks held
  for (size_t i = 0; i < sink.chunks_.size(); ++i) EXPECT_EQ(sink.chunks_[i].chunk_index(), i);
}

// A client that stops reading holds only its own frame's thread, not the extraction's TBB
// workers, which every extraction in the daemon shares: its chunks wait for room after the
// extraction has returned. They used to wait inside the extractor's on_ready, under the lock
// every worker of that extraction takes after each subtree, so the workers stayed there until
// the deadline and other frames ran on their own threads alone.
TEST(FrameProducer, AStuckClientLeavesTheSharedWorkersFree) {
  if (std::thread::hardware_concurrency() < 2) GTEST_SKIP() << "TBB has no worker thread";
  StuckSink sink;
  absl::Status stuck;
  std::thread frame([&] {
    stuck = ProduceIntoStuckSink(1024, 2, 2500, {0.05f, 0.15f, 0.25f}, 0.0, 1, &sink);
  });
  // The volume prepared and the frame's queue full by now.
  std::this_thread::sleep_for(std::chrono::milliseconds(800));
  // Work another frame would give the workers: slow items, so that a free worker joins.
  std::mutex mu;
  std::set<std::thread::id> threads;
  tbb::parallel_for(0, 64, [&](int) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    std::lock_guard<std::mutex> lock(mu);
    threads.insert(std::this_thread::get_id());
  });
  frame.join();
  EXPECT_EQ(stuck.code(), absl::StatusCode::kDeadlineExceeded) << stuck;
  EXPECT_LE(sink.chunks_.size(), 2u);
  EXPECT_GE(threads.size(), 2u) << "the other work ran on its own thread only";
}

TEST(FrameProducer, ChunksCoverTheFrameInOrder) {
  FrameSettings settings;
  settings.first_chunk_triangles = 1000;
  settings.chunk_triangles = 7000;
  settings.max_queued_chunks = 1000;
  ProducerRig rig(settings, 2);
  ASSERT_TRUE(rig.volume);
  ::isostream::v1::ViewRequest view = BuckyballView({0.1f}, 0.002);
  view.mutable_camera()->mutable_eye()->set_y(-3);
  auto request = ToExtractRequest(view, Limits{}, 0);
  ASSERT_TRUE(request.ok());
  StuckSink sink;
  ASSERT_TRUE(RunNow(rig, view, *request, &sink).ok());
  auto direct =
      Extract(*rig.volume->prepared.hierarchy, rig.volume->prepared.grid_to_world, *request);
  ASSERT_TRUE(direct.ok());
  ASSERT_GT(sink.chunks_.size(), 4u);
  uint64_t next = 0;
  for (size_t i = 0; i < sink.chunks_.size(); ++i) {
    const auto& c = sink.chunks_[i];
    EXPECT_EQ(c.chunk_index(), i);
    EXPECT_EQ(c.first_triangle(), next);
    if (i < 3) {
      EXPECT_EQ(c.triangle_count(), std::min<uint32_t>(7000, 1000u << i));
    }
    EXPECT_EQ(c.last(), i + 1 == sink.chunks_.size());
    next += c.triangle_count();
  }
  EXPECT_EQ(next, direct->mesh.triangle_count());
  EXPECT_EQ(sink.chunks_.back().stats().triangles(), int64_t(next));
  EXPECT_EQ(rig.counters.frames_started.load(), 1);

  // The client puts them back together; a frame whose last chunk comes early, or whose last
  // chunk's counts disagree with what arrived, is DATA_LOSS, not a smaller frame.
  auto assemble = [](const std::vector<::isostream::v1::FrameChunk>& chunks,
                     int64_t max_triangles = net::kDefaultMaxFrameTriangles) {
    net::FrameAssembler a(max_triangles);
    for (const auto& c : chunks) {
      const absl::Status s = a.Add(c);
      if (!s.ok()) return s;
    }
    return a.complete() ? absl::OkStatus() : absl::UnavailableError("incomplete");
  };
  ASSERT_TRUE(assemble(sink.chunks_).ok());
  std::vector<::isostream::v1::FrameChunk> early = {sink.chunks_[0]};
  early[0].set_last(true);
  early[0].set_chunk_count(uint32_t(sink.chunks_.size()));
  *early[0].mutable_stats() = sink.chunks_.back().stats();
  EXPECT_EQ(assemble(early).code(), absl::StatusCode::kDataLoss);
  early[0].set_chunk_count(1);  // consistent count, but the stats count the whole frame
  EXPECT_EQ(assemble(early).code(), absl::StatusCode::kDataLoss);
  auto miscounted = sink.chunks_;
  miscounted.back().set_chunk_count(miscounted.back().chunk_count() + 1);
  EXPECT_EQ(assemble(miscounted).code(), absl::StatusCode::kDataLoss);
  // A frame past the client's limit is refused at the chunk that would pass it (a server
  // streaming one frame without end cannot fill the client's memory); exactly at it, it fits.
  EXPECT_TRUE(assemble(sink.chunks_, int64_t(next)).ok());
  net::FrameAssembler limited(int64_t(next) - 1);
  absl::Status refused;
  size_t refused_at = 0;
  for (; refused_at < sink.chunks_.size() && refused.ok(); ++refused_at)
    refused = limited.Add(sink.chunks_[refused_at]);
  EXPECT_EQ(refused.code(), absl::StatusCode::kResourceExhausted) << refused;
  EXPECT_EQ(refused_at, sink.chunks_.size());  // the last chunk, before decoding it
  EXPECT_EQ(limited.frame().mesh.triangle_count(), next - sink.chunks_.back().triangle_count());

  // Only the last chunk may be empty: empty chunks without end are a frame that never completes
  // nor grows (the viewer waited on them for ever).
  {
    ::isostream::v1::FrameChunk empty;
    ASSERT_TRUE(EncodeChunkRaw(OrderedMesh{}, 0, 0, empty.mutable_data()).ok());
    empty.set_frame_id(sink.chunks_[0].frame_id());
    net::FrameAssembler endless;
    EXPECT_EQ(endless.Add(empty).code(), absl::StatusCode::kDataLoss);
    empty.set_last(true);
    empty.set_chunk_count(1);
    net::FrameAssembler empty_frame;
    EXPECT_TRUE(empty_frame.Add(empty).ok());
    EXPECT_TRUE(empty_frame.complete());
  }

  // A refused chunk leaves the frame as it was: a chunk whose field miscounts its data, then the
  // right one, give the frame once (the first had been decoded into it before the check).
  net::FrameAssembler careful;
  auto wrong = sink.chunks_[0];
  wrong.set_triangle_count(wrong.triangle_count() + 1);
  EXPECT_EQ(careful.Add(wrong).code(), absl::StatusCode::kDataLoss);
  EXPECT_EQ(careful.frame().mesh.triangle_count(), 0u);
  for (const auto& c : sink.chunks_) ASSERT_TRUE(careful.Add(c).ok());
  ASSERT_TRUE(careful.complete());
  EXPECT_EQ(careful.frame().mesh.triangle_count(), next);
  EXPECT_EQ(careful.frame().mesh.vertex_count(), [&] {
    net::FrameAssembler plain;
    for (const auto& c : sink.chunks_) EXPECT_TRUE(plain.Add(c).ok());
    return plain.frame().mesh.vertex_count();
  }());
  // The first chunk of a new frame too: refused, it leaves the complete frame before it (it
  // used to replace it by an empty frame in progress).
  auto next_frame = sink.chunks_[0];
  next_frame.set_frame_id(next_frame.frame_id() + 1);
  next_frame.set_first_triangle(5);
  EXPECT_EQ(careful.Add(next_frame).code(), absl::StatusCode::kDataLoss);
  EXPECT_TRUE(careful.complete());
  EXPECT_EQ(careful.frame().mesh.triangle_count(), next);
  EXPECT_EQ(careful.frame().id, sink.chunks_[0].frame_id());

  // A chunk declaring more triangles than a stream's chunks hold is refused before decoding
  // (a 64 KB chunk could expand to a million triangles).
  OrderedMesh many;
  for (uint32_t t = 0; t <= kMaxStreamChunkTriangles; ++t) {
    for (int i = 0; i < 3; ++i) {
      many.positions.insert(many.positions.end(), {float(t), float(i), 0.0f});
      many.normals.insert(many.normals.end(), {0.0f, 0.0f, 1.0f});
      many.triangles.push_back(3 * t + uint32_t(i));
    }
    many.surface.push_back(0);
  }
  ::isostream::v1::FrameChunk big;
  ASSERT_TRUE(EncodeChunk(many, 0, many.triangle_count(), CodecOptions{}, big.mutable_data()).ok());
  big.set_triangle_count(uint32_t(many.triangle_count()));
  net::FrameAssembler bounded;
  const absl::Status too_big = bounded.Add(big);
  EXPECT_EQ(too_big.code(), absl::StatusCode::kDataLoss) << too_big;
  EXPECT_NE(too_big.message().find("at most 65536"), std::string::npos) << too_big;
}

// `n` triangles on vertices of their own (three per triangle), normals +z, surface 0.
OrderedMesh DisjointTriangles(uint32_t n) {
  OrderedMesh mesh;
  for (uint32_t t = 0; t < n; ++t) {
    for (int i = 0; i < 3; ++i) {
      mesh.positions.insert(mesh.positions.end(), {float(t), float(i), 0.0f});
      mesh.normals.insert(mesh.normals.end(), {0.0f, 0.0f, 1.0f});
      mesh.triangles.push_back(3 * t + uint32_t(i));
    }
    mesh.surface.push_back(0);
  }
  return mesh;
}

// Chunk `index` of frame `frame_id`: triangle `index` of `mesh`, raw; the last one says the
// frame has index + 1 chunks.
::isostream::v1::FrameChunk OneTriangleChunk(const OrderedMesh& mesh, uint64_t frame_id,
                                             uint32_t index, bool last, bool coarse = false) {
  ::isostream::v1::FrameChunk c;
  EXPECT_TRUE(EncodeChunkRaw(mesh, index, 1, c.mutable_data()).ok());
  c.set_frame_id(frame_id);
  c.set_coarse(coarse);
  c.set_chunk_index(index);
  c.set_first_triangle(index);
  c.set_triangle_count(1);
  if (last) {
    c.set_last(true);
    c.set_chunk_count(index + 1);
  }
  return c;
}

// Takes every chunk but a frame's last one: a newer view took over as the frame went out.
class RefusesTheLastChunkSink : public ChunkSink {
 public:
  bool Push(uint64_t, ::isostream::v1::FrameChunk&& chunk) override {
    std::lock_guard<std::mutex> lock(mu_);
    if (chunk.last()) return false;
    ++taken_;
    return true;
  }
  size_t Queued() const override { return 0; }
  size_t taken() const {
    std::lock_guard<std::mutex> lock(mu_);
    return taken_;
  }

 private:
  mutable std::mutex mu_;
  size_t taken_ = 0;
};

// A frame whose last chunk the stream refused did not go out: it is cancelled, not complete,
// though it was extracted and cut whole.
TEST(FrameProducer, AFrameWhoseLastChunkIsRefusedIsCancelled) {
  FrameSettings settings;
  settings.first_chunk_triangles = settings.chunk_triangles = 1000;
  ProducerRig rig(settings, 1);
  ASSERT_TRUE(rig.volume);
  ::isostream::v1::ViewRequest view = BuckyballView({0.1f}, 0.01);
  view.mutable_camera()->mutable_eye()->set_x(-3);
  auto request = ToExtractRequest(view, Limits{}, 0);
  ASSERT_TRUE(request.ok());
  RefusesTheLastChunkSink sink;
  const absl::Status s = RunNow(rig, view, *request, &sink);
  EXPECT_EQ(s.code(), absl::StatusCode::kCancelled) << s;
  EXPECT_GT(sink.taken(), 0u);
  EXPECT_EQ(rig.counters.frames_cancelled.load(), 1);
  EXPECT_EQ(rig.counters.frames_failed.load(), 0);
}

// A deadline that has passed when the extraction starts stops the frame with the daemon's
// deadline in the message, whichever part of the work noticed it first.
TEST(FrameProducer, APassedDeadlineNamesTheDaemonsDeadline) {
  FrameSettings settings;
  settings.deadline_ms = 0;
  ProducerRig rig(settings, 1);
  ASSERT_TRUE(rig.volume);
  for (bool budget : {false, true}) {
    ::isostream::v1::ViewRequest view = BuckyballView({0.05f, 0.15f}, 0.002);
    if (budget) view.set_triangle_budget(30000);
    view.mutable_camera()->mutable_eye()->set_y(3);
    auto request = ToExtractRequest(view, Limits{}, 0);
    ASSERT_TRUE(request.ok());
    std::atomic<bool> cancel{false};
    StuckSink sink;
    const auto before = std::chrono::steady_clock::now() - std::chrono::milliseconds(50);
    const absl::Status s =
        rig.producer.Run(*rig.volume, view, *request, 1, &cancel, &sink, before, before);
    EXPECT_EQ(s.code(), absl::StatusCode::kDeadlineExceeded) << s;
    EXPECT_NE(s.message().find("the daemon's deadline of 0 ms"), std::string::npos) << s;
  }
}

// The frame limit is a number of triangles a frame may have: a frame of exactly that many goes
// out whole, one more than the limit is refused.
TEST(FrameProducer, AFrameOfExactlyTheTriangleLimitGoesOut) {
  ::isostream::v1::ViewRequest view = BuckyballView({0.1f}, 0.01);
  view.mutable_camera()->mutable_eye()->set_z(3);
  auto request = ToExtractRequest(view, Limits{}, 0);
  ASSERT_TRUE(request.ok()) << request.status();
  int64_t triangles = 0;
  {
    ProducerRig rig(FrameSettings{}, 1);
    ASSERT_TRUE(rig.volume);
    auto direct =
        Extract(*rig.volume->prepared.hierarchy, rig.volume->prepared.grid_to_world, *request);
    ASSERT_TRUE(direct.ok()) << direct.status();
    triangles = int64_t(direct->mesh.triangle_count());
  }
  ASSERT_GT(triangles, 100);
  for (int64_t limit : {triangles, triangles - 1}) {
    FrameSettings settings;
    settings.max_triangles = limit;
    settings.max_queued_chunks = 1000;  // the sink never drains
    ProducerRig rig(settings, 1);
    ASSERT_TRUE(rig.volume);
    StuckSink sink;
    const absl::Status s = RunNow(rig, view, *request, &sink);
    if (limit == triangles) {
      ASSERT_TRUE(s.ok()) << s;
      ASSERT_FALSE(sink.chunks_.empty());
      EXPECT_EQ(sink.chunks_.back().stats().triangles(), triangles);
    } else {
      EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted) << s;
    }
  }
}

// Triangles of the coarse and of the refined frames in `chunks`.
std::pair<int64_t, int64_t> CoarseAndRefinedTriangles(
    const std::vector<::isostream::v1::FrameChunk>& chunks) {
  std::pair<int64_t, int64_t> n{0, 0};
  for (const auto& c : chunks) (c.coarse() ? n.first : n.second) += c.triangle_count();
  return n;
}

// A progressive view whose frame has no more triangles than the coarse budget gets that frame
// alone (exactly the budget included); one triangle more, and a coarse frame comes first.
TEST(FrameProducer, AProgressiveFrameOfAtMostTheCoarseBudgetComesAlone) {
  ::isostream::v1::ViewRequest view = BuckyballView({0.1f}, 0.01);
  view.set_progressive(true);
  view.mutable_camera()->mutable_eye()->set_y(3);
  auto request = ToExtractRequest(view, Limits{}, 0);
  ASSERT_TRUE(request.ok());
  int64_t triangles = 0;
  {
    ProducerRig rig(FrameSettings{}, 1);
    ASSERT_TRUE(rig.volume);
    auto direct =
        Extract(*rig.volume->prepared.hierarchy, rig.volume->prepared.grid_to_world, *request);
    ASSERT_TRUE(direct.ok());
    triangles = int64_t(direct->mesh.triangle_count());
  }
  ASSERT_GT(triangles, 100);
  for (int64_t coarse : {triangles, triangles - 1}) {
    FrameSettings settings;
    settings.coarse_triangles = int(coarse);
    settings.max_queued_chunks = 1000;  // the sink never drains
    ProducerRig rig(settings, 1);
    ASSERT_TRUE(rig.volume);
    StuckSink sink;
    ASSERT_TRUE(RunNow(rig, view, *request, &sink).ok());
    const auto [coarse_n, refined_n] = CoarseAndRefinedTriangles(sink.chunks_);
    EXPECT_EQ(refined_n, triangles);
    if (coarse == triangles)
      EXPECT_EQ(coarse_n, 0) << "a coarse frame of the frame itself";
    else
      EXPECT_GT(coarse_n, 0) << "coarse budget " << coarse;
  }
}

// The coarse hint: a remembered eps is used for the same volume and isovalues only, never makes
// the coarse frame finer than the requested one, and is forgotten when the frame it gave is far
// from the coarse budget (the next coarse frame is searched for again, within the budget).
TEST(FrameProducer, TheCoarseHintIsUsedOnlyWhereItFits) {
  FrameSettings settings;
  settings.coarse_triangles = 2000;
  settings.max_queued_chunks = 1000;  // the sink never drains
  ProducerRig rig(settings, 1);
  ASSERT_TRUE(rig.volume);
  ::isostream::v1::ViewRequest view = BuckyballView({0.1f}, 0.002);
  view.set_progressive(true);
  view.mutable_camera()->mutable_eye()->set_z(-3);
  auto request = ToExtractRequest(view, Limits{}, 0);
  ASSERT_TRUE(request.ok());
  auto run = [&](CoarseHint* hint) {
    std::atomic<bool> cancel{false};
    StuckSink sink;
    const auto now = std::chrono::steady_clock::now();
    const absl::Status s =
        rig.producer.Run(*rig.volume, view, *request, 1, &cancel, &sink, now, now, hint);
    EXPECT_TRUE(s.ok()) << s;
    return CoarseAndRefinedTriangles(sink.chunks_);
  };
  // A hint of other isovalues (eps 0: the whole mesh) is not taken: the coarse frame is searched.
  CoarseHint other{"buckyball:65", {0.3f}, 0.0};
  const auto [coarse_n, refined_n] = run(&other);
  EXPECT_GT(refined_n, 4 * 2000) << "the frame must be well over the coarse budget";
  EXPECT_GT(coarse_n, 0);
  EXPECT_LE(coarse_n, 2000);
  EXPECT_EQ(other.isovalues, std::vector<float>({0.1f}));
  EXPECT_GE(other.eps, 0.0);

  // A hint finer than the request (eps 0) draws the coarse frame at the request's eps, no finer;
  // that frame, far over the coarse budget, makes the hint forgotten.
  CoarseHint finer{"buckyball:65", {0.1f}, 0.0};
  const auto [hinted_coarse, hinted_refined] = run(&finer);
  EXPECT_EQ(hinted_refined, refined_n);
  EXPECT_GT(hinted_coarse, 0);
  EXPECT_LE(hinted_coarse, hinted_refined);
  EXPECT_EQ(finer.eps, -1.0);
  const auto [again_coarse, again_refined] = run(&finer);
  EXPECT_GT(again_coarse, 0);
  EXPECT_LE(again_coarse, 2000);
  EXPECT_GE(finer.eps, 0.0);
}

// The wire request's fields as the extraction gets them, at the edges of the daemon's limits:
// exactly max_isovalues surfaces are taken and one more refused, a budget of 0 is refused and one
// over max_triangles is the limit, an orthographic view looks from the eye to the target, and
// `unordered` and `normals` choose the order and the normal mode.
TEST(ToExtractRequest, MapsEachFieldAndChecksTheLimitsAtTheirEdges) {
  Limits limits;
  limits.max_isovalues = 3;
  limits.max_triangles = 5000;
  ::isostream::v1::ViewRequest view = BuckyballView({0.1f, 0.2f, 0.3f}, 0.01);
  auto three = ToExtractRequest(view, limits, 1);
  ASSERT_TRUE(three.ok()) << three.status();
  EXPECT_EQ(three->isovalues, std::vector<float>({0.1f, 0.2f, 0.3f}));
  EXPECT_EQ(three->eps, 0.01);
  EXPECT_EQ(three->budget, 0);
  EXPECT_EQ(three->order, DrawOrder::kBackToFront);
  EXPECT_EQ(three->normals, NormalMode::kSmooth);
  view.add_surfaces()->set_isovalue(0.4f);
  EXPECT_EQ(ToExtractRequest(view, limits, 1).status().code(),
            absl::StatusCode::kResourceExhausted);

  view = BuckyballView({0.1f}, 0.01);
  view.set_triangle_budget(0);
  EXPECT_EQ(ToExtractRequest(view, limits, 1).status().code(), absl::StatusCode::kInvalidArgument);
  view.set_triangle_budget(-3);
  EXPECT_EQ(ToExtractRequest(view, limits, 1).status().code(), absl::StatusCode::kInvalidArgument);
  view.set_triangle_budget(4999);
  EXPECT_EQ(ToExtractRequest(view, limits, 1)->budget, 4999);
  view.set_triangle_budget(5001);
  EXPECT_EQ(ToExtractRequest(view, limits, 1)->budget, 5000);

  view = BuckyballView({0.1f}, 0.01);
  auto* camera = view.mutable_camera();
  camera->set_projection(::isostream::v1::ORTHOGRAPHIC);
  camera->mutable_eye()->set_x(1);
  camera->mutable_eye()->set_y(2);
  camera->mutable_eye()->set_z(3);
  camera->mutable_target()->set_x(-4);
  camera->mutable_target()->set_y(7);
  camera->mutable_target()->set_z(3.5);
  view.set_unordered(true);
  view.set_normals(::isostream::v1::FLAT);
  auto ortho = ToExtractRequest(view, limits, 1);
  ASSERT_TRUE(ortho.ok()) << ortho.status();
  EXPECT_TRUE(ortho->view.orthographic);
  EXPECT_EQ(ortho->view.direction, glm::dvec3(-5, 5, 0.5));
  EXPECT_EQ(ortho->order, DrawOrder::kNone);
  EXPECT_EQ(ortho->normals, NormalMode::kFlat);
  camera->set_projection(::isostream::v1::PERSPECTIVE);
  auto perspective = ToExtractRequest(view, limits, 1);
  ASSERT_TRUE(perspective.ok()) << perspective.status();
  EXPECT_FALSE(perspective->view.orthographic);
  EXPECT_EQ(perspective->view.eye, glm::dvec3(1, 2, 3));
}

// A refused first chunk of a new frame must leave an unfinished frame able to
// continue with its next chunk (next_chunk_ restored too, not only the mesh).
TEST(FrameAssembler, ARefusedNewFrameLeavesTheUnfinishedOneResumable) {
  const OrderedMesh mesh = DisjointTriangles(3);
  auto chunk = [&](uint32_t index, bool last) { return OneTriangleChunk(mesh, 7, index, last); };
  net::FrameAssembler a;
  ASSERT_TRUE(a.Add(chunk(0, false)).ok());
  ASSERT_TRUE(a.Add(chunk(1, false)).ok());
  auto bad = chunk(0, false);
  bad.set_frame_id(8);
  bad.set_first_triangle(5);  // refused
  EXPECT_EQ(a.Add(bad).code(), absl::StatusCode::kDataLoss);
  EXPECT_FALSE(a.complete());
  EXPECT_EQ(a.frame().id, 7u);
  const absl::Status resumed = a.Add(chunk(2, true));
  EXPECT_TRUE(resumed.ok()) << resumed;
  EXPECT_TRUE(a.complete());
  EXPECT_EQ(a.frame().mesh.triangle_count(), 3u);
}

// A refined frame's first chunk starts a new frame even while the coarse frame of the same id
// is unfinished (that frame was superseded), instead of being taken for its next chunk.
TEST(FrameAssembler, ARefinedChunkStartsANewFrameAfterAnUnfinishedCoarseOne) {
  const OrderedMesh mesh = DisjointTriangles(2);
  net::FrameAssembler a;
  ASSERT_TRUE(a.Add(OneTriangleChunk(mesh, 4, 0, false, /*coarse=*/true)).ok());
  const absl::Status refined = a.Add(OneTriangleChunk(mesh, 4, 0, false));
  EXPECT_TRUE(refined.ok()) << refined;
  EXPECT_FALSE(a.frame().coarse);
  EXPECT_EQ(a.frame().mesh.triangle_count(), 1u);
}

// A chunk the codec refuses (here its header's magic) is the server's fault: DATA_LOSS, not
// the codec's INVALID_ARGUMENT, which would blame the caller.
TEST(FrameAssembler, AChunkTheCodecRefusesIsDataLoss) {
  auto chunk = OneTriangleChunk(DisjointTriangles(1), 1, 0, true);
  (*chunk.mutable_data())[0] = 'X';
  net::FrameAssembler a;
  EXPECT_EQ(a.Add(chunk).code(), absl::StatusCode::kDataLoss);
}

// The frame limit counts triangles; vertices may number up to three per triangle: three
// triangles on nine vertices fit a limit of three triangles.
TEST(FrameAssembler, ThreeVerticesPerTriangleFitTheLimit) {
  const OrderedMesh mesh = DisjointTriangles(3);
  net::FrameAssembler a(3);
  for (uint32_t i = 0; i < 3; ++i) {
    const absl::Status s = a.Add(OneTriangleChunk(mesh, 1, i, i == 2));
    ASSERT_TRUE(s.ok()) << i << ": " << s;
  }
  EXPECT_TRUE(a.complete());
  EXPECT_EQ(a.frame().mesh.vertex_count(), 9u);
}

// A chunk refused after decoding (its triangle_count field miscounts its data) takes out all it
// added: positions, normals, triangles and surfaces alike.
TEST(FrameAssembler, ARefusedChunkLeavesEveryArrayOfTheFrameAsItWas) {
  const OrderedMesh mesh = DisjointTriangles(2);
  net::FrameAssembler a;
  ASSERT_TRUE(a.Add(OneTriangleChunk(mesh, 1, 0, false)).ok());
  const OrderedMesh before = a.frame().mesh;
  auto wrong = OneTriangleChunk(mesh, 1, 1, true);
  wrong.set_triangle_count(2);
  EXPECT_EQ(a.Add(wrong).code(), absl::StatusCode::kDataLoss);
  EXPECT_EQ(a.frame().mesh.positions, before.positions);
  EXPECT_EQ(a.frame().mesh.normals, before.normals);
  EXPECT_EQ(a.frame().mesh.triangles, before.triangles);
  EXPECT_EQ(a.frame().mesh.surface, before.surface);
}

// The frame counts its chunks, their encoded bytes and each one's first vertex.
TEST(FrameAssembler, CountsChunksAndBytes) {
  const OrderedMesh mesh = DisjointTriangles(3);
  net::FrameAssembler a;
  int64_t bytes = 0;
  for (uint32_t i = 0; i < 3; ++i) {
    const auto chunk = OneTriangleChunk(mesh, 1, i, i == 2);
    bytes += int64_t(chunk.data().size());
    ASSERT_TRUE(a.Add(chunk).ok());
  }
  EXPECT_EQ(a.frame().chunks, 3);
  EXPECT_EQ(a.frame().bytes, bytes);
  EXPECT_EQ(a.frame().chunk_first_vertex, (std::vector<uint32_t>{0, 3, 6}));
}

// After Take, the next frame starts afresh even under the same id (request ids are the
// client's: 0 is one).
TEST(FrameAssembler, AfterTakeAFrameOfTheSameIdStartsAfresh) {
  const OrderedMesh mesh = DisjointTriangles(2);
  net::FrameAssembler a;
  for (int round = 0; round < 2; ++round) {
    ASSERT_TRUE(a.Add(OneTriangleChunk(mesh, 0, 0, false)).ok()) << round;
    ASSERT_TRUE(a.Add(OneTriangleChunk(mesh, 0, 1, true)).ok()) << round;
    ASSERT_TRUE(a.complete());
    EXPECT_EQ(a.Take().mesh.triangle_count(), 2u);
  }
}

// As worker_pool.h promises: ~WorkerPool runs the jobs already queued, then joins.
TEST(WorkerPool, DestructorRunsTheJobsAlreadyQueued) {
  std::atomic<int> ran{0};
  {
    WorkerPool pool(1);
    pool.Submit([&] {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      ++ran;
    });
    for (int i = 0; i < 10; ++i) pool.Submit([&] { ++ran; });
  }
  EXPECT_EQ(ran.load(), 11);
}

}  // namespace
}  // namespace isostream::service
