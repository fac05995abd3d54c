// The output of one subtree of the traversal, and a pool that recycles these buffers.
//
// A frame is extracted as ~256 subtrees, each into its own buffers, appended to the frame in
// draw order as soon as its predecessors are done. Fresh buffers for every subtree of every
// frame cost page faults (slow on VMs: a 1 M-triangle frame touched ~35 MB of new pages);
// recycled ones keep their capacity, and only a few are alive at once.
#pragma once

#include <cstdint>
#include <cstring>
#include <glm/vec3.hpp>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <utility>
#include <vector>

#include "server/extract/append_buffer.h"

namespace isostream::extract_internal {

// Where a vertex made by clipping at the data box is, and for which surface. The triangles
// beside a clipped edge compute its crossing with a face of the box from the same two ends
// (ClipToDataBox orders them), so they make the same bits, and its normal is made from the
// position alone (LeafEmitter::ClipNormal): the vertex is made once (it was made once per
// triangle, leaving the edges through it open to any check by index).
struct ClipVertexKey {
  uint32_t bits[3];  // the position's floats
  uint32_t surface;
  static ClipVertexKey Of(const glm::vec3& p, uint8_t surface) {
    ClipVertexKey k;
    std::memcpy(&k.bits[0], &p, sizeof(p));
    k.surface = surface;
    return k;
  }
  bool operator==(const ClipVertexKey& o) const {
    return bits[0] == o.bits[0] && bits[1] == o.bits[1] && bits[2] == o.bits[2] &&
           surface == o.surface;
  }
};
struct ClipVertexKeyHash {
  size_t operator()(const ClipVertexKey& k) const {
    uint64_t h = k.surface;
    for (const uint32_t b : k.bits) h = (h ^ b) * 0x9e3779b97f4a7c15ull;
    return size_t(h ^ (h >> 29));
  }
};
// Clip vertex key -> vertex: per subtree in the emitter, per frame in the join. Node-based:
// only leaves that straddle the data box make such vertices, a few per thousand.
using ClipVertexIds = std::unordered_map<ClipVertexKey, uint32_t, ClipVertexKeyHash>;

// A mesh with local vertex indices, plus the vertices that lie on the subtree root's faces
// (they may be shared with a neighbouring subtree and are merged on append).
struct SubtreeMesh {
  AppendBuffer<float> positions;  // 3 per vertex
  AppendBuffer<float> normals;    // 3 per vertex
  AppendBuffer<uint32_t> triangles;
  AppendBuffer<uint8_t> surface;
  std::vector<std::pair<uint32_t, uint64_t>> boundary;  // (local vertex, edge key)
  // The vertices clipping made (local vertex, key): merged with the same ones of other subtrees.
  std::vector<std::pair<uint32_t, ClipVertexKey>> clipped;
  // The same, for the emitter to find them while the subtree is extracted. Kept here, not in
  // the emitter: a member with a destructor there changed which of the traversal's functions GCC
  // inlines (+1-2% instructions at cayley:257 eps 0, where nothing clips).
  ClipVertexIds clip_ids;
  uint32_t vertices = 0;
  int64_t visited = 0;
  int64_t leaves = 0;
  // Some vertex may be used by no triangle (DropUnusedVertices): a triangle was clipped at the
  // data box, and its corners outside went.
  bool maybe_unused = false;

  size_t vertex_count() const { return vertices; }
  size_t capacity_bytes() const {
    return (positions.capacity() + normals.capacity()) * sizeof(float) +
           triangles.capacity() * sizeof(uint32_t) + surface.capacity() +
           boundary.capacity() * sizeof(boundary[0]) + clipped.capacity() * sizeof(clipped[0]) +
           clip_ids.bucket_count() * sizeof(void*) +
           clip_ids.size() * (sizeof(ClipVertexIds::value_type) + 2 * sizeof(void*));
  }
  void clear() {
    positions.clear();
    normals.clear();
    triangles.clear();
    surface.clear();
    boundary.clear();
    clipped.clear();
    if (!clip_ids.empty()) clip_ids.clear();
    vertices = 0;
    visited = leaves = 0;
    maybe_unused = false;
  }

  // Removes the vertices no triangle uses, keeping the others in order (the output stays
  // deterministic); boundary entries of removed vertices go too.
  void DropUnusedVertices() {
    constexpr uint32_t kUnused = 0xffffffffu;
    std::vector<uint32_t> remap(vertices, kUnused);
    for (size_t i = 0; i < triangles.size(); ++i) remap[triangles[i]] = 0;
    uint32_t kept = 0;
    for (uint32_t v = 0; v < vertices; ++v) {
      if (remap[v] == kUnused) continue;
      for (size_t a = 0; a < 3; ++a) {
        positions[3 * size_t(kept) + a] = positions[3 * size_t(v) + a];
        normals[3 * size_t(kept) + a] = normals[3 * size_t(v) + a];
      }
      remap[v] = kept++;
    }
    if (kept == vertices) return;
    for (size_t i = 0; i < triangles.size(); ++i) triangles[i] = remap[triangles[i]];
    size_t b = 0;
    for (const auto& [local, key] : boundary)
      if (remap[local] != kUnused) boundary[b++] = {remap[local], key};
    boundary.resize(b);
    size_t c = 0;
    for (const auto& [local, key] : clipped)
      if (remap[local] != kUnused) clipped[c++] = {remap[local], key};
    clipped.resize(c);
    positions.Shrink(3 * size_t(kept));
    normals.Shrink(3 * size_t(kept));
    vertices = kept;
  }
};

class SubtreeMeshPool {
 public:
  static SubtreeMeshPool& Global() {
    static SubtreeMeshPool pool;
    return pool;
  }

  std::unique_ptr<SubtreeMesh> Acquire() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (!free_.empty()) {
        auto mesh = std::move(free_.back());
        free_.pop_back();
        return mesh;
      }
    }
    return std::make_unique<SubtreeMesh>();
  }

  // Keeps at most kMaxPooled meshes of moderate size; the rest are freed.
  void Release(std::unique_ptr<SubtreeMesh> mesh) {
    if (!mesh || mesh->capacity_bytes() > kMaxPooledBytes) return;
    mesh->clear();
    std::lock_guard<std::mutex> lock(mu_);
    if (free_.size() < kMaxPooled) free_.push_back(std::move(mesh));
  }

 private:
  static constexpr size_t kMaxPooled = 32;
  static constexpr size_t kMaxPooledBytes = size_t{16} << 20;
  std::mutex mu_;
  std::vector<std::unique_ptr<SubtreeMesh>> free_;
};

}  // namespace isostream::extract_internal
