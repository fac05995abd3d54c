// Frame codec: turns a range of an OrderedMesh's triangles into a self-contained byte chunk and
// back, keeping triangle order, because the order is the product (drawing first to last is the
// back-to-front order the server computed).
//
// Three codecs share one 24-byte little-endian chunk header:
//   0  'I' 'S' 'C' '1'   magic
//   4  uint8   format version (1)
//   5  uint8   codec: 1 raw, 2 Draco mesh, 3 edge cache (kDracoEdgeCache: a historical name)
//   6  uint16  flags: bit 0 = the chunk carries normals; other bits must be 0
//   8  uint32  triangle count
//   12 uint32  vertex count
//   16 uint32  payload size in bytes (the chunk is exactly header + payload)
//   20 uint32  low 32 bits of XXH3-64 of the payload
//
// Raw payload: float32 positions[3V], float32 normals[3V] (if flagged), uint32 triangles[3T],
// uint8 surface[T].
//
// Draco vertex attributes (codec 2): POSITION (float32 x3, quantized unless position_bits is
// 0), NORMAL (float32 x3, octahedral-quantized unless normal_bits is 0; absent when the mesh
// has no normals) and one GENERIC uint8 per vertex holding the vertex's surface index in bits
// 0-6 and, in bit 7, "normal undefined": Draco's octahedral coding cannot represent the zero
// normal OrderedMesh uses for "undefined" and would turn it into (1, 0, 0). Draco codes them
// in vertex order, each value as a delta from the previous vertex's.
//
// Draco mesh payload (codec 2): one Draco mesh written with MESH_SEQUENTIAL_ENCODING, the only
// Draco mesh method that keeps face order (edgebreaker reorders faces, drops degenerate ones and
// splits non-manifold vertices), with the attributes above.
//
// Edge-cache payload (codec 3, EncodeChunk's default; no Draco inside despite the enum's name):
//   uint32   byte size S of the vertex part
//   S bytes  vertex part (shared/internal/vertex_coder.h): bit counts, the quantization cube,
//            then per vertex a tag byte (surface index | bit 7 "normal undefined"), positions
//            quantized on the same grid as Draco's (decoded values are bit-identical to codec
//            2's) and octahedral normals, each as wrapped deltas from the previous vertex
//   rest     the triangles, coded by isostream's order-keeping connectivity coder
//            (shared/internal/ordered_connectivity.h: an edge FIFO and a vertex cache)
// Every symbol array in both parts is entropy-coded by isostream's own static rANS coder
// (shared/internal/symbol_stream.h), whose decoder checks every field and that each array ends
// exactly. Same vertices, triangles and corner order as codec 2; on a view-ordered 1 M-triangle
// isosurface frame the chunk costs ~3.4 bytes per triangle (codec 2: ~4.7), and encoding is
// about twice as fast as with the Draco point cloud and symbol coder it replaced.
//
// In every codec the chunk's vertices are the ones its triangles use, numbered in order of first
// use, with a mesh vertex used by triangles of two surfaces duplicated so that every vertex has
// one surface. A chunk therefore decodes to the same topology whichever codec carried it.
//
// Every decoder validates before it allocates or calls Draco: header fields, payload size, the
// checksum, and for Draco the counts and method in Draco's own header (codec 3: the part sizes,
// and symbol counts the header's counts bound). Corrupt, truncated or
// hostile input returns an error and leaves the destination mesh unchanged.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "shared/ordered_mesh.h"
#include "shared/status.h"

