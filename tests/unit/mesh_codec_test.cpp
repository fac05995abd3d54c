// Frame codec: all codecs keep triangle order and surfaces, Draco stays within its documented
// error bounds, chunks append, and malformed or hostile input returns errors without crashing.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <random>
#include <string>
#include <vector>

#define XXH_INLINE_ALL
#include <draco/compression/encode.h>
#include <draco/mesh/mesh.h>
#include <xxhash.h>

#include "mesh_test_meshes.h"
#include "shared/frame_codec.h"
#include "shared/internal/symbol_stream.h"
#include "shared/mesh_validate.h"

namespace isostream {
namespace {

using testing::Concatenate;
using testing::ExpectSameTrianglesInOrder;
using testing::MakeGrid;
using testing::MakeSphere;
using testing::Shuffled;
using testing::SortedByDepth;

std::string Encode(const OrderedMesh& mesh, size_t first, size_t count,
                   const CodecOptions& options = {}) {
  std::string chunk;
  const absl::Status status = EncodeChunk(mesh, first, count, options, &chunk);
  EXPECT_TRUE(status.ok()) << status;
  return chunk;
}

std::string EncodeRaw(const OrderedMesh& mesh, size_t first, size_t count) {
  std::string chunk;
  const absl::Status status = EncodeChunkRaw(mesh, first, count, &chunk);
  EXPECT_TRUE(status.ok()) << status;
  return chunk;
}

OrderedMesh Decode(const std::string& chunk) {
  OrderedMesh mesh;
  const absl::Status status = DecodeAnyChunk(chunk.data(), chunk.size(), &mesh);
  EXPECT_TRUE(status.ok()) << status;
  return mesh;
}

// The cube Draco quantizes a chunk over: the bounding cube of the vertices the range uses.
QuantizationBox RangeCube(const OrderedMesh& mesh, size_t first, size_t count) {
  std::vector<float> used;
  for (size_t i = 3 * first; i < 3 * (first + count); ++i) {
    const float* p = &mesh.positions[3 * mesh.triangles[i]];
    used.insert(used.end(), p, p + 3);
  }
  return BoundingCube(used.data(), used.size() / 3);
}

float RangeBound(const OrderedMesh& mesh, size_t first, size_t count, int bits) {
  return PositionErrorBound(RangeCube(mesh, first, count), bits);
}

// Re-computes the payload checksum after a test edits the payload, so the edit reaches the
// payload decoder instead of being caught by the checksum.
void Reseal(std::string* chunk) {
  const uint32_t checksum = static_cast<uint32_t>(
      XXH3_64bits(chunk->data() + kChunkHeaderSize, chunk->size() - kChunkHeaderSize));
  std::memcpy(chunk->data() + 20, &checksum, 4);
}

// A 71 x 71 grid (10082 triangles) whose surface index follows the row band, shuffled: the
// surface sequence and the corner positions pin the order, and vertices on band borders are
// shared by two surfaces.
OrderedMesh ShuffledBandedGrid() {
  OrderedMesh grid = MakeGrid(71);
  for (size_t t = 0; t < grid.triangle_count(); ++t) {
    grid.surface[t] = static_cast<uint8_t>((t / (2 * 71 * 5)) % kMaxSurfaces);
  }
  return Shuffled(grid, 1234);
}

// The Draco chunk variants: edge cache (codec 3, the default), Draco mesh with compressed and
// with plain indices (codec 2).
std::vector<CodecOptions> DracoVariants() {
  CodecOptions edge_cache, compressed, plain;
  compressed.connectivity = CodecOptions::Connectivity::kDracoSequential;
  plain.connectivity = CodecOptions::Connectivity::kDracoSequential;
  plain.compress_connectivity = false;
  return {edge_cache, compressed, plain};
}

TEST(MeshCodec, DracoKeepsShuffledTriangleOrder) {
  const OrderedMesh mesh = ShuffledBandedGrid();
  const size_t count = mesh.triangle_count();
  ASSERT_EQ(count, 10082u);
  for (const CodecOptions& options : DracoVariants()) {
    const OrderedMesh decoded = Decode(Encode(mesh, 0, count, options));
    ASSERT_EQ(decoded.triangle_count(), count);
    EXPECT_EQ(decoded.surface, mesh.surface);
    ExpectSameTrianglesInOrder(mesh, 0, count, decoded, 0, RangeBound(mesh, 0, count, 14),
                               NormalErrorBound(10));
  }
}

TEST(MeshCodec, RawIsExactAndHasTheSameTopologyAsDraco) {
  const OrderedMesh mesh = ShuffledBandedGrid();
  const size_t first = 100, count = 5000;
  const OrderedMesh raw = Decode(EncodeRaw(mesh, first, count));
  ExpectSameTrianglesInOrder(mesh, first, count, raw, 0, 0.0f, 0.0f);
  const OrderedMesh draco = Decode(Encode(mesh, first, count));
  EXPECT_EQ(raw.triangles, draco.triangles);
  EXPECT_EQ(raw.surface, draco.surface);
  EXPECT_EQ(raw.vertex_count(), draco.vertex_count());
}

TEST(MeshCodec, EdgeCacheIsTheDefaultAndDecodesLikeTheDracoMesh) {
  // Same vertex order and position quantization, so triangles and positions match bit for bit.
  // Normals are codec 3's own octahedral coding: each within the bound of the original.
  const OrderedMesh sphere = MakeSphere(20000);
  const OrderedMesh meshes[] = {ShuffledBandedGrid(), sphere, SortedByDepth(sphere, 0),
                                Shuffled(sphere, 3)};
  for (const OrderedMesh& mesh : meshes) {
    const size_t count = mesh.triangle_count();
    const std::string edge_cache = Encode(mesh, 0, count);
    const absl::StatusOr<ChunkHeader> header = ReadChunkHeader(edge_cache.data(), kChunkHeaderSize);
    ASSERT_TRUE(header.ok());
    EXPECT_EQ(header->codec, ChunkCodec::kDracoEdgeCache);
    const OrderedMesh decoded = Decode(edge_cache);
    for (const CodecOptions& options : DracoVariants()) {
      const OrderedMesh other = Decode(Encode(mesh, 0, count, options));
      EXPECT_EQ(decoded.triangles, other.triangles);
      EXPECT_EQ(decoded.surface, other.surface);
      EXPECT_EQ(decoded.positions, other.positions);
    }
    ExpectSameTrianglesInOrder(mesh, 0, count, decoded, 0, RangeBound(mesh, 0, count, 14),
                               NormalErrorBound(10));
  }
}

TEST(MeshCodec, EdgeCacheKeepsCornerOrderOfEveryTriangle) {
  // Each triangle of a grid in all three rotations and both windings, shuffled: edges match
  // their neighbours forwards, backwards and not at all, and corner order must survive.
  const OrderedMesh grid = MakeGrid(30);
  OrderedMesh mesh = grid;
  mesh.triangles.clear();
  mesh.surface.clear();
  for (size_t t = 0; t < grid.triangle_count(); ++t) {
    const uint32_t* x = &grid.triangles[3 * t];
    for (int r = 0; r < 3; ++r) {
      mesh.triangles.insert(mesh.triangles.end(), {x[r], x[(r + 1) % 3], x[(r + 2) % 3]});
      mesh.triangles.insert(mesh.triangles.end(), {x[r], x[(r + 2) % 3], x[(r + 1) % 3]});
      mesh.surface.insert(mesh.surface.end(), {uint8_t(t % 3), uint8_t(t % 3)});
    }
  }
  for (const OrderedMesh& m : {mesh, Shuffled(mesh, 17)}) {
    const size_t count = m.triangle_count();
    const OrderedMesh decoded = Decode(Encode(m, 0, count));
    EXPECT_EQ(decoded.surface, m.surface);
    ExpectSameTrianglesInOrder(m, 0, count, decoded, 0, RangeBound(m, 0, count, 14),
                               NormalErrorBound(10));
  }
}

TEST(MeshCodec, CopiedRangesEncodeToTheSameBytes) {
  // One copier over consecutive ranges of a mesh that grows between copies, as the frame
  // producer uses it, then over another mesh: every chunk equals the one-step encoding.
  const OrderedMesh full = ShuffledBandedGrid();
  const OrderedMesh other = Shuffled(MakeSphere(3000), 8);
  ChunkCopier copier;
  const size_t cuts[] = {0, 1, 700, 2000, 2001, 6000, full.triangle_count()};
  OrderedMesh growing;
  for (size_t i = 0; i + 1 < std::size(cuts); ++i) {
    // the first cuts[i + 1] triangles, with every vertex of the full mesh
    growing = full;
    growing.triangles.resize(3 * cuts[i + 1]);
    growing.surface.resize(cuts[i + 1]);
    const size_t count = cuts[i + 1] - cuts[i];
    ChunkCopy copy;
    ASSERT_TRUE(copier.Copy(growing, cuts[i], count, &copy).ok());
    EXPECT_EQ(copy.triangle_count(), count);
    std::string two_step, raw_two_step;
    ASSERT_TRUE(EncodeChunk(copy, {}, &two_step).ok());
    ASSERT_TRUE(EncodeChunkRaw(copy, &raw_two_step).ok());
    EXPECT_EQ(two_step, Encode(full, cuts[i], count)) << i;
    EXPECT_EQ(raw_two_step, EncodeRaw(full, cuts[i], count)) << i;
  }
  ChunkCopy copy;
  ASSERT_TRUE(copier.Copy(other, 10, 2500, &copy).ok());
  std::string two_step;
  ASSERT_TRUE(EncodeChunk(copy, {}, &two_step).ok());
  EXPECT_EQ(two_step, Encode(other, 10, 2500));
  // Errors leave the copy as it was; an empty copy is not encodable.
  EXPECT_EQ(copier.Copy(other, 10, other.triangle_count(), &copy).code(),
            absl::StatusCode::kOutOfRange);
  EXPECT_EQ(copy.triangle_count(), 2500u);
  ChunkCopy empty;
  EXPECT_EQ(EncodeChunk(empty, {}, &two_step).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(EncodeChunkRaw(empty, &two_step).code(), absl::StatusCode::kInvalidArgument);
}

TEST(MeshCodec, VerticesAreNumberedInFirstUseOrder) {
  OrderedMesh mesh;
  for (int v = 0; v < 10; ++v) {
    mesh.positions.insert(mesh.positions.end(), {float(v), float(v * v % 7), 1.0f});
    mesh.normals.insert(mesh.normals.end(), {0.0f, 0.0f, 1.0f});
  }
  mesh.triangles = {7, 3, 5, 3, 5, 9, 0, 7, 9};
  mesh.surface = {2, 2, 2};
  for (const std::string& chunk : {Encode(mesh, 0, 3), EncodeRaw(mesh, 0, 3)}) {
    const OrderedMesh decoded = Decode(chunk);
    EXPECT_EQ(decoded.triangles, (std::vector<uint32_t>{0, 1, 2, 1, 2, 3, 4, 0, 3}));
    EXPECT_EQ(decoded.vertex_count(), 5u);
  }
}

TEST(MeshCodec, VertexUsedByTwoSurfacesIsDuplicated) {
  OrderedMesh mesh;
  mesh.positions = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
  mesh.normals.assign(12, 0.0f);
  for (int v = 0; v < 4; ++v) mesh.normals[3 * v + 2] = 1.0f;
  mesh.triangles = {0, 1, 2, 1, 3, 2};
  mesh.surface = {0, 5};
  for (const std::string& chunk : {Encode(mesh, 0, 2), EncodeRaw(mesh, 0, 2)}) {
    const OrderedMesh decoded = Decode(chunk);
    EXPECT_EQ(decoded.vertex_count(), 6u);
    EXPECT_EQ(decoded.triangles, (std::vector<uint32_t>{0, 1, 2, 3, 4, 5}));
    EXPECT_EQ(decoded.surface, (std::vector<uint8_t>{0, 5}));
    ExpectSameTrianglesInOrder(mesh, 0, 2, decoded, 0, 1e-3f, NormalErrorBound(10));
  }
}

TEST(MeshCodec, ChunksAppendIntoOneMeshInOrder) {
  const float center[3] = {0.5f, -2.0f, 3.0f};
  const OrderedMesh mesh =
      Concatenate(MakeSphere(12000, 1.0f, nullptr, 1), MakeSphere(8000, 0.5f, center, 3));
  const size_t cuts[] = {0, 1, 2500, 2501, 9000, 14000, mesh.triangle_count()};
  OrderedMesh draco, raw;
  for (size_t i = 0; i + 1 < std::size(cuts); ++i) {
    const std::string chunk = Encode(mesh, cuts[i], cuts[i + 1] - cuts[i]);
    const std::string raw_chunk = EncodeRaw(mesh, cuts[i], cuts[i + 1] - cuts[i]);
    ASSERT_TRUE(DecodeChunk(chunk.data(), chunk.size(), &draco).ok());
    ASSERT_TRUE(DecodeChunkRaw(raw_chunk.data(), raw_chunk.size(), &raw).ok());
  }
  const size_t count = mesh.triangle_count();
  ASSERT_EQ(draco.triangle_count(), count);
  ASSERT_TRUE(ValidateMesh(draco).ok());
  // Each chunk's cube lies inside the mesh's, so the mesh-wide bound covers every chunk.
  ExpectSameTrianglesInOrder(mesh, 0, count, draco, 0, RangeBound(mesh, 0, count, 14),
                             NormalErrorBound(10));
  ExpectSameTrianglesInOrder(mesh, 0, count, raw, 0, 0.0f, 0.0f);
}

// Decoded position of every original vertex used by triangles [first, first + count).
std::map<uint32_t, std::vector<float>> DecodedVertexPositions(const OrderedMesh& mesh, size_t first,
                                                              size_t count,
                                                              const OrderedMesh& decoded) {
  std::map<uint32_t, std::vector<float>> out;
  for (size_t i = 0; i < 3 * count; ++i) {
    const float* p = &decoded.positions[3 * decoded.triangles[i]];
    out[mesh.triangles[3 * first + i]] = {p[0], p[1], p[2]};
  }
  return out;
}

TEST(MeshCodec, FixedQuantizationBoxMakesChunkSeamsIdentical) {
  OrderedMesh mesh = MakeGrid(40);
  for (size_t i = 0; i < mesh.positions.size(); ++i) mesh.positions[i] += 10.0f;
  // The volume the grid sits in: [0, 64]^3 in world units.
  QuantizationBox box;
  box.range = 64.0f;
  const size_t half = mesh.triangle_count() / 2;
  for (bool use_box : {false, true}) {
    for (int bits : {14, 16}) {
      CodecOptions options;
      options.position_bits = bits;
      if (use_box) options.position_box = box;
      const OrderedMesh a = Decode(Encode(mesh, 0, half, options));
      const OrderedMesh b = Decode(Encode(mesh, half, mesh.triangle_count() - half, options));
      const auto in_a = DecodedVertexPositions(mesh, 0, half, a);
      const auto in_b = DecodedVertexPositions(mesh, half, mesh.triangle_count() - half, b);
      int shared = 0, different = 0;
      for (const auto& [vertex, position] : in_a) {
        const auto other = in_b.find(vertex);
        if (other == in_b.end()) continue;
        ++shared;
        different += position != other->second;
      }
      EXPECT_GT(shared, 30);
      if (use_box) {
        EXPECT_EQ(different, 0) << bits << " bits";
        // Volume-bounds quantization error in units of this grid's 1-unit spacing.
        const float bound = PositionErrorBound(box, bits);
        EXPECT_LT(bound, bits == 14 ? 0.0021f : 0.00053f);
        ExpectSameTrianglesInOrder(mesh, 0, half, a, 0, bound, NormalErrorBound(10));
      } else {
        // Per-chunk cubes differ, so the seams crack: this is what position_box is for.
        EXPECT_GT(different, 0) << bits << " bits";
      }
    }
  }
}

TEST(MeshCodec, PositionOutsideQuantizationBoxIsRejected) {
  const OrderedMesh mesh = MakeGrid(4);
  CodecOptions options;
  options.position_box = QuantizationBox{{0.0f, 0.0f, 0.0f}, 3.0f};  // grid spans [0, 4]
  std::string chunk;
  const absl::Status status = EncodeChunk(mesh, 0, mesh.triangle_count(), options, &chunk);
  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << status;
  options.position_box->range = 0.0f;
  EXPECT_EQ(EncodeChunk(mesh, 0, 1, options, &chunk).code(), absl::StatusCode::kInvalidArgument);
}

TEST(MeshCodec, PositionErrorBoundHoldsAndIsTight) {
  OrderedMesh mesh = MakeGrid(60);
  // A far origin makes the float-rounding part of the bound matter.
  for (size_t v = 0; v < mesh.vertex_count(); ++v) {
    mesh.positions[3 * v] += 1000.0f;
    mesh.positions[3 * v + 1] -= 500.0f;
  }
  const size_t count = mesh.triangle_count();
  const QuantizationBox cube = RangeCube(mesh, 0, count);
  for (int bits : {4, 8, 11, 14, 16, 20}) {
    CodecOptions options;
    options.position_bits = bits;
    const OrderedMesh decoded = Decode(Encode(mesh, 0, count, options));
    float worst = 0.0f;
    for (size_t i = 0; i < 3 * count; ++i) {
      for (int k = 0; k < 3; ++k) {
        worst = std::max(worst, std::fabs(mesh.positions[3 * mesh.triangles[i] + k] -
                                          decoded.positions[3 * decoded.triangles[i] + k]));
      }
    }
    const float bound = PositionErrorBound(cube, bits);
    EXPECT_LE(worst, bound) << bits << " bits";
    const float half_step = cube.range / (2.0f * (std::ldexp(1.0f, bits) - 1.0f));
    if (bits <= 16) {
      EXPECT_GT(worst, 0.5f * half_step) << bits << " bits";
    }
  }
}

TEST(MeshCodec, NormalErrorBoundHoldsAndIsTight) {
  // One triangle fan whose vertices carry random unit normals.
  std::mt19937 rng(7);
  std::normal_distribution<float> gauss;
  OrderedMesh mesh;
  const int n = 20000;
  for (int v = 0; v < n; ++v) {
    float normal[3] = {gauss(rng), gauss(rng), gauss(rng)};
    const float length =
        std::sqrt(normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]);
    for (float& c : normal) c /= length;
    mesh.positions.insert(mesh.positions.end(), {float(v % 100), float(v / 100), 0.0f});
    mesh.normals.insert(mesh.normals.end(), normal, normal + 3);
  }
  for (uint32_t v = 1; v + 1 < n; ++v) {
    mesh.triangles.insert(mesh.triangles.end(), {0, v, v + 1});
    mesh.surface.push_back(0);
  }
  for (int bits : {4, 6, 8, 10, 12, 16}) {
    CodecOptions options;
    options.normal_bits = bits;
    const OrderedMesh decoded = Decode(Encode(mesh, 0, mesh.triangle_count(), options));
    float worst = 0.0f;
    for (size_t i = 0; i < mesh.triangles.size(); ++i) {
      float sq = 0.0f;
      for (int k = 0; k < 3; ++k) {
        const float d =
            mesh.normals[3 * mesh.triangles[i] + k] - decoded.normals[3 * decoded.triangles[i] + k];
        sq += d * d;
      }
      worst = std::max(worst, std::sqrt(sq));
    }
    EXPECT_LE(worst, NormalErrorBound(bits)) << bits << " bits";
    EXPECT_GT(worst, 0.2f * NormalErrorBound(bits)) << bits << " bits";
  }
}

TEST(MeshCodec, LosslessOptionsAreExact) {
  const OrderedMesh mesh = Shuffled(MakeSphere(3000), 5);
  CodecOptions options;
  options.position_bits = 0;
  options.normal_bits = 0;
  const OrderedMesh decoded = Decode(Encode(mesh, 0, mesh.triangle_count(), options));
  ExpectSameTrianglesInOrder(mesh, 0, mesh.triangle_count(), decoded, 0, 0.0f, 0.0f);
}

TEST(MeshCodec, ZeroNormalsStayZero) {
  OrderedMesh mesh = MakeGrid(10);
  for (size_t v = 0; v < mesh.vertex_count(); v += 3) std::fill_n(&mesh.normals[3 * v], 3, 0.0f);
  const OrderedMesh decoded = Decode(Encode(mesh, 0, mesh.triangle_count()));
  ExpectSameTrianglesInOrder(mesh, 0, mesh.triangle_count(), decoded, 0,
                             RangeBound(mesh, 0, mesh.triangle_count(), 14), NormalErrorBound(10));
  size_t zero = 0;
  for (size_t v = 0; v < decoded.vertex_count(); ++v) {
    zero += decoded.normals[3 * v] == 0 && decoded.normals[3 * v + 1] == 0 &&
            decoded.normals[3 * v + 2] == 0;
  }
  EXPECT_EQ(zero, (mesh.vertex_count() + 2) / 3);
}

TEST(MeshCodec, MeshesWithoutNormalsAppendZeroNormals) {
  OrderedMesh bare = MakeGrid(6);
  bare.normals.clear();
  const OrderedMesh with_normals = MakeGrid(3);
  for (bool raw : {false, true}) {
    const std::string bare_chunk =
        raw ? EncodeRaw(bare, 0, bare.triangle_count()) : Encode(bare, 0, bare.triangle_count());
    const std::string full_chunk = raw ? EncodeRaw(with_normals, 0, with_normals.triangle_count())
                                       : Encode(with_normals, 0, with_normals.triangle_count());
    EXPECT_FALSE(ReadChunkHeader(bare_chunk.data(), bare_chunk.size())->has_normals);
    // bare then full: normals back-filled with zeros, then the real ones
    OrderedMesh out;
    ASSERT_TRUE(DecodeAnyChunk(bare_chunk.data(), bare_chunk.size(), &out).ok());
    ASSERT_TRUE(DecodeAnyChunk(full_chunk.data(), full_chunk.size(), &out).ok());
    ASSERT_TRUE(ValidateMesh(out).ok());
    ExpectSameTrianglesInOrder(bare, 0, bare.triangle_count(), out, 0, 1e-3f, 0.0f);
    ExpectSameTrianglesInOrder(with_normals, 0, with_normals.triangle_count(), out,
                               bare.triangle_count(), 1e-3f, NormalErrorBound(10));
  }
}

TEST(MeshCodec, EmptyRangeGivesEmptyChunk) {
  const OrderedMesh mesh = MakeGrid(3);
  for (const std::string& chunk : {Encode(mesh, 5, 0), EncodeRaw(mesh, 5, 0)}) {
    EXPECT_EQ(chunk.size(), kChunkHeaderSize);
    OrderedMesh out = MakeGrid(1);
    const OrderedMesh before = out;
    ASSERT_TRUE(DecodeAnyChunk(chunk.data(), chunk.size(), &out).ok());
    EXPECT_EQ(out.triangles, before.triangles);
    EXPECT_EQ(out.positions, before.positions);
  }
}

TEST(MeshCodec, DegenerateAndRepeatedTrianglesKeepOrder) {
  OrderedMesh mesh = MakeGrid(2);
  mesh.triangles.clear();
  mesh.surface.clear();
  std::mt19937 rng(3);
  // Mostly one repeated triangle (compresses to a fraction of a byte each), some degenerate.
  for (int t = 0; t < 100000; ++t) {
    if (t % 1000 == 0) {
      const uint32_t v = rng() % 9;
      mesh.triangles.insert(mesh.triangles.end(), {v, v, v});
    } else {
      mesh.triangles.insert(mesh.triangles.end(), {0, 1, 3});
    }
    mesh.surface.push_back(static_cast<uint8_t>(t % 1000 == 0));
  }
  const std::string chunk = Encode(mesh, 0, mesh.triangle_count());
  const absl::StatusOr<ChunkHeader> header = ReadChunkHeader(chunk.data(), chunk.size());
  ASSERT_TRUE(header.ok()) << header.status();
  EXPECT_LE(header->triangle_count, kMaxTrianglesPerDracoByte * uint64_t{header->payload_size});
  const OrderedMesh decoded = Decode(chunk);
  EXPECT_EQ(decoded.surface, mesh.surface);
  ExpectSameTrianglesInOrder(mesh, 0, mesh.triangle_count(), decoded, 0, 1e-3f,
                             NormalErrorBound(10));
}

TEST(MeshCodec, EncoderRejectsInvalidMeshesAndOptions) {
  const OrderedMesh good = MakeGrid(3);
  std::string chunk;
  EXPECT_EQ(EncodeChunk(good, 17, 2, {}, &chunk).code(), absl::StatusCode::kOutOfRange);
  EXPECT_EQ(EncodeChunkRaw(good, 0, 19, &chunk).code(), absl::StatusCode::kOutOfRange);
  OrderedMesh bad = good;
  bad.triangles[7] = 16;
  EXPECT_EQ(EncodeChunk(bad, 0, 3, {}, &chunk).code(), absl::StatusCode::kInvalidArgument);
  // The bad index sits in triangle 2; a range that does not read it is fine.
  EXPECT_TRUE(EncodeChunk(bad, 3, 3, {}, &chunk).ok());
  bad = good;
  bad.surface[4] = kMaxSurfaces;
  EXPECT_EQ(EncodeChunkRaw(bad, 0, 18, &chunk).code(), absl::StatusCode::kInvalidArgument);
  bad = good;
  bad.positions[4] = std::nanf("");
  EXPECT_EQ(EncodeChunk(bad, 0, 18, {}, &chunk).code(), absl::StatusCode::kInvalidArgument);
  bad = good;
  bad.normals.pop_back();
  EXPECT_EQ(EncodeChunk(bad, 0, 18, {}, &chunk).code(), absl::StatusCode::kInvalidArgument);
  bad = good;
  bad.surface.pop_back();
  EXPECT_EQ(EncodeChunk(bad, 0, 1, {}, &chunk).code(), absl::StatusCode::kInvalidArgument);
  for (auto [position_bits, normal_bits] : {std::pair{-1, 10}, {31, 10}, {14, 1}, {14, 31}}) {
    CodecOptions options;
    options.position_bits = position_bits;
    options.normal_bits = normal_bits;
    EXPECT_EQ(EncodeChunk(good, 0, 18, options, &chunk).code(), absl::StatusCode::kInvalidArgument)
        << position_bits << " " << normal_bits;
  }
}

// ---------------------------------------------------------------------------------------------
// Malformed input: every case must return an error (or, for re-sealed payload edits that
// happen to decode, a structurally valid mesh) and leave the destination unchanged on error.

class MalformedChunks : public ::testing::Test {
 protected:
  void SetUp() override {
    mesh_ = Shuffled(MakeSphere(2000), 11);
    // edge cache, raw, Draco mesh with compressed and with plain indices
    chunks_ = {Encode(mesh_, 0, mesh_.triangle_count()),
               EncodeRaw(mesh_, 0, mesh_.triangle_count())};
    for (const CodecOptions& options : DracoVariants()) {
      if (options.connectivity == CodecOptions::Connectivity::kDracoSequential) {
        chunks_.push_back(Encode(mesh_, 0, mesh_.triangle_count(), options));
      }
    }
    destination_ = MakeGrid(2);
  }

