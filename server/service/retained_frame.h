// What a stream keeps of its last refined frame, so that a later view of the same mesh (same
// volume, isovalues, eps or budget, normals) is drawn by re-ordering it
// (server/extract/retained_cut.h) instead of extracting it again; and the daemon-wide cap on
// the memory all streams keep so (frames.retain_mb).
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <utility>
#include <vector>

#include "server/extract/retained_cut.h"
#include "server/service/catalogue.h"

namespace isostream::service {

class RetainedFrame;

// Bytes of retained frames the daemon holds, against its limit, and the frames holding them.
// Thread-safe.
class RetainBudget {
 public:
  explicit RetainBudget(int64_t limit_bytes) : limit_(limit_bytes) {}

  // Takes `bytes` if they fit under the limit.
  bool Take(int64_t bytes) {
    int64_t used = used_.load();
    do {
      if (used + bytes > limit_) return false;
    } while (!used_.compare_exchange_weak(used, used + bytes));
    return true;
  }
  // Takes `bytes`, freeing other streams' frames, least recently used first, until they fit
  // (only frames not in use at the moment: their streams are between views).
  inline bool TakeEvicting(int64_t bytes, const RetainedFrame* taker);
  void Give(int64_t bytes) { used_.fetch_sub(bytes); }
  int64_t used() const { return used_.load(); }
  int64_t limit() const { return limit_; }

  // What a frame of `triangles` is expected to hold: the most bytes per triangle a frame has
  // held so far (its buffers' capacity; ~64 before any), so that streams reserve up front what
  // they will need instead of all growing past their reserves at once and dropping their
  // frames for want of room.
  int64_t Estimate(int64_t triangles) const {
    return std::max<int64_t>(bytes_per_triangle_.load() * triangles, int64_t{1} << 16);
  }
  void Held(int64_t bytes, int64_t triangles) {
    if (triangles <= 0) return;
    const int64_t ratio = (bytes + triangles - 1) / triangles;
    int64_t seen = bytes_per_triangle_.load();
    while (ratio > seen && !bytes_per_triangle_.compare_exchange_weak(seen, ratio)) {
    }
  }

  // A clock for "least recently used".
  uint64_t Tick() { return ++clock_; }
  void Register(RetainedFrame* frame) {
    std::lock_guard<std::mutex> lock(mu_);
    frames_.push_back(frame);
  }
  void Unregister(RetainedFrame* frame) {
    std::lock_guard<std::mutex> lock(mu_);
    frames_.erase(std::remove(frames_.begin(), frames_.end(), frame), frames_.end());
  }

 private:
  std::atomic<int64_t> used_{0};
  const int64_t limit_;
  std::atomic<uint64_t> clock_{0};
  std::atomic<int64_t> bytes_per_triangle_{64};
  std::mutex mu_;  // guards frames_
  std::vector<RetainedFrame*> frames_;
};

// One stream's retained frame. Its buffers, kept or not, are charged to the budget for what
// they hold (their capacity), from before a frame is recorded into them (an estimate; the
// records' growth past it is asked for as it happens, and the whole settled after) until they
// are freed. Its stream's job holds mutex() while it uses the frame (one view
// at a time); other streams' jobs may free it meanwhile only when that lock is free
// (RetainBudget::TakeEvicting).
class RetainedFrame {
 public:
  explicit RetainedFrame(RetainBudget* budget) : budget_(budget) {
    if (budget_ == nullptr) return;
    budget_->Register(this);
    cut_.SetReserve([this](int64_t bytes) { return Reserve(bytes); });
  }
  ~RetainedFrame() {
    if (budget_) budget_->Unregister(this);  // first: no evictor reaches it after
    Drop();
  }
  RetainedFrame(const RetainedFrame&) = delete;
  RetainedFrame& operator=(const RetainedFrame&) = delete;

  std::mutex& mutex() { return use_mu_; }
  uint64_t last_use() const { return last_use_.load(); }
  int64_t charged() const { return charged_; }  // with mutex() held, or by its own job

  // The retained cut if it draws `request` on `volume` as prepared now, else null. A cut of a
  // volume re-prepared or dropped since is freed.
  const RetainedCut* Find(const ServedVolume& volume, const ExtractRequest& request) {
    if (budget_) last_use_ = budget_->Tick();
    if (!holds_frame_) return nullptr;
    const HierarchyPtr h = hierarchy_.lock();
    if (h == nullptr || h != volume.prepared.hierarchy) {
      Drop();
      return nullptr;
    }
    double budget_eps = -1;
    if (request.budget > 0)
      budget_eps = volume.budget_memo.Find(request.isovalues, request.budget).value_or(-1.0);
    return cut_.Serves(request, budget_eps) ? &cut_ : nullptr;
  }

  // Where to record the refined frame about to be extracted for `request`, or null. A frame is
  // recorded unless the stream is sliding through meshes (its last two refined frames drew
  // different meshes, and this one is another again: a client changing the isovalues or eps
  // with every view, who would pay for recording and never re-order), so that the view after
  // a new mesh's first frame is already re-ordered; and only when the budget has room for a
  // frame of the previous one's size.
  RetainedCut* StartRecording(const ServedVolume& volume, const ExtractRequest& request) {
    if (budget_ == nullptr || budget_->limit() <= 0) return nullptr;
    if (sliding_ && !last_.Same(volume, request)) return nullptr;
    // The reserve is settled against what the buffers hold once the frame is in.
    const int64_t estimate = budget_->Estimate(last_triangles_);
    if (estimate > charged_) {
      if (!budget_->TakeEvicting(estimate - charged_, this)) {
        Drop();  // no room: free what this stream held as well
        return nullptr;
      }
      charged_ = estimate;
    }
    holds_frame_ = false;  // the buffers are being rewritten
    // The extraction frees the old mesh first: what is charged is the tree's to grow into.
    tree_bytes_at_start_ = int64_t(cut_.tree_bytes());
    tree_growth_ = 0;
    return &cut_;
  }

