// What a stream keeps of its last refined frame, so that a later view of the same mesh (same
// volume, isovalues, eps or budget, normals) is drawn by re-ordering it
// (server/extract/retained_cut.h) instead of extracting it again; and the daemon-wide cap on
// the memory all streams keep so (frames.retain_mb).
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "server/extract/retained_cut.h"
#include "server/service/catalogue.h"

namespace isostream::service {

// Bytes of retained frames the daemon holds, against its limit. Thread-safe.
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
  void Give(int64_t bytes) { used_.fetch_sub(bytes); }
  int64_t used() const { return used_.load(); }
  int64_t limit() const { return limit_; }

 private:
  std::atomic<int64_t> used_{0};
  const int64_t limit_;
};

// One stream's retained frame. Used by the stream's one running job at a time: no lock.
class RetainedFrame {
 public:
  explicit RetainedFrame(RetainBudget* budget) : budget_(budget) {}
  ~RetainedFrame() { Clear(); }
  RetainedFrame(const RetainedFrame&) = delete;
  RetainedFrame& operator=(const RetainedFrame&) = delete;

  // Whether frames are retained at all (a limit of 0 turns it off).
  bool enabled() const { return budget_ != nullptr && budget_->limit() > 0; }

  // Whether the refined frame about to be extracted for `request` should be recorded: when it
  // draws the mesh the stream's previous refined frame drew, i.e. the client is moving around
  // one mesh. Recording costs an extraction ~15-30% more, which a client that changes the
  // isovalues or eps with every view (a slider) would pay for nothing.
  bool ShouldRecord(const ServedVolume& volume, const ExtractRequest& request) const {
    return enabled() && last_.Same(volume, request);
  }
  // The mesh of the refined frame just drawn (extracted or re-ordered).
  void Drew(const ServedVolume& volume, const ExtractRequest& request) {
    last_ = MeshKey(volume, request);
  }

  // The retained cut if it draws `request` on `volume` as prepared now, else null.
  const RetainedCut* Find(const ServedVolume& volume, const ExtractRequest& request) const {
    if (charged_ == 0) return nullptr;
    const HierarchyPtr h = hierarchy_.lock();
    if (h == nullptr || h != volume.prepared.hierarchy) return nullptr;
    double budget_eps = -1;
    if (request.budget > 0)
      budget_eps = volume.budget_memo.Find(request.isovalues, request.budget).value_or(-1.0);
    return cut_.Serves(request, budget_eps) ? &cut_ : nullptr;
  }

  // Keeps `cut`, the frame just extracted on `volume`, in place of the one before, if the
  // daemon's budget has room for it; otherwise keeps nothing.
  void Keep(const ServedVolume& volume, RetainedCut&& cut) {
    Clear();
    const int64_t bytes = int64_t(cut.memory_bytes());
    if (bytes == 0 || budget_ == nullptr || !budget_->Take(bytes)) return;
    cut_ = std::move(cut);
    hierarchy_ = volume.prepared.hierarchy;
    charged_ = bytes;
  }

  void Clear() {
    if (charged_ == 0) return;
    cut_ = RetainedCut();
    hierarchy_.reset();
    budget_->Give(charged_);
    charged_ = 0;
  }

 private:
  // What identifies a frame's mesh, whatever its view.
  struct MeshKey {
    MeshKey() = default;
    MeshKey(const ServedVolume& volume, const ExtractRequest& r)
        : hierarchy(volume.prepared.hierarchy.get()),
          isovalues(r.isovalues),
          eps(r.budget > 0 ? 0.0 : r.eps),
          budget(r.budget),
          normals(r.normals) {}
    bool Same(const ServedVolume& volume, const ExtractRequest& r) const {
      const MeshKey k(volume, r);
      return hierarchy != nullptr && k.hierarchy == hierarchy && k.isovalues == isovalues &&
             k.eps == eps && k.budget == budget && k.normals == normals;
    }
    const Hierarchy* hierarchy = nullptr;  // compared only, never read
    std::vector<float> isovalues;
    double eps = 0;
    int64_t budget = 0;
    NormalMode normals = NormalMode::kSmooth;
  };

  RetainBudget* budget_;
  MeshKey last_;
  // The volume as prepared when the frame was extracted: re-prepared, it is another mesh.
  std::weak_ptr<const Hierarchy> hierarchy_;
  RetainedCut cut_;
  int64_t charged_ = 0;  // bytes taken from the budget; 0: nothing retained
};

}  // namespace isostream::service