namespace isostream {

namespace internal {
struct GatheredChunk;
struct GatherScratch;
}  // namespace internal

// The cube [origin, origin + range] on each axis over which positions are quantized.
struct QuantizationBox {
  float origin[3] = {0.0f, 0.0f, 0.0f};
  float range = 1.0f;
};

// The box Draco picks by itself for these positions: origin at the per-axis minimum, range the
// largest per-axis extent (1 when all positions coincide, as Draco does). vertex_count 0 gives
// the default box.
QuantizationBox BoundingCube(const float* positions, size_t vertex_count);

// Largest per-coordinate difference between a position inside `box` and what codecs 2 and 3
// return for it at `position_bits` (0 means lossless: returns 0).
//
// Derivation: Draco maps a coordinate p to q = floor((p - origin) * M / range + 0.5) with
// M = 2^bits - 1 and decodes q * (range / M) + origin, so rounding to the nearest of the M + 1
// grid values costs at most range / (2M). The float arithmetic (subtract, two multiplies, the
// rounded scale factors, the final add) adds a few ulps of (|origin| + range); 4 * FLT_EPSILON *
// (max |origin| + range) covers them. Without CodecOptions::position_box the box is the chunk's
// BoundingCube; any box containing the chunk's positions with a range at least as large (for
// example the whole mesh's BoundingCube) gives a valid, looser bound.
//
// With position_box set to the volume's bounds, the error is N / (2 (2^bits - 1)) voxels where N
// is the volume's largest extent in voxels: for N = 512, 0.0156 voxels at 14 bits and 0.0039 at
// 16; for N = 2048, 0.0625 and 0.0156.
float PositionErrorBound(const QuantizationBox& box, int position_bits);

// Largest Euclidean distance between a unit normal and its decoded value at `normal_bits`
// (0 means lossless: returns 0).
//
// Derivation: Draco projects the normal onto the octahedron |x| + |y| + |z| = 1 and rounds x
// and y to multiples of 1 / c with c = 2^(bits-1) - 1, an error e <= 1 / (2c) per coordinate;
// z = +-(1 - |x| - |y|) then moves by at most 2e, so the point on the octahedron moves by at
// most sqrt(6) e. Renormalizing scales distances by at most 1 / |v| <= sqrt(3) for v on the
// octahedron, giving sqrt(18) e = 2.12 / c. The bound returned is 2.5 / c to absorb the
// re-balancing Draco does when rounding pushes |x| + |y| past 1. Codec 3's own octahedral
// coder rounds x and y the same way after folding the lower half over the diagonals (a map that
// moves points no further than it moves x and y), and needs no re-balancing.
float NormalErrorBound(int normal_bits);

struct CodecOptions {
  // How EncodeChunk codes the triangles.
  enum class Connectivity : uint8_t {
    kEdgeCache,        // codec 3: isostream's own vertex and connectivity coders
    kDracoSequential,  // codec 2: one Draco sequential mesh (see compress_connectivity)
  };
  Connectivity connectivity = Connectivity::kEdgeCache;
  // Position quantization bits, 1..30; 0 stores float32 positions losslessly.
  int position_bits = 14;
  // Octahedral normal quantization bits, 2..30; 0 stores float32 normals losslessly.
  int normal_bits = 10;
  // With kDracoSequential: entropy-code the index deltas (Draco's "compress_connectivity").
  // Measured on a 1M-triangle sphere (MeshCodecReport in tests/unit/mesh_codec_test.cpp):
  // 2.2 instead of 10.3 bytes/triangle in generation order, 7.7 instead of 12.2 when sorted
  // back to front across its bands; encode and decode times are about the same either way.
  bool compress_connectivity = true;
  // When set, positions are quantized on this fixed grid instead of each chunk's own bounding
  // cube, so a vertex that appears in two chunks of a frame (or in consecutive frames) decodes
  // to the same value in both and chunk seams cannot crack. Every position quantized must lie
  // inside the box (with position_bits 0 nothing is quantized: the box is not used). Use the
  // volume's bounds.
  std::optional<QuantizationBox> position_box;
};

enum class ChunkCodec : uint8_t { kRaw = 1, kDraco = 2, kDracoEdgeCache = 3 };

inline constexpr size_t kChunkHeaderSize = 24;
inline constexpr uint32_t kChunkFormatVersion = 1;
// Upper limit on triangles in one chunk; chunks meant for transport are far smaller.
inline constexpr uint32_t kMaxChunkTriangles = 1u << 26;
// Chunks of a stream: isostreamd cuts frames into chunks of at most this many triangles, and
// clients refuse larger ones before decoding (a small chunk can declare and expand to far more).
inline constexpr uint32_t kMaxStreamChunkTriangles = 65536;
// A Draco chunk's payload has at least one byte per this many triangles: the encoder falls back
// to a codec 2 chunk with uncompressed indices to guarantee it, and decoders use it to reject
// counts that could not fit in the payload before allocating for them.
inline constexpr uint32_t kMaxTrianglesPerDracoByte = 16;

struct ChunkHeader {
  ChunkCodec codec = ChunkCodec::kRaw;
  bool has_normals = false;
  uint32_t triangle_count = 0;
  uint32_t vertex_count = 0;
  uint32_t payload_size = 0;
  uint32_t checksum = 0;
};

// Parses and checks the header at the start of `data`: magic, version, codec, flags, and
// counts that are consistent with each other and with the payload size (for raw the payload
// size must be exact). Does not require the payload to be present, so a reader can learn a
// chunk's size from its first kChunkHeaderSize bytes; does not verify the checksum. Returns
// InvalidArgument for anything malformed, DataLoss if fewer than kChunkHeaderSize bytes.
absl::StatusOr<ChunkHeader> ReadChunkHeader(const char* data, size_t size);

// Encodes triangles [first_triangle, first_triangle + triangle_count) of `mesh` as a Draco
// chunk (codec 3, or 2 with Connectivity::kDracoSequential), replacing the contents of `out`. The
// mesh is checked as far as the range reads it (sizes, indices, surface < kMaxSurfaces, finite
// positions and normals; positions inside options.position_box when set and quantizing) and
// options are range-checked; failures return InvalidArgument/OutOfRange and leave `out`
// unspecified. An empty range gives a valid empty chunk. Costs about 0.1 s per million triangles
// (codec 3), 0.13-0.15 s (codec 2).
absl::Status EncodeChunk(const OrderedMesh& mesh, size_t first_triangle, size_t triangle_count,
                         const CodecOptions& options, std::string* out);

// As EncodeChunk, but stores the gathered arrays as they are: exact, 24-25 bytes per vertex
// plus 13 per triangle, and a memcpy to decode.
absl::Status EncodeChunkRaw(const OrderedMesh& mesh, size_t first_triangle, size_t triangle_count,
                            std::string* out);

// Two-step encoding, for a producer that must copy a range out of a mesh that keeps changing
// (the extractor appends to its mesh while a frame streams) and encode it later on another
// thread. ChunkCopier::Copy does the first half of EncodeChunk: it checks the range as
// EncodeChunk does and copies its triangles with their own vertices (first-use order, split
// per surface); EncodeChunk(copy, ...) does the rest. The result is byte-identical to the
// one-step call. A ChunkCopier keeps a lookup table indexed by mesh vertex across calls, so
// copying consecutive ranges of a large mesh costs O(range) each, with no per-call table.
class ChunkCopy {
 public:
  ChunkCopy();
  ~ChunkCopy();
  ChunkCopy(ChunkCopy&&) noexcept;
  ChunkCopy& operator=(ChunkCopy&&) noexcept;
  size_t triangle_count() const;

