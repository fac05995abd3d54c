// Shared by the frame codec tests: one-call encode and decode that expect success, the Draco
// chunk variants, and re-sealing a chunk's checksum after a test edits its payload.
#pragma once

#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#define XXH_INLINE_ALL
#include <xxhash.h>

#include "shared/frame_codec.h"
#include "shared/ordered_mesh.h"

namespace isostream::testing {

inline std::string Encode(const OrderedMesh& mesh, size_t first, size_t count,
                          const CodecOptions& options = {}) {
  std::string chunk;
  const absl::Status status = EncodeChunk(mesh, first, count, options, &chunk);
  EXPECT_TRUE(status.ok()) << status;
  return chunk;
}

inline std::string EncodeRaw(const OrderedMesh& mesh, size_t first, size_t count) {
  std::string chunk;
  const absl::Status status = EncodeChunkRaw(mesh, first, count, &chunk);
  EXPECT_TRUE(status.ok()) << status;
  return chunk;
}

inline OrderedMesh Decode(const std::string& chunk) {
  OrderedMesh mesh;
  const absl::Status status = DecodeAnyChunk(chunk.data(), chunk.size(), &mesh);
  EXPECT_TRUE(status.ok()) << status;
  return mesh;
}

// Re-computes the payload checksum after a test edits the payload, so the edit reaches the
// payload decoder instead of being caught by the checksum.
inline void Reseal(std::string* chunk) {
  const uint32_t checksum = static_cast<uint32_t>(
      XXH3_64bits(chunk->data() + kChunkHeaderSize, chunk->size() - kChunkHeaderSize));
  std::memcpy(chunk->data() + 20, &checksum, 4);
}

// The Draco chunk variants: edge cache (codec 3, the default), Draco mesh with compressed and
// with plain indices (codec 2).
inline std::vector<CodecOptions> DracoVariants() {
  CodecOptions edge_cache, compressed, plain;
  compressed.connectivity = CodecOptions::Connectivity::kDracoSequential;
  plain.connectivity = CodecOptions::Connectivity::kDracoSequential;
  plain.compress_connectivity = false;
  return {edge_cache, compressed, plain};
}

}  // namespace isostream::testing
