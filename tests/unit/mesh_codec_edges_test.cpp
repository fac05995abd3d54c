// The chunk decoders at the edges of what they accept, and the encoder's fallback that keeps its
// chunks within them (each case was a mutation no other test caught).
#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include "shared/frame_codec.h"
#include "shared/internal/ordered_connectivity.h"
#include "shared/internal/symbol_stream.h"

namespace isostream {
namespace {

using internal::kExplicitCorner;
using internal::kNoEdge;

std::string Streams(const std::vector<std::vector<uint32_t>>& arrays) {
  std::string out;
  for (const auto& a : arrays) internal::AppendSymbols(a.data(), a.size(), &out);
  return out;
}

// Bytes after the extra bits (or non-zero padding) must not decode.
TEST(CodecEdges, SymbolStreamRejectsBytesAfterItsExtraBits) {
  const std::vector<uint32_t> symbols = {1, 2, 3, 1, 1, 0, 5};  // direct tokens: no extra bits
  std::string s;
  internal::AppendSymbols(symbols.data(), symbols.size(), &s);
  ASSERT_EQ(s.back(), '\0');  // extra_size 0, last
  std::string longer = s.substr(0, s.size() - 1) + std::string("\x01\x00", 2);
  std::vector<uint32_t> decoded(symbols.size());
  size_t at = 0;
  EXPECT_FALSE(
      internal::ReadSymbols(longer.data(), longer.size(), &at, symbols.size(), decoded.data()));
}

// Connectivity that leaves some of the declared vertices unused is DATA_LOSS.
TEST(CodecEdges, ConnectivityUsingFewerVerticesThanDeclaredIsRejected) {
  const std::string s = Streams({{kNoEdge}, {0, 0, 0}});
  std::vector<uint32_t> triangles;
  EXPECT_TRUE(internal::DecodeOrderedConnectivity(s.data(), s.size(), 1, 3, &triangles).ok());
  EXPECT_EQ(internal::DecodeOrderedConnectivity(s.data(), s.size(), 1, 4, &triangles).code(),
            absl::StatusCode::kDataLoss);
}

// A cache position one past the cache's fill is refused (not read as vertex 0xffffffff).
TEST(CodecEdges, CornerOnePastTheCacheIsRejected) {
  // Two new vertices, then "cache position 0" while the cache is still empty.
  const std::string s = Streams({{kNoEdge}, {0, 0, 1}});
  std::vector<uint32_t> triangles;
  EXPECT_EQ(internal::DecodeOrderedConnectivity(s.data(), s.size(), 1, 2, &triangles).code(),
            absl::StatusCode::kDataLoss);
  // Second triangle: cache holds 3 vertices, position 3 (symbol 4) is past it.
  const std::string t = Streams({{kNoEdge, kNoEdge}, {0, 0, 0, 1, 2, 4}});
  EXPECT_EQ(internal::DecodeOrderedConnectivity(t.data(), t.size(), 2, 3, &triangles).code(),
            absl::StatusCode::kDataLoss);
}

// A chunk that compresses past 16 triangles a byte must still decode (the encoder falls
// back to plain indices rather than emit a chunk ReadChunkHeader refuses).
TEST(CodecEdges, AChunkPastSixteenTrianglesAByteFallsBackAndDecodes) {
  OrderedMesh mesh;
  // One vertex, every triangle degenerate on it: every connectivity symbol after the first
  // triangle is the same, so the rANS streams cost almost nothing.
  mesh.positions = {0.25f, 0.5f, 0.75f};
  mesh.normals = {0, 0, 1};
  const size_t n = 60000;
  for (size_t t = 0; t < n; ++t) {
    mesh.triangles.insert(mesh.triangles.end(), {0, 0, 0});
    mesh.surface.push_back(0);
  }
  std::string bytes;
  ASSERT_TRUE(EncodeChunk(mesh, 0, n, CodecOptions{}, &bytes).ok());
  const auto header = ReadChunkHeader(bytes.data(), bytes.size());
  ASSERT_TRUE(header.ok()) << header.status();   // without the fallback it is refused here
  EXPECT_EQ(header->codec, ChunkCodec::kDraco);  // fell back to plain indices
  OrderedMesh decoded;
  const absl::Status s = DecodeChunk(bytes.data(), bytes.size(), &decoded);
  ASSERT_TRUE(s.ok()) << s;
  EXPECT_EQ(decoded.triangle_count(), n);
}

// A header declaring more than three vertices a triangle is refused.
TEST(CodecEdges, HeaderWithMoreThanThreeVerticesATriangleIsRejected) {
  char h[kChunkHeaderSize] = {'I', 'S', 'C', '1'};
  h[4] = char(kChunkFormatVersion);
  h[5] = char(static_cast<uint8_t>(ChunkCodec::kRaw));
  const uint32_t triangles = 1, vertices = 4, payload = 4 * 12 + 13;
  std::memcpy(h + 8, &triangles, 4);
  std::memcpy(h + 12, &vertices, 4);
  std::memcpy(h + 16, &payload, 4);
  EXPECT_EQ(ReadChunkHeader(h, sizeof(h)).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace isostream
