// Frame codec: all codecs keep triangle order and surfaces, Draco stays within its documented
// error bounds, chunks append. Malformed and hostile input: mesh_codec_malformed_test.cpp.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "codec_test_support.h"
#include "mesh_test_meshes.h"
#include "shared/frame_codec.h"
#include "shared/mesh_validate.h"

namespace isostream {
namespace {

using testing::Concatenate;
using testing::Decode;
using testing::DracoVariants;
using testing::Encode;
using testing::EncodeRaw;
using testing::ExpectSameTrianglesInOrder;
using testing::MakeGrid;
using testing::MakeSphere;
using testing::Shuffled;
using testing::SortedByDepth;

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

// A frame's arrays grow geometrically as chunks are appended: the Draco decoders reserved the
// index array's exact new size, so every chunk reallocated and copied the whole frame's
// indices (1.62 M page faults and 4.8 s of system time fetching an 8.2 M-triangle frame).
TEST(MeshCodec, AppendingChunksReallocatesLogarithmicallyOften) {
  const OrderedMesh mesh = MakeSphere(2000);
  std::vector<std::string> chunks;
  for (const CodecOptions& options : DracoVariants())
    chunks.push_back(Encode(mesh, 0, mesh.triangle_count(), options));
  chunks.push_back(EncodeRaw(mesh, 0, mesh.triangle_count()));
  for (const std::string& chunk : chunks) {
    OrderedMesh frame;
    int reallocations[4] = {0, 0, 0, 0};
    for (int i = 0; i < 200; ++i) {
      const size_t before[4] = {frame.positions.capacity(), frame.normals.capacity(),
                                frame.triangles.capacity(), frame.surface.capacity()};
      ASSERT_TRUE(DecodeAnyChunk(chunk.data(), chunk.size(), &frame).ok());
      const size_t after[4] = {frame.positions.capacity(), frame.normals.capacity(),
                               frame.triangles.capacity(), frame.surface.capacity()};
      for (int a = 0; a < 4; ++a) reallocations[a] += after[a] != before[a];
    }
    ASSERT_EQ(frame.triangle_count(), 200 * mesh.triangle_count());
    for (int a = 0; a < 4; ++a) EXPECT_LE(reallocations[a], 12) << "array " << a;
  }
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
    // The worst error reaches 0.80-0.83 of the bound at every width: a bound looser by a
    // third would not be tight.
    EXPECT_GT(worst, 0.7f * NormalErrorBound(bits)) << bits << " bits";
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
