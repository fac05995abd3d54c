#include "shared/internal/ordered_connectivity.h"

#include "shared/internal/symbol_stream.h"
#include "shared/uninitialized_vector.h"

#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include <absl/strings/str_cat.h>

#include <algorithm>
#include <cstring>
#include <limits>
#include <memory>

namespace isostream::internal {
namespace {

static_assert((kEdgeFifoSize & (kEdgeFifoSize - 1)) == 0, "the edge FIFO is a power-of-2 ring");
static_assert(kVertexCacheSize % 4 == 0, "the cache is searched four entries at a time");

uint64_t EdgeKey(uint32_t from, uint32_t to) { return (uint64_t{from} << 32) | to; }

// The coder state both sides keep in step.
class CoderState {
 public:
  // Vertices are numbered 0..vertex_count-1.
  explicit CoderState(size_t vertex_count) : in_cache_(vertex_count, 0) {
    // No vertex has this number (vertex_count < 2^32), so unused entries never match.
    std::fill_n(window_, kWindowSpace, 0xffffffffu);
  }
  CoderState(const CoderState&) = delete;  // cache_ points into window_
  CoderState& operator=(const CoderState&) = delete;

  // Most recent first: k = 0 is the last edge pushed. Requires k < edge_count().
  uint64_t edge(uint32_t k) const { return edges_[(pushes_ - 1 - k) & (kEdgeFifoSize - 1)]; }
  uint32_t edge_count() const { return std::min(pushes_, kEdgeFifoSize); }
  // Edges pushed so far; entry k is push number pushes() - 1 - k.
  uint32_t pushes() const { return pushes_; }

  // Most recent first. Requires i < cache_size().
  uint32_t cached(uint32_t i) const { return cache_[i]; }
  uint32_t cache_size() const { return cache_size_; }

  // Position of `vertex` in the cache, or cache_size() if absent: the per-vertex flag answers
  // misses, and a hit compares all entries at once (they are distinct) instead of walking.
  uint32_t FindCached(uint32_t vertex) const {
    if (!in_cache_[vertex]) return cache_size_;
#ifdef __SSE2__
    const __m128i key = _mm_set1_epi32(static_cast<int>(vertex));
    // Most hits are among the first eight entries: look there first.
    uint32_t hits = 0;
    for (uint32_t i = 0; i < 8; i += 4) {
      const __m128i entries = _mm_loadu_si128(reinterpret_cast<const __m128i*>(cache_ + i));
      const __m128i equal = _mm_cmpeq_epi32(entries, key);
      hits |= static_cast<uint32_t>(_mm_movemask_ps(_mm_castsi128_ps(equal))) << i;
    }
    if (hits) return static_cast<uint32_t>(__builtin_ctz(hits));
    for (uint32_t i = 8; i < kVertexCacheSize; i += 4) {
      const __m128i entries = _mm_loadu_si128(reinterpret_cast<const __m128i*>(cache_ + i));
      const __m128i equal = _mm_cmpeq_epi32(entries, key);
      hits |= static_cast<uint32_t>(_mm_movemask_ps(_mm_castsi128_ps(equal))) << i;
    }
    return hits ? static_cast<uint32_t>(__builtin_ctz(hits)) : cache_size_;
#else
    uint32_t i = 0;
    while (i < cache_size_ && cache_[i] != vertex) ++i;
    return i;
#endif
  }

  // What a caller knows of a corner's cache position before the triangle is recorded.
  static constexpr uint32_t kUnknown = 0xffffffffu;  // look it up
  static constexpr uint32_t kAbsent = 0xfffffffeu;   // not in the cache