  // The recording StartRecording began is over: `frame` is its mesh if it was drawn completely,
  // moved into the cut, else null (a frame stopped part way, or refused after it ran, is not
  // kept).
  void EndRecording(const ServedVolume& volume, OrderedMesh* frame) {
    const bool whole = frame != nullptr && cut_.KeepMesh(std::move(*frame));
    const int64_t held = int64_t(cut_.memory_bytes());
    if (whole) budget_->Held(held, int64_t(cut_.triangle_count()));
    if (held > charged_ && !budget_->TakeEvicting(held - charged_, this)) {
      Drop();
      return;
    }
    if (held < charged_) budget_->Give(charged_ - held);
    charged_ = held;
    holds_frame_ = whole && !cut_.empty();
    if (holds_frame_) hierarchy_ = volume.prepared.hierarchy;
  }

  // A refined frame of `request` was drawn (extracted or re-ordered), with `triangles`. When
  // the stream has moved on to another mesh, what it held (a frame, or buffers of an unfinished
  // one) is freed.
  void Drew(const ServedVolume& volume, const ExtractRequest& request, int64_t triangles) {
    const bool same = last_.Same(volume, request);
    if (charged_ > 0 && Find(volume, request) == nullptr && !same) Drop();
    sliding_ = !same && last_.hierarchy != nullptr;
    last_ = MeshKey(volume, request);
    last_triangles_ = triangles;
  }

  // Frees the buffers and gives their memory back to the budget.
  void Drop() {
    cut_.Release();
    hierarchy_.reset();
    holds_frame_ = false;
    if (charged_ > 0) budget_->Give(charged_);
    charged_ = 0;
  }

 private:
  // What identifies a frame's mesh, whatever its view: the volume as prepared, and the
  // request's MeshName.
  struct MeshKey {
    MeshKey() = default;
    MeshKey(const ServedVolume& volume, const ExtractRequest& r)
        : hierarchy(volume.prepared.hierarchy.get()), name(MeshName::Of(r)) {}
    bool Same(const ServedVolume& volume, const ExtractRequest& r) const {
      return hierarchy != nullptr && volume.prepared.hierarchy.get() == hierarchy &&
             MeshName::Of(r) == name;
    }
    const Hierarchy* hierarchy = nullptr;  // compared only, never read
    MeshName name;
  };

  // The recording's tree grew by `bytes` (called by the extraction's workers, as each subtree's
  // records grow): what it then holds past what is charged is taken from the budget, freeing
  // other streams' frames if need be; false (the recording stops) if there is no room. So the
  // budget is overshot at most by what the workers are recording at the moment.
  bool Reserve(int64_t bytes) {
    std::lock_guard<std::mutex> lock(reserve_mu_);
    tree_growth_ += bytes;
    const int64_t need = tree_bytes_at_start_ + tree_growth_ - charged_;
    if (need <= 0) return true;
    if (!budget_->TakeEvicting(need, this)) return false;
    charged_ += need;
    return true;
  }

  RetainBudget* budget_;
  std::mutex use_mu_;
  std::mutex reserve_mu_;  // Reserve's, from the recording extraction's workers
  int64_t tree_bytes_at_start_ = 0, tree_growth_ = 0;  // of the recording
  std::atomic<uint64_t> last_use_{0};
  MeshKey last_;          // the mesh of the last refined frame drawn
  bool sliding_ = false;  // and it differs from the one drawn before it
  int64_t last_triangles_ = 0;
  RetainedCut cut_;
  bool holds_frame_ = false;  // cut_ holds a whole frame of the volume below
  // The volume as prepared when the frame was extracted: re-prepared, it is another mesh.
  std::weak_ptr<const Hierarchy> hierarchy_;
  int64_t charged_ = 0;  // bytes taken from the budget for cut_'s buffers
};

inline bool RetainBudget::TakeEvicting(int64_t bytes, const RetainedFrame* taker) {
  if (Take(bytes)) return true;
  if (bytes > limit_) return false;
  std::lock_guard<std::mutex> lock(mu_);
  // Least recently used first, by stamps read once: other streams' jobs move theirs meanwhile,
  // and sorting on values that change under it is undefined behaviour.
  std::vector<std::pair<uint64_t, RetainedFrame*>> others;
  for (RetainedFrame* f : frames_)
    if (f != taker) others.push_back({f->last_use(), f});
  std::sort(others.begin(), others.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  // Frames in use stay (their jobs hold the lock; never wait here: the taker holds its own).
  // Frames are freed only if enough can be freed: otherwise idle streams would lose theirs
  // for nothing.
  std::vector<std::pair<RetainedFrame*, std::unique_lock<std::mutex>>> victims;
  int64_t freeable = limit_ - used();
  for (const auto& entry : others) {
    if (freeable >= bytes) break;
    RetainedFrame* f = entry.second;
    std::unique_lock<std::mutex> in_use(f->mutex(), std::try_to_lock);
    if (!in_use.owns_lock() || f->charged() == 0) continue;
    freeable += f->charged();
    victims.push_back({f, std::move(in_use)});
  }
  if (freeable < bytes) return false;  // the locks are released, nothing freed
  for (auto& victim : victims) victim.first->Drop();
  return Take(bytes);
}

}  // namespace isostream::service
