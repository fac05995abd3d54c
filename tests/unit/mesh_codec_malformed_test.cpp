// Frame codec on malformed and hostile input: truncations, bit flips, absurd counts, re-sealed
// payload edits and chunks spliced from others all return an error (or, for an edit that
// happens to decode, a structurally valid mesh) and leave the destination unchanged.
#include <draco/compression/encode.h>
#include <draco/mesh/mesh.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "codec_test_support.h"
#include "mesh_test_meshes.h"
#include "shared/frame_codec.h"
#include "shared/mesh_validate.h"

namespace isostream {
namespace {

using testing::DracoVariants;
using testing::Encode;
using testing::EncodeRaw;
using testing::MakeGrid;
using testing::MakeSphere;
using testing::Reseal;
using testing::Shuffled;

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

// A raw chunk's positions follow its header; a non-finite one (with a valid checksum) is
// DATA_LOSS, where it used to draw nothing for its triangles without a word.
TEST_F(MalformedChunks, RawChunkWithANonFinitePositionIsRejected) {
  for (const float bad : {std::nanf(""), INFINITY}) {
    std::string raw = chunks_[1];
    std::memcpy(raw.data() + kChunkHeaderSize + 4 * 7, &bad, sizeof(bad));
    Reseal(&raw);
    EXPECT_EQ(TryDecode(raw).code(), absl::StatusCode::kDataLoss) << bad;
  }
  EXPECT_TRUE(TryDecode(chunks_[1]).ok());
}

// A quantization box whose ends are finite but whose top step rounds past FLT_MAX (found by a
// reviewing helper): the chunk encodes, and its decoding is DATA_LOSS, not infinite positions.
TEST(QuantizedPositions, ABoxWhoseTopRoundsToInfinityIsRejected) {
  const float origin = 0x1.46c102p+120f, range = 0x1.fd727cp+127f;
  ASSERT_TRUE(std::isfinite(origin + range));
  OrderedMesh m;
  m.positions = {origin, origin, origin, origin + range, origin, origin, origin, origin + range,
                 origin};
  m.triangles = {0, 1, 2};
  m.surface = {0};
  CodecOptions o;
  o.position_bits = 6;
  o.position_box = QuantizationBox{{origin, origin, origin}, range};
  std::string chunk;
  ASSERT_TRUE(EncodeChunk(m, 0, 1, o, &chunk).ok());
  OrderedMesh out;
  const absl::Status s = DecodeAnyChunk(chunk.data(), chunk.size(), &out);
  EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss) << s;
  EXPECT_NE(s.message().find("not finite"), std::string::npos) << s;
}

// Normals too, in raw chunks and in lossless Draco ones (codec 3 checked both already).
TEST_F(MalformedChunks, NonFiniteNormalsAndDracoValuesAreRejected) {
  std::string raw = chunks_[1];
  uint32_t vertices = 0;
  std::memcpy(&vertices, raw.data() + 12, sizeof(vertices));
  const float bad = std::nanf("");
  std::memcpy(raw.data() + kChunkHeaderSize + 12 * size_t(vertices) + 4, &bad, sizeof(bad));
  Reseal(&raw);
  EXPECT_EQ(TryDecode(raw).code(), absl::StatusCode::kDataLoss);
  // A lossless codec 2 chunk (one triangle) with a NaN position and an infinite normal.
  static const unsigned char kDraco[] = {
      0x49, 0x53, 0x43, 0x31, 0x01, 0x02, 0x01, 0x00, 0x01, 0x00, 0x00, 0x00, 0x03, 0x00, 0x00,
      0x00, 0x88, 0x00, 0x00, 0x00, 0x55, 0x31, 0x89, 0x18, 0x44, 0x52, 0x41, 0x43, 0x4f, 0x02,
      0x02, 0x01, 0x00, 0x00, 0x00, 0x01, 0x03, 0x00, 0x01, 0x02, 0x03, 0x55, 0x15, 0x03, 0xad,
      0x2a, 0x03, 0x04, 0x70, 0x81, 0x01, 0x03, 0x00, 0x09, 0x03, 0x00, 0x00, 0x01, 0x09, 0x03,
      0x00, 0x01, 0x04, 0x02, 0x01, 0x00, 0x02, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00,
      0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0xc0, 0x7f,
      0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00,
      0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x00,
      0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x7f, 0x00, 0x00, 0x00, 0x00, 0x00,
      0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x40,
      0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00};
  const std::string draco(reinterpret_cast<const char*>(kDraco), sizeof(kDraco));
  EXPECT_EQ(TryDecode(draco).code(), absl::StatusCode::kDataLoss);
}

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
    EXPECT_EQ(TryDecode(edited(part + 14, &range, 4)).code(), absl::StatusCode::kDataLoss) << range;
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

}  // namespace
}  // namespace isostream