  // Records a triangle once all three corners are known. `at[r]` is corner r's cache position
  // before this call (< cache_size()), kAbsent or kUnknown; known positions save the lookups.
  template <typename OnPush>
  void Add(const uint32_t x[3], uint32_t at[3], OnPush on_push) {
    for (int r = 2; r >= 0; --r) {
      const uint64_t key = EdgeKey(x[r], x[(r + 1) % 3]);
      on_push(key, pushes_);
      edges_[pushes_ & (kEdgeFifoSize - 1)] = key;
      ++pushes_;
    }
    for (int r = 0; r < 3; ++r) {
      const uint32_t from = at[r] == kUnknown  ? FindCached(x[r])
                            : at[r] == kAbsent ? cache_size_
                                               : at[r];
      MoveToFront(x[r], from);
      // Keep the later corners' positions current: entries before `from` moved back by one,
      // the last one falling out if the cache was full and x[r] new to it.
      for (int s = r + 1; s < 3; ++s) {
        if (x[s] == x[r]) {
          at[s] = 0;
        } else if (at[s] < from) {
          at[s] = at[s] + 1 < kVertexCacheSize ? at[s] + 1 : kAbsent;
        }
      }
    }
  }

 private:
  // Moves `vertex`, at position `from` (cache_size() if absent), to the front, dropping the
  // least recent vertex when the cache is full: entries 0..from-1 move up by one.
  void MoveToFront(uint32_t vertex, uint32_t from) {
    if (from == cache_size_) {
      // New to the cache, about one corner in six: the cache slides down one entry in window_
      // instead of every entry moving up, and the least recent one falls off its end.
      if (cache_size_ == kVertexCacheSize) {
        in_cache_[cache_[kVertexCacheSize - 1]] = 0;
      } else {
        ++cache_size_;
      }
      in_cache_[vertex] = 1;
      if (cache_ == window_) {  // at the bottom of window_: move back to the top
        std::memmove(window_ + kWindowSpace - kVertexCacheSize, window_,
                     kVertexCacheSize * sizeof(uint32_t));
        cache_ = window_ + kWindowSpace - kVertexCacheSize;
      }
      *--cache_ = vertex;
      return;
    }
#ifdef __SSE2__
    // Four entries at a time, only as far as `from`: a lane takes its left neighbour (the
    // first lane the previous group's last) where its position is at most `from`. A memmove
    // call costs more than this for the few entries a move usually shifts.
    const __m128i limit = _mm_set1_epi32(static_cast<int>(from) + 1);
    __m128i carry = _mm_cvtsi32_si128(static_cast<int>(vertex));
    __m128i position = _mm_setr_epi32(0, 1, 2, 3);
    const __m128i four = _mm_set1_epi32(4);
    for (uint32_t i = 0; i <= from; i += 4) {
      __m128i* group = reinterpret_cast<__m128i*>(cache_ + i);
      const __m128i entries = _mm_loadu_si128(group);
      const __m128i shifted = _mm_or_si128(_mm_slli_si128(entries, 4), carry);
      carry = _mm_srli_si128(entries, 12);
      const __m128i take = _mm_cmplt_epi32(position, limit);
      _mm_storeu_si128(group,
                       _mm_or_si128(_mm_and_si128(take, shifted), _mm_andnot_si128(take, entries)));
      position = _mm_add_epi32(position, four);
    }
#else
    for (uint32_t i = from; i > 0; --i) cache_[i] = cache_[i - 1];
    cache_[0] = vertex;
#endif
  }

  uint64_t edges_[kEdgeFifoSize] = {};
  uint32_t pushes_ = 0;  // wraps only past 2^32 edges, far more than a chunk has
  static constexpr uint32_t kWindowSpace = 8 * kVertexCacheSize;
  // The cache is the kVertexCacheSize entries from cache_, most recent first, unused ones
  // 0xffffffff; cache_ slides down through window_ as new vertices arrive.
  uint32_t window_[kWindowSpace];
  uint32_t* cache_ = window_ + kWindowSpace - kVertexCacheSize;
  uint32_t cache_size_ = 0;
  std::vector<uint8_t> in_cache_;  // per vertex: 1 while it is in cache_
};

// Encoder side: finds the newest FIFO entry holding an edge without scanning the FIFO. A
// direct-mapped table remembers, per hashed edge, its latest push; a collision can only hide a
// match (the triangle is then coded without it), never report a wrong one.
class EdgeIndex {
 public:
  void Record(uint64_t key, uint32_t push) {
    Slot& slot = slots_[Hash(key)];
    slot.key = key;
    slot.push = push;
    slot.used = true;
  }

