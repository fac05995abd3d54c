// Edge -> vertex lookup for sharing isosurface vertices between the tetrahedra around an edge
// (the edge-based idea of Kipfer & Westermann): each edge crossing is computed once per surface.
//
// Open addressing with linear probing over one flat array. Clearing is O(1): each slot carries
// the generation that wrote it, and Reset() starts a new generation. The table grows by
// rehashing when half full; it never allocates per lookup.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace isostream {

class EdgeVertexTable {
 public:
  static constexpr uint32_t kMissing = 0xffffffffu;

  explicit EdgeVertexTable(size_t initial_capacity = 1 << 12) {
    Allocate(RoundUp(initial_capacity));
  }
  // data_ points into slots_: a copy or a move would leave it pointing at another table.
  EdgeVertexTable(const EdgeVertexTable&) = delete;
  EdgeVertexTable& operator=(const EdgeVertexTable&) = delete;

  void Reset() {
    ++generation_;
    size_ = 0;
    if (generation_ == 0) {  // wrapped: stale slots could look current
      for (auto& s : slots_) s.generation = 0;
      generation_ = 1;
    }
  }

  // Returns the vertex stored for key, or kMissing after reserving the slot for `fresh`
  // (the caller then creates vertex `fresh`).
  uint32_t FindOrInsert(uint64_t key, uint32_t fresh) {
    size_t i = Hash(key);
    for (;;) {
      Slot& s = data_[i];
      if (s.generation != generation_) {
        s = Slot{key, fresh, generation_};
        if (++size_ >= grow_at_) Grow();  // on inserts only: hits, most lookups, skip the test
        return kMissing;
      }
      if (s.key == key) return s.value;
      i = (i + 1) & mask_;
    }
  }

  // The value stored for key, or kMissing (inserts nothing).
  uint32_t Find(uint64_t key) const {
    for (size_t i = Hash(key);; i = (i + 1) & mask_) {
      const Slot& s = data_[i];
      if (s.generation != generation_) return kMissing;
      if (s.key == key) return s.value;
    }
  }

  size_t size() const { return size_; }

 private:
  struct Slot {
    uint64_t key;
    uint32_t value;
    uint32_t generation;
  };

  static size_t RoundUp(size_t n) {
    size_t c = 16;
    while (c < n) c <<= 1;
    return c;
  }
  // Fibonacci hashing: keys are packed coordinates, and one multiply spreads them well
  // enough; the high bits are used.
  size_t Hash(uint64_t k) const { return size_t((k * 0x9e3779b97f4a7c15ull) >> shift_); }
  void Allocate(size_t capacity) {
    slots_.assign(capacity, Slot{0, 0, 0});
    data_ = slots_.data();
    grow_at_ = capacity / 2;  // at most half full: probe runs stay short
    mask_ = capacity - 1;
    shift_ = 64 - __builtin_ctzll(capacity);
    generation_ = 1;
    size_ = 0;
  }
  __attribute__((noinline)) void Grow() {  // rare: kept out of the lookup's frame
    std::vector<Slot> old;
    old.swap(slots_);
    const uint32_t gen = generation_;
    Allocate(old.size() * 2);
    for (const Slot& s : old)
      if (s.generation == gen) FindOrInsert(s.key, s.value);
  }

  std::vector<Slot> slots_;
  Slot* data_ = nullptr;  // slots_.data(), and the bound below, without vector arithmetic
  size_t grow_at_ = 0;
  size_t mask_ = 0;
  int shift_ = 64;
  size_t size_ = 0;
  uint32_t generation_ = 1;
};

}  // namespace isostream
