// The chunk decoders at the edges of what they accept, and the encoder's fallback that keeps its
// chunks within them (each case was a mutation no other test caught).
#include <gtest/gtest.h>

#include <array>
#include <cstring>
#include <string>
#include <vector>

#include "codec_test_support.h"
#include "shared/frame_codec.h"
#include "shared/internal/ordered_connectivity.h"
#include "shared/internal/symbol_stream.h"
#include "shared/internal/varint.h"

namespace isostream {
namespace {

using internal::kExplicitCorner;
using internal::kNoEdge;
using testing::EncodeRaw;
using testing::Reseal;

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

// A chunk header with these fields (checksum 0: ReadChunkHeader does not verify it).
std::string Header(ChunkCodec codec, uint16_t flags, uint32_t triangles, uint32_t vertices,
                   uint32_t payload) {
  std::string h(kChunkHeaderSize, '\0');
  std::memcpy(h.data(), "ISC1", 4);
  h[4] = char(kChunkFormatVersion);
  h[5] = char(static_cast<uint8_t>(codec));
  std::memcpy(h.data() + 6, &flags, 2);
  std::memcpy(h.data() + 8, &triangles, 4);
  std::memcpy(h.data() + 12, &vertices, 4);
  std::memcpy(h.data() + 16, &payload, 4);
  return h;
}

// One triangle on three distinct vertices (normals +z), surface 0.
OrderedMesh OneTriangle() {
  OrderedMesh m;
  m.positions = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  m.normals = {0, 0, 1, 0, 0, 1, 0, 0, 1};
  m.triangles = {0, 1, 2};
  m.surface = {0};
  return m;
}

// A non-empty chunk has at least one vertex.
TEST(CodecEdges, HeaderWithTrianglesAndNoVerticesIsRejected) {
  for (ChunkCodec codec : {ChunkCodec::kRaw, ChunkCodec::kDraco, ChunkCodec::kDracoEdgeCache}) {
    const std::string h = Header(codec, 0, 1, 0, 13);
    EXPECT_EQ(ReadChunkHeader(h.data(), h.size()).status().code(),
              absl::StatusCode::kInvalidArgument)
        << int(codec);
  }
}

// An empty chunk carries nothing: neither a payload nor the normals flag.
TEST(CodecEdges, EmptyChunkWithTheNormalsFlagIsRejected) {
  const std::string plain = Header(ChunkCodec::kRaw, 0, 0, 0, 0);
  EXPECT_TRUE(ReadChunkHeader(plain.data(), plain.size()).ok());
  const std::string flagged = Header(ChunkCodec::kRaw, 1, 0, 0, 0);
  EXPECT_EQ(ReadChunkHeader(flagged.data(), flagged.size()).status().code(),
            absl::StatusCode::kInvalidArgument);
}

// A Draco chunk may declare up to 16 triangles per payload byte, not one more.
TEST(CodecEdges, DracoHeaderAllowsSixteenTrianglesAByteAndNoMore) {
  for (ChunkCodec codec : {ChunkCodec::kDraco, ChunkCodec::kDracoEdgeCache}) {
    const std::string at_limit = Header(codec, 0, 32, 3, 2);
    EXPECT_TRUE(ReadChunkHeader(at_limit.data(), at_limit.size()).ok()) << int(codec);
    const std::string past = Header(codec, 0, 33, 3, 2);
    EXPECT_EQ(ReadChunkHeader(past.data(), past.size()).status().code(),
              absl::StatusCode::kInvalidArgument)
        << int(codec);
  }
}

// An edge-cache payload starts with its vertex part's 4-byte size: a 3-byte payload is refused
// before that field is read (past the payload's end, and 16 MB further for the connectivity).
TEST(CodecEdges, EdgeCachePayloadShorterThanItsSizeFieldIsRejected) {
  std::string chunk = Header(ChunkCodec::kDracoEdgeCache, 0, 1, 1, 3) + std::string(3, '\xff');
  Reseal(&chunk);
  OrderedMesh out;
  EXPECT_EQ(DecodeAnyChunk(chunk.data(), chunk.size(), &out).code(), absl::StatusCode::kDataLoss);
}

// A raw chunk's index equal to its vertex count (one past the last vertex) is DATA_LOSS.
TEST(CodecEdges, RawChunkIndexAtTheVertexCountIsRejected) {
  std::string raw = EncodeRaw(OneTriangle(), 0, 1);
  const size_t index_at = kChunkHeaderSize + 2 * 12 * 3 + 4 * 2;  // after positions and normals
  const uint32_t last = 2, past = 3;
  std::memcpy(raw.data() + index_at, &last, 4);
  Reseal(&raw);
  OrderedMesh out;
  EXPECT_TRUE(DecodeAnyChunk(raw.data(), raw.size(), &out).ok());
  std::memcpy(raw.data() + index_at, &past, 4);
  Reseal(&raw);
  out = OrderedMesh();
  EXPECT_EQ(DecodeAnyChunk(raw.data(), raw.size(), &out).code(), absl::StatusCode::kDataLoss);
  EXPECT_TRUE(out.empty());
}

// A raw chunk's surface must be below kMaxSurfaces: 15 decodes, 16 is DATA_LOSS.
TEST(CodecEdges, RawChunkSurfaceAtTheLimitIsRejected) {
  std::string raw = EncodeRaw(OneTriangle(), 0, 1);
  ASSERT_EQ(raw.size(), kChunkHeaderSize + 2 * 12 * 3 + 12 + 1);
  raw.back() = char(kMaxSurfaces - 1);
  Reseal(&raw);
  OrderedMesh out;
  EXPECT_TRUE(DecodeAnyChunk(raw.data(), raw.size(), &out).ok());
  raw.back() = char(kMaxSurfaces);
  Reseal(&raw);
  out = OrderedMesh();
  EXPECT_EQ(DecodeAnyChunk(raw.data(), raw.size(), &out).code(), absl::StatusCode::kDataLoss);
  EXPECT_TRUE(out.empty());
}

// A chunk whose vertices all coincide quantizes over a cube of range 1 (as Draco does), not 0,
// which no decoder accepts.
TEST(CodecEdges, AChunkOnOnePointRoundTripsQuantized) {
  OrderedMesh m;
  m.positions = {0.25f, 0.5f, 0.75f};
  m.normals = {0, 0, 1};
  m.triangles = {0, 0, 0};
  m.surface = {0};
  const QuantizationBox cube = BoundingCube(m.positions.data(), 1);
  EXPECT_EQ(cube.range, 1.0f);
  std::string chunk;
  ASSERT_TRUE(EncodeChunk(m, 0, 1, CodecOptions{}, &chunk).ok());
  OrderedMesh out;
  const absl::Status s = DecodeAnyChunk(chunk.data(), chunk.size(), &out);
  ASSERT_TRUE(s.ok()) << s;
  ASSERT_EQ(out.vertex_count(), 1u);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(out.positions[k], m.positions[k], 1e-3f) << k;
}

// An explicit corner may point back at most to vertex 0 (back = next - 1), not one past it.
TEST(CodecEdges, ExplicitCornerBeforeTheFirstVertexIsRejected) {
  std::vector<uint32_t> triangles;
  const std::string first = Streams({{kNoEdge}, {0, 0, kExplicitCorner}, {1}});
  ASSERT_TRUE(
      internal::DecodeOrderedConnectivity(first.data(), first.size(), 1, 2, &triangles).ok());
  EXPECT_EQ(triangles, (std::vector<uint32_t>{0, 1, 0}));
  const std::string before_it = Streams({{kNoEdge}, {0, 0, kExplicitCorner}, {2}});
  EXPECT_EQ(
      internal::DecodeOrderedConnectivity(before_it.data(), before_it.size(), 1, 2, &triangles)
          .code(),
      absl::StatusCode::kDataLoss);
}

// After one triangle the edge FIFO holds three edges: k = 2 names the oldest, k = 3 none.
TEST(CodecEdges, EdgeOnePastTheFifoFillIsRejected) {
  std::vector<uint32_t> triangles;
  const std::string oldest = Streams({{kNoEdge, 3 * 2}, {0, 0, 0, 0}});
  ASSERT_TRUE(
      internal::DecodeOrderedConnectivity(oldest.data(), oldest.size(), 2, 4, &triangles).ok());
  const std::string past = Streams({{kNoEdge, 3 * 3}, {0, 0, 0, 0}});
  EXPECT_EQ(internal::DecodeOrderedConnectivity(past.data(), past.size(), 2, 4, &triangles).code(),
            absl::StatusCode::kDataLoss);
}

// Connectivity is exactly its three symbol arrays: a byte after them is DATA_LOSS.
TEST(CodecEdges, ConnectivityWithATrailingByteIsRejected) {
  const std::string s = Streams({{kNoEdge}, {0, 0, 0}}) + std::string(1, '\0');
  std::vector<uint32_t> triangles;
  EXPECT_EQ(internal::DecodeOrderedConnectivity(s.data(), s.size(), 1, 3, &triangles).code(),
            absl::StatusCode::kDataLoss);
}

// The encoder refuses a vertex count its triangles do not use up (the decoder would refuse the
// stream).
TEST(CodecEdges, ConnectivityEncoderRefusesUnusedVertices) {
  const uint32_t triangle[3] = {0, 1, 2};
  std::string out;
  EXPECT_TRUE(internal::EncodeOrderedConnectivity(triangle, 1, 3, &out).ok());
  out.clear();
  EXPECT_EQ(internal::EncodeOrderedConnectivity(triangle, 1, 4, &out).code(),
            absl::StatusCode::kInvalidArgument);
}

// Offset of the first rANS state in a symbol stream (after the alphabet, the frequencies and
// the rANS part's size).
size_t StatesOffset(const std::string& s) {
  const auto* bytes = reinterpret_cast<const uint8_t*>(s.data());
  size_t at = 0;
  uint32_t alphabet = 0, value = 0;
  EXPECT_TRUE(internal::GetVarint32(bytes, s.size(), &at, &alphabet));
  for (uint32_t t = 0; t <= alphabet; ++t) {  // the frequencies, then the rANS size
    EXPECT_TRUE(internal::GetVarint32(bytes, s.size(), &at, &value));
  }
  return at;
}

// Each rANS state must end where the encoder started it: a state off by one is corruption
// (with one token the states never change, so nothing else notices).
TEST(CodecEdges, SymbolStreamWithAStateThatDoesNotReturnIsRejected) {
  const std::vector<uint32_t> symbols(100, 7);
  std::string s;
  internal::AppendSymbols(symbols.data(), symbols.size(), &s);
  std::vector<uint32_t> decoded(symbols.size());
  size_t at = 0;
  ASSERT_TRUE(internal::ReadSymbols(s.data(), s.size(), &at, symbols.size(), decoded.data()));
  const size_t state = StatesOffset(s);
  uint32_t x0;
  std::memcpy(&x0, s.data() + state, 4);
  ++x0;
  std::memcpy(s.data() + state, &x0, 4);
  at = 0;
  EXPECT_FALSE(internal::ReadSymbols(s.data(), s.size(), &at, symbols.size(), decoded.data()));
}

// The extra bits' last byte is zero-padded: a padding bit set is not a stream the encoder writes.
TEST(CodecEdges, SymbolStreamWithNonZeroPaddingIsRejected) {
  const std::vector<uint32_t> symbols = {200};  // token of width 8: 5 extra bits, 3 padding
  std::string s;
  internal::AppendSymbols(symbols.data(), symbols.size(), &s);
  std::vector<uint32_t> decoded(1);
  size_t at = 0;
  ASSERT_TRUE(internal::ReadSymbols(s.data(), s.size(), &at, 1, decoded.data()));
  ASSERT_EQ(decoded[0], 200u);
  s.back() = static_cast<char>(s.back() | 0x80);  // the extra bits are the last byte
  at = 0;
  EXPECT_FALSE(internal::ReadSymbols(s.data(), s.size(), &at, 1, decoded.data()));
}

// A hand-made symbol stream: the alphabet's frequencies (one per token), a rANS part of four
// states, no extra bits. Whether reading one symbol from it succeeds.
bool ReadsAHandMadeStream(const std::vector<uint32_t>& frequencies,
                          const std::array<uint32_t, 4>& states) {
  std::string s;
  internal::PutVarint32(uint32_t(frequencies.size()), &s);
  for (const uint32_t f : frequencies) internal::PutVarint32(f, &s);
  internal::PutVarint32(16, &s);  // the rANS part's bytes
  s.append(reinterpret_cast<const char*>(states.data()), sizeof(states));
  internal::PutVarint32(0, &s);  // no extra bits
  uint32_t symbol = 0;
  size_t at = 0;
  return internal::ReadSymbols(s.data(), s.size(), &at, 1, &symbol);
}

constexpr uint32_t kLowState = 1u << 23;

// rANS states start in [2^23, 2^31): a hand-made stream whose first state is 2^31 + 4080
// would decode (to token 1, back to 2^23) if only the lower end were checked.
TEST(CodecEdges, SymbolStreamWithAStateAboveItsIntervalIsRejected) {
  EXPECT_FALSE(
      ReadsAHandMadeStream({4080, 16}, {(1u << 31) + 4080, kLowState, kLowState, kLowState}));
}

// Frequencies above the total are refused one by one: 4096, 2^32 - 1 and 1 wrap around to a
// sum of 4096, and filling the second token's slots would then write 4 GB past the table.
TEST(CodecEdges, SymbolStreamWithAFrequencyAboveTheTotalIsRejected) {
  EXPECT_FALSE(
      ReadsAHandMadeStream({4096, 0xffffffffu, 1}, {kLowState, kLowState, kLowState, kLowState}));
}

// The alphabet has 228 tokens (128 direct, 4 per bit width 8..32): a stream declaring a 229th,
// even one that never occurs, is refused before the frequency tables are written past their end.
TEST(CodecEdges, SymbolStreamWithAnAlphabetPastTheLastTokenIsRejected) {
  std::vector<uint32_t> frequencies(229, 0);
  frequencies[0] = 4096;  // every slot is token 0
  EXPECT_FALSE(ReadsAHandMadeStream(frequencies, {kLowState, kLowState, kLowState, kLowState}));
  frequencies.pop_back();  // 228 tokens: a valid stream
  EXPECT_TRUE(ReadsAHandMadeStream(frequencies, {kLowState, kLowState, kLowState, kLowState}));
}

}  // namespace
}  // namespace isostream