  // FIFO position k of `key` in `state`, or -1.
  int64_t Find(uint64_t key, const CoderState& state) const {
    const Slot& slot = slots_[Hash(key)];
    if (!slot.used || slot.key != key) return -1;
    const uint32_t k = state.pushes() - 1 - slot.push;
    return k < kEdgeFifoSize ? int64_t{k} : -1;
  }

 private:
  static constexpr int kBits = 10;
  static size_t Hash(uint64_t key) {
    return static_cast<size_t>((key * 0x9e3779b97f4a7c15ull) >> (64 - kBits));
  }
  struct Slot {
    uint64_t key = 0;
    uint32_t push = 0;
    bool used = false;
  };
  Slot slots_[size_t{1} << kBits];
};

bool ReadArray(const char* data, size_t size, size_t* at, size_t count,
               std::vector<uint32_t>* symbols) {
  symbols->resize(count);
  return count == 0 || ReadSymbols(data, size, at, count, symbols->data());
}

}  // namespace

absl::Status EncodeOrderedConnectivity(const uint32_t* triangles, size_t triangle_count,
                                       size_t vertex_count, std::string* out) {
  if (triangle_count > std::numeric_limits<int>::max() / 3 ||
      vertex_count > std::numeric_limits<uint32_t>::max()) {
    return absl::InvalidArgumentError("too many triangles or vertices for one chunk");
  }
  // Written once each, at most one corner symbol and one explicit value per corner.
  UninitializedVector<uint32_t> triangle_symbols(triangle_count);
  UninitializedVector<uint32_t> corner_symbols(3 * triangle_count);
  UninitializedVector<uint32_t> explicit_values(3 * triangle_count);
  size_t corners = 0, explicits = 0;
  CoderState state(vertex_count);
  auto index = std::make_unique<EdgeIndex>();
  auto record = [&index](uint64_t key, uint32_t push) { index->Record(key, push); };
  uint32_t next = 0;  // the number a new vertex gets

  // Codes one corner; false if `vertex` breaks first-use order or the vertex count.
  auto code_corner = [&](uint32_t vertex, uint32_t* at) -> bool {
    if (vertex == next) {
      *at = CoderState::kAbsent;
      if (next == vertex_count) return false;
      ++next;
      corner_symbols[corners++] = 0;
      return true;
    }
    if (vertex > next) return false;
    *at = state.FindCached(vertex);
    if (*at < state.cache_size()) {
      corner_symbols[corners++] = 1 + *at;
    } else {
      *at = CoderState::kAbsent;
      corner_symbols[corners++] = kExplicitCorner;
      explicit_values[explicits++] = next - 1 - vertex;
    }
    return true;
  };

  for (size_t t = 0; t < triangle_count; ++t) {
    const uint32_t* x = triangles + 3 * t;
    // The newest FIFO edge that is one of this triangle's edges reversed (smallest k, then r).
    uint32_t symbol = kNoEdge;
    for (uint32_t r = 0; r < 3; ++r) {
      const int64_t k = index->Find(EdgeKey(x[(r + 1) % 3], x[r]), state);
      if (k >= 0 && (symbol == kNoEdge || uint32_t(k) < symbol / 3)) symbol = 3 * uint32_t(k) + r;
    }
    triangle_symbols[t] = symbol;
    uint32_t at[3] = {CoderState::kUnknown, CoderState::kUnknown, CoderState::kUnknown};
    bool ok = true;
    if (symbol == kNoEdge) {
      ok = code_corner(x[0], &at[0]) && code_corner(x[1], &at[1]) && code_corner(x[2], &at[2]);
    } else {
      const int r = (symbol % 3 + 2) % 3;
      ok = code_corner(x[r], &at[r]);
    }
    if (!ok) {
      return absl::InvalidArgumentError(
          absl::StrCat("triangle ", t, " uses a vertex that is not the next new one (", next,
                       ") nor an earlier one, or is not below the vertex count ", vertex_count));
    }
    state.Add(x, at, record);
  }
  if (next != vertex_count) {
    return absl::InvalidArgumentError(
        absl::StrCat("the triangles use ", next, " of ", vertex_count, " vertices"));
  }
  if (triangle_count > 0) AppendSymbols(triangle_symbols.data(), triangle_count, out);
  if (corners > 0) AppendSymbols(corner_symbols.data(), corners, out);
  if (explicits > 0) AppendSymbols(explicit_values.data(), explicits, out);
  return absl::OkStatus();
}

absl::Status DecodeOrderedConnectivity(const char* data, size_t size, size_t triangle_count,
                                       size_t vertex_count, std::vector<uint32_t>* triangles) {
  if (triangle_count > std::numeric_limits<uint32_t>::max() / 3 ||
      vertex_count > std::numeric_limits<uint32_t>::max()) {
    return absl::DataLossError("connectivity counts out of range");
  }
  size_t read_at = 0;
  std::vector<uint32_t> triangle_symbols;
  if (!ReadArray(data, size, &read_at, triangle_count, &triangle_symbols)) {
    return absl::DataLossError("connectivity: triangle symbols do not decode");
  }
  size_t corner_count = 0;
  for (uint32_t s : triangle_symbols) {
    if (s > kNoEdge) return absl::DataLossError("connectivity: triangle symbol out of range");
    corner_count += s == kNoEdge ? 3 : 1;
  }
  std::vector<uint32_t> corner_symbols;
  if (!ReadArray(data, size, &read_at, corner_count, &corner_symbols)) {
    return absl::DataLossError("connectivity: corner symbols do not decode");
  }
  size_t explicit_count = 0;
  for (uint32_t s : corner_symbols) {
    if (s > kExplicitCorner) return absl::DataLossError("connectivity: corner symbol out of range");
    explicit_count += s == kExplicitCorner;
  }
  std::vector<uint32_t> explicit_values;
  if (!ReadArray(data, size, &read_at, explicit_count, &explicit_values)) {
    return absl::DataLossError("connectivity: explicit corners do not decode");
  }
  if (read_at != size) {
    return absl::DataLossError("connectivity: bytes left over after the last symbol");
  }

  triangles->resize(3 * triangle_count);
  CoderState state(vertex_count);
  uint32_t next = 0;
  size_t corner = 0, explicit_index = 0;
  auto decode_corner = [&](uint32_t* vertex, uint32_t* at) -> bool {
    const uint32_t s = corner_symbols[corner++];
    if (s == 0) {
      if (next == vertex_count) return false;
      *vertex = next++;
      *at = CoderState::kAbsent;
    } else if (s == kExplicitCorner) {
      const uint32_t back = explicit_values[explicit_index++];
      if (back >= next) return false;
      *vertex = next - 1 - back;
      // Normally not in the cache (the encoder would have used its position), but a stream
      // may code a cached vertex explicitly: the lookup in Add decides.
      *at = CoderState::kUnknown;
    } else {
      if (s - 1 >= state.cache_size()) return false;
      *vertex = state.cached(s - 1);
      *at = s - 1;
    }
    return true;
  };
  for (size_t t = 0; t < triangle_count; ++t) {
    uint32_t* x = triangles->data() + 3 * t;
    const uint32_t s = triangle_symbols[t];
    bool ok = true;
    uint32_t at[3] = {CoderState::kUnknown, CoderState::kUnknown, CoderState::kUnknown};
    if (s == kNoEdge) {
      for (int r = 0; r < 3 && ok; ++r) ok = decode_corner(&x[r], &at[r]);
    } else {
      const uint32_t k = s / 3, r = s % 3;
      if (k >= state.edge_count()) {
        ok = false;
      } else {
        const uint64_t e = state.edge(k);
        x[r] = static_cast<uint32_t>(e);
        x[(r + 1) % 3] = static_cast<uint32_t>(e >> 32);
        ok = decode_corner(&x[(r + 2) % 3], &at[(r + 2) % 3]);
      }
    }
    if (!ok) {
      return absl::DataLossError(
          absl::StrCat("connectivity: triangle ", t, " refers to a vertex it cannot have"));
    }
    state.Add(x, at, [](uint64_t, uint32_t) {});
  }
  if (next != vertex_count) {
    return absl::DataLossError(
        absl::StrCat("connectivity: the triangles use ", next, " of ", vertex_count, " vertices"));
  }
  return absl::OkStatus();
}

}  // namespace isostream::internal