  // Decodes `bytes` onto a copy of destination_; returns the status and checks the copy is
  // unchanged on failure and valid on success.
  absl::Status TryDecode(const std::string& bytes) {
    OrderedMesh out = destination_;
    const absl::Status status = DecodeAnyChunk(bytes.data(), bytes.size(), &out);
    if (status.ok()) {
      EXPECT_TRUE(ValidateMesh(out).ok());
    } else {
      EXPECT_EQ(out.positions, destination_.positions);
      EXPECT_EQ(out.normals, destination_.normals);
      EXPECT_EQ(out.triangles, destination_.triangles);
      EXPECT_EQ(out.surface, destination_.surface);
    }
    return status;
  }

  OrderedMesh mesh_;
  std::vector<std::string> chunks_;
  OrderedMesh destination_;
};

TEST_F(MalformedChunks, EmptyAndNullBuffers) {
  OrderedMesh out;
  EXPECT_FALSE(DecodeAnyChunk(nullptr, 0, &out).ok());
  EXPECT_FALSE(DecodeChunk("", 0, &out).ok());
  EXPECT_FALSE(DecodeChunkRaw("", 0, &out).ok());
  EXPECT_FALSE(DecodeAnyChunk(chunks_[0].data(), chunks_[0].size(), nullptr).ok());
}

TEST_F(MalformedChunks, TruncatedAtEverySeventhByte) {
  for (const std::string& chunk : chunks_) {
    for (size_t length = 0; length < chunk.size(); length += 7) {
      EXPECT_FALSE(TryDecode(chunk.substr(0, length)).ok()) << "length " << length;
    }
    EXPECT_FALSE(TryDecode(chunk + '\0').ok());
  }
}

TEST_F(MalformedChunks, EveryHeaderBitFlipIsRejected) {
  for (const std::string& chunk : chunks_) {
    for (size_t bit = 0; bit < 8 * kChunkHeaderSize; ++bit) {
      std::string flipped = chunk;
      flipped[bit / 8] = static_cast<char>(flipped[bit / 8] ^ (1 << (bit % 8)));
      EXPECT_FALSE(TryDecode(flipped).ok()) << "bit " << bit;
    }
  }
}

TEST_F(MalformedChunks, AbsurdCountsAreRejectedBeforeAllocating) {
  for (const std::string& chunk : chunks_) {
    for (uint32_t triangles : {0u, 1u, 1000000u, kMaxChunkTriangles, 0xffffffffu}) {
      for (uint32_t vertices : {0u, 1u, 0x10000000u, 0xffffffffu}) {
        std::string edited = chunk;
        std::memcpy(edited.data() + 8, &triangles, 4);
        std::memcpy(edited.data() + 12, &vertices, 4);
        EXPECT_FALSE(TryDecode(edited).ok()) << triangles << " " << vertices;
      }
    }
    std::string edited = chunk;
    const uint32_t payload = 0xfffffff0u;
    std::memcpy(edited.data() + 16, &payload, 4);
    EXPECT_FALSE(TryDecode(edited).ok());
  }
}

TEST_F(MalformedChunks, WrongDecoderForCodec) {
  OrderedMesh out;
  EXPECT_EQ(DecodeChunkRaw(chunks_[0].data(), chunks_[0].size(), &out).code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(DecodeChunk(chunks_[1].data(), chunks_[1].size(), &out).code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(out.empty());
}

TEST_F(MalformedChunks, CorruptPayloadIsCaughtByChecksum) {
  std::mt19937 rng(21);
  for (const std::string& chunk : chunks_) {
    for (int trial = 0; trial < 200; ++trial) {
      std::string edited = chunk;
      const size_t at = kChunkHeaderSize + rng() % (chunk.size() - kChunkHeaderSize);
      edited[at] = static_cast<char>(edited[at] ^ (1 + rng() % 255));
      EXPECT_EQ(TryDecode(edited).code(), absl::StatusCode::kDataLoss);
    }
  }
}

TEST_F(MalformedChunks, HostilePayloadsWithValidChecksumNeverCrash) {
  // What a sender that computes checksums over garbage would produce: reaches Draco itself.
  std::mt19937 rng(22);
  int accepted = 0;
  for (const std::string& chunk : chunks_) {
    for (int trial = 0; trial < 300; ++trial) {
      std::string edited = chunk;
      const int flips = 1 + static_cast<int>(rng() % 8);
      for (int f = 0; f < flips; ++f) {
        const size_t at = kChunkHeaderSize + rng() % (chunk.size() - kChunkHeaderSize);
        edited[at] = static_cast<char>(rng());
      }
      Reseal(&edited);
      accepted += TryDecode(edited).ok();
    }
  }
  // Most edits to attribute bytes still decode (to wrong values); that is fine, crashing is not.
  std::printf("hostile payloads accepted: %d of %zu\n", accepted, 300 * chunks_.size());
}

TEST_F(MalformedChunks, RandomGarbageIsRejected) {
  std::mt19937 rng(23);
  for (int trial = 0; trial < 2000; ++trial) {
    std::string garbage(rng() % 200, '\0');
    for (char& c : garbage) c = static_cast<char>(rng());
    if (trial % 2 == 0 && garbage.size() >= kChunkHeaderSize) {
      // Valid magic, version and codec, random everything else.
      std::memcpy(garbage.data(), chunks_[(trial / 2) % chunks_.size()].data(), 6);
    }
    EXPECT_FALSE(TryDecode(garbage).ok());
  }
}

TEST_F(MalformedChunks, DracoPayloadThatLosesOrderIsRejected) {
  // A well-formed edgebreaker payload with a correct header: rejected because edgebreaker does
  // not keep triangle order.
  draco::Mesh mesh;
  mesh.set_num_points(static_cast<uint32_t>(mesh_.vertex_count()));
  auto position = std::make_unique<draco::PointAttribute>();
  position->Init(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32, false,
                 mesh_.vertex_count());
  position->buffer()->Write(0, mesh_.positions.data(), 4 * mesh_.positions.size());
  mesh.AddAttribute(std::move(position));
  for (size_t t = 0; t < mesh_.triangle_count(); ++t) {
    mesh.AddFace({draco::PointIndex(mesh_.triangles[3 * t]),
                  draco::PointIndex(mesh_.triangles[3 * t + 1]),
                  draco::PointIndex(mesh_.triangles[3 * t + 2])});
  }
  draco::Encoder encoder;
  encoder.SetEncodingMethod(draco::MESH_EDGEBREAKER_ENCODING);
  draco::EncoderBuffer buffer;
  ASSERT_TRUE(encoder.EncodeMeshToBuffer(mesh, &buffer).ok());
  std::string chunk = chunks_[2].substr(0, kChunkHeaderSize);  // a Draco mesh chunk's header
  chunk.append(buffer.data(), buffer.size());
  const uint32_t payload = static_cast<uint32_t>(buffer.size());
  const uint32_t vertices = static_cast<uint32_t>(mesh_.vertex_count());
  const uint16_t no_normals = 0;
  std::memcpy(chunk.data() + 6, &no_normals, 2);
  std::memcpy(chunk.data() + 12, &vertices, 4);
  std::memcpy(chunk.data() + 16, &payload, 4);
  Reseal(&chunk);
  const absl::Status status = TryDecode(chunk);
  EXPECT_EQ(status.code(), absl::StatusCode::kDataLoss) << status;
  EXPECT_NE(status.message().find("order"), absl::string_view::npos) << status;
}

TEST_F(MalformedChunks, EdgeCacheVertexPartSizeFieldIsChecked) {
  const std::string& chunk = chunks_[0];
  ASSERT_EQ(ReadChunkHeader(chunk.data(), chunk.size())->codec, ChunkCodec::kDracoEdgeCache);
  uint32_t points_size;
  std::memcpy(&points_size, chunk.data() + kChunkHeaderSize, 4);
  const uint32_t payload_size = static_cast<uint32_t>(chunk.size() - kChunkHeaderSize);
  for (uint32_t edited_size : {0u, 1u, 11u, 15u, points_size - 1, points_size + 1, payload_size - 4,
                               payload_size - 3, 0xffffffffu}) {
    std::string edited = chunk;
    std::memcpy(edited.data() + kChunkHeaderSize, &edited_size, 4);
    Reseal(&edited);
    EXPECT_EQ(TryDecode(edited).code(), absl::StatusCode::kDataLoss) << edited_size;
  }
}

TEST_F(MalformedChunks, EdgeCacheVertexPartFieldsAreChecked) {
  // The vertex part starts with position bits, normal bits, the box origin and range.
  const std::string& chunk = chunks_[0];
  ASSERT_EQ(ReadChunkHeader(chunk.data(), chunk.size())->codec, ChunkCodec::kDracoEdgeCache);
  const size_t part = kChunkHeaderSize + 4;
  auto edited = [&](size_t at, const void* value, size_t bytes) {
    std::string e = chunk;
    std::memcpy(e.data() + at, value, bytes);
    Reseal(&e);
    return e;
  };
  // Widths outside the format's range. (Another valid width may decode, to wrong values, as
  // any edit of attribute bytes can.)
  for (uint8_t bits : {31, 32, 255}) {
    EXPECT_EQ(TryDecode(edited(part, &bits, 1)).code(), absl::StatusCode::kDataLoss) << int{bits};
  }
  for (uint8_t bits : {1, 31, 255}) {
    EXPECT_EQ(TryDecode(edited(part + 1, &bits, 1)).code(), absl::StatusCode::kDataLoss)
        << int{bits};
  }
  const float bad_ranges[] = {0.0f, -1.0f, INFINITY, NAN};
  for (float range : bad_ranges) {
    EXPECT_EQ(TryDecode(edited(part + 14, &range, 4)).code(), absl::StatusCode::kDataLoss)
        << range;
  }
  const float bad_origin = INFINITY;
  EXPECT_EQ(TryDecode(edited(part + 2, &bad_origin, 4)).code(), absl::StatusCode::kDataLoss);
  // Then the number of tag runs: at least one, at most one per vertex, and exactly the number
  // of run symbols that follow.
  uint32_t runs;
  std::memcpy(&runs, chunk.data() + part + 18, 4);
  const uint32_t vertices = static_cast<uint32_t>(mesh_.vertex_count());
  for (uint32_t bad_runs : {0u, runs - 1, runs + 1, vertices + 1, 0xffffffffu}) {
    if (bad_runs == runs) continue;
    EXPECT_EQ(TryDecode(edited(part + 18, &bad_runs, 4)).code(), absl::StatusCode::kDataLoss)
        << bad_runs;
  }
  // A chunk without normals must not carry normal bits or undefined-normal tags.
  OrderedMesh bare = mesh_;
  bare.normals.clear();
  const std::string no_normals = Encode(bare, 0, bare.triangle_count());
  std::string e = no_normals;
  e[part + 1] = 10;
  Reseal(&e);
  OrderedMesh out;
  EXPECT_EQ(DecodeAnyChunk(e.data(), e.size(), &out).code(), absl::StatusCode::kDataLoss);
  EXPECT_TRUE(out.empty());
}

TEST(SymbolStream, RoundTripsAndRejectsEveryTruncationAndExtension) {
  std::mt19937 rng(31);
  std::geometric_distribution<uint32_t> small(0.3);
  std::uniform_int_distribution<uint32_t> any;
  for (int trial = 0; trial < 40; ++trial) {
    const size_t count = 1 + rng() % 3000;
    std::vector<uint32_t> symbols(count);
    for (uint32_t& v : symbols) {
      switch (trial % 4) {
        case 0: v = small(rng); break;                    // skewed, direct tokens
        case 1: v = any(rng) >> (rng() % 32); break;      // every bit width
        case 2: v = 7; break;                             // a single token
        default: v = rng() % 2 ? small(rng) : any(rng);  // mixed
      }
    }
    std::string stream = "prefix";
    internal::AppendSymbols(symbols.data(), count, &stream);
    std::vector<uint32_t> decoded(count);
    size_t at = 6;
    ASSERT_TRUE(internal::ReadSymbols(stream.data(), stream.size(), &at, count, decoded.data()));
    EXPECT_EQ(at, stream.size());
    EXPECT_EQ(decoded, symbols);
    // Fewer bytes never decode, nor do more symbols than were written.
    for (size_t size = 6; size < stream.size(); size += 1 + size / 16) {
      at = 6;
      EXPECT_FALSE(internal::ReadSymbols(stream.data(), size, &at, count, decoded.data()));
    }
    // (A one-token array carries no information per symbol: any count decodes from it.)
    at = 6;
    std::vector<uint32_t> more(count + 1);
    if (trial % 4 != 2) {
      EXPECT_FALSE(
          internal::ReadSymbols(stream.data(), stream.size(), &at, count + 1, more.data()));
    }
    // Edited bytes must never read out of bounds (checked under sanitizers), and mostly fail.
    for (int edit = 0; edit < 50; ++edit) {
      std::string e = stream;
      e[6 + rng() % (e.size() - 6)] = static_cast<char>(rng());
      at = 6;
      internal::ReadSymbols(e.data(), e.size(), &at, count, decoded.data());
    }
  }
}

TEST_F(MalformedChunks, EdgeCacheConnectivityFromAnotherChunkIsRejected) {
  // Chunk A's vertex part with chunk B's connectivity, B using more vertices, then fewer.
  const OrderedMesh small = Shuffled(MakeSphere(1000), 12);
  const std::string chunks[2] = {Encode(small, 0, small.triangle_count()), chunks_[0]};
  for (int a = 0; a < 2; ++a) {
    const std::string& points_from = chunks[a];
    const std::string& connectivity_from = chunks[1 - a];
    uint32_t points_size, other_points_size;
    std::memcpy(&points_size, points_from.data() + kChunkHeaderSize, 4);
    std::memcpy(&other_points_size, connectivity_from.data() + kChunkHeaderSize, 4);
    std::string edited = points_from.substr(0, kChunkHeaderSize + 4 + points_size);
    edited.append(connectivity_from.substr(kChunkHeaderSize + 4 + other_points_size));
    const uint32_t payload = static_cast<uint32_t>(edited.size() - kChunkHeaderSize);
    std::memcpy(edited.data() + 16, &payload, 4);
    for (const std::string* counts_from : {&points_from, &connectivity_from}) {
      std::memcpy(edited.data() + 8, counts_from->data() + 8, 8);  // triangles and vertices
      Reseal(&edited);
      EXPECT_EQ(TryDecode(edited).code(), absl::StatusCode::kDataLoss) << a;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Size and speed report: bytes per triangle on a smooth closed surface, in the order it was
// generated (latitude bands around z) and sorted back to front along x, across the bands, like
// a frame viewed from the side.
// ISOSTREAM_CODEC_REPORT_TRIANGLES sets the mesh size (default 100k).

struct Measured {
  double bytes_per_triangle;
  double encode_ms_per_million;
  double decode_ms_per_million;
};

template <typename EncodeFn>
Measured Measure(const OrderedMesh& mesh, EncodeFn encode) {
  using Clock = std::chrono::steady_clock;
  std::string chunk;
  double encode_s = 1e9, decode_s = 1e9;
  for (int repeat = 0; repeat < 3; ++repeat) {
    const auto t0 = Clock::now();
    EXPECT_TRUE(encode(&chunk).ok());
    const auto t1 = Clock::now();
    OrderedMesh decoded;
    EXPECT_TRUE(DecodeAnyChunk(chunk.data(), chunk.size(), &decoded).ok());
    const auto t2 = Clock::now();
    EXPECT_EQ(decoded.surface, mesh.surface);
    encode_s = std::min(encode_s, std::chrono::duration<double>(t1 - t0).count());
    decode_s = std::min(decode_s, std::chrono::duration<double>(t2 - t1).count());
  }
  const double millions = mesh.triangle_count() / 1e6;
  return {double(chunk.size()) / mesh.triangle_count(), 1e3 * encode_s / millions,
          1e3 * decode_s / millions};
}

TEST(MeshCodecReport, BytesPerTriangleOnSphere) {
  size_t target = 100000;
  if (const char* env = std::getenv("ISOSTREAM_CODEC_REPORT_TRIANGLES")) {
    target = std::strtoull(env, nullptr, 10);
  }
  const OrderedMesh banded = MakeSphere(target);
  const OrderedMesh depth = SortedByDepth(banded, 0);
  for (const auto& [name, mesh] : {std::pair{"band order", &banded}, {"depth order", &depth}}) {
    const size_t count = mesh->triangle_count();
    CodecOptions sequential;
    sequential.connectivity = CodecOptions::Connectivity::kDracoSequential;
    sequential.compress_connectivity = false;
    CodecOptions compressed;
    compressed.connectivity = CodecOptions::Connectivity::kDracoSequential;
    const CodecOptions edge_cache;
    const Measured raw =
        Measure(*mesh, [&](std::string* out) { return EncodeChunkRaw(*mesh, 0, count, out); });
    const Measured plain = Measure(
        *mesh, [&](std::string* out) { return EncodeChunk(*mesh, 0, count, sequential, out); });
    const Measured packed = Measure(
        *mesh, [&](std::string* out) { return EncodeChunk(*mesh, 0, count, compressed, out); });
    const Measured cached = Measure(
        *mesh, [&](std::string* out) { return EncodeChunk(*mesh, 0, count, edge_cache, out); });
    std::printf("sphere %zu triangles, %zu vertices, %s, 14-bit positions, 10-bit normals:\n",
                count, mesh->vertex_count(), name);
    for (const auto& [row, m] : {std::pair{"raw", &raw},
                                 {"draco sequential", &plain},
                                 {"draco sequential + compressed conn.", &packed},
                                 {"edge cache (default)", &cached}}) {
      std::printf("  %-36s %6.2f B/tri  encode %6.1f ms/M  decode %6.1f ms/M\n", row,
                  m->bytes_per_triangle, m->encode_ms_per_million, m->decode_ms_per_million);
    }
    // The reasons for the default, and for compress_connectivity defaulting to true.
    EXPECT_LT(cached.bytes_per_triangle, packed.bytes_per_triangle);
    EXPECT_LT(packed.bytes_per_triangle, plain.bytes_per_triangle);
    EXPECT_LT(plain.bytes_per_triangle, raw.bytes_per_triangle);
  }
}

}  // namespace
}  // namespace isostream