 private:
  friend class ChunkCopier;
  friend absl::Status EncodeChunk(const ChunkCopy&, const CodecOptions&, std::string*);
  friend absl::Status EncodeChunkRaw(const ChunkCopy&, std::string*);
  std::unique_ptr<internal::GatheredChunk> chunk_;
};

class ChunkCopier {
 public:
  ChunkCopier();
  ~ChunkCopier();
  // Replaces `out` with triangles [first_triangle, first_triangle + triangle_count) of `mesh`.
  // Errors as EncodeChunk's for the same range; `out` is then unchanged.
  absl::Status Copy(const OrderedMesh& mesh, size_t first_triangle, size_t triangle_count,
                    ChunkCopy* out);

 private:
  std::unique_ptr<internal::GatherScratch> scratch_;
};

// EncodeChunk and EncodeChunkRaw of a copied range. InvalidArgument for a ChunkCopy that holds
// no copy.
absl::Status EncodeChunk(const ChunkCopy& copy, const CodecOptions& options, std::string* out);
absl::Status EncodeChunkRaw(const ChunkCopy& copy, std::string* out);

// Decodes the chunk in data[0, size) (size must be exactly header + payload) and appends its
// vertices and triangles to `append_to`, offsetting the indices by the vertex count it had.
// Normals are appended too (zero when the chunk has none), back-filling zeros first if
// `append_to` had vertices but no normals. On any error `append_to` is left as it was.
// DecodeChunk accepts only Draco chunks (codecs 2 and 3) and DecodeChunkRaw only raw ones;
// DecodeAnyChunk dispatches on the header's codec. Returns InvalidArgument for malformed headers,
// DataLoss for truncated or corrupt payloads, OutOfRange if the result would need more than 2^32 -
// 1 vertices.
absl::Status DecodeChunk(const char* data, size_t size, OrderedMesh* append_to);
absl::Status DecodeChunkRaw(const char* data, size_t size, OrderedMesh* append_to);
absl::Status DecodeAnyChunk(const char* data, size_t size, OrderedMesh* append_to);

}  // namespace isostream
