// Internal to shared/: an order-keeping triangle connectivity coder for the frame codec's
// kDracoEdgeCache chunks. Draco's sequential coder entropy-codes each corner's index as a delta
// from the previous corner, which costs ~2.6 bytes per triangle on view-ordered isosurface
// frames; this coder keeps every triangle and every corner in place and spends ~1.45.
//
// Model. Vertices are numbered in order of first use (GatherTriangleRange does this), so a
// vertex seen for the first time is always the next unused number and costs one symbol. The
// coder keeps, identically on both sides:
//   - an edge FIFO of the kEdgeFifoSize most recent directed edges (each triangle (a, b, c)
//     pushes (c, a), (b, c), (a, b), so (a, b) ends up most recent);
//   - a vertex cache of the kVertexCacheSize most recently used vertices, most recent first
//     (after each triangle its corners are moved to the front in corner order, c ending first).
// A triangle whose corners r and r+1 (mod 3) are FIFO entry k reversed, as in a neighbour with
// the same winding, is coded by (k, r) and its third corner; any other triangle by its three
// corners. A corner is coded as "new vertex", as a cache position, or explicitly as the
// distance back from the newest vertex.
//
// Stream: three symbol arrays, each written with isostream's rANS coder (AppendSymbols,
// shared/internal/symbol_stream.h)
// and omitted when empty, one after the other with nothing in between:
//   triangle symbols, one per triangle: 3k + r for an edge match, kNoEdge otherwise;
//   corner symbols, one per coded corner: 0 new, 1 + i cache position i, kExplicitCorner;
//   explicit values, one per kExplicitCorner: newest vertex index minus the corner's index.
// The decoder derives each array's length from the ones before it, checks every symbol against
// the state it refers to, and requires the stream to end exactly after the last array.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "shared/status.h"

namespace isostream::internal {

inline constexpr uint32_t kEdgeFifoSize = 32;
inline constexpr uint32_t kVertexCacheSize = 32;
inline constexpr uint32_t kNoEdge = 3 * kEdgeFifoSize;
inline constexpr uint32_t kExplicitCorner = kVertexCacheSize + 1;

// Appends the coded connectivity of `triangle_count` triangles (3 indices each) to `out`.
// Indices must be numbered in order of first use and below vertex_count, and every vertex must
// be used; InvalidArgument otherwise.
absl::Status EncodeOrderedConnectivity(const uint32_t* triangles, size_t triangle_count,
                                       size_t vertex_count, std::string* out);

// Decodes exactly data[0, size) into 3 * triangle_count indices (replacing `triangles`).
// DataLoss unless the stream decodes to that many triangles using exactly vertex_count vertices
// and ends where the data does.
absl::Status DecodeOrderedConnectivity(const char* data, size_t size, size_t triangle_count,
                                       size_t vertex_count, std::vector<uint32_t>* triangles);

}  // namespace isostream::internal
