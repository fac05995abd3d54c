#include "shared/frame_codec.h"

#include <absl/strings/str_cat.h>
#include <xxhash.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <exception>
#include <limits>
#include <new>

#include "shared/internal/chunk_gather.h"
#include "shared/internal/draco_mesh.h"
#include "shared/internal/ordered_connectivity.h"
#include "shared/internal/vertex_coder.h"
#include "shared/mesh_validate.h"

// Header fields and raw payloads are copied with memcpy of host values.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__,
              "frame_codec assumes a little-endian host");

namespace isostream {
namespace {

constexpr char kMagic[4] = {'I', 'S', 'C', '1'};
constexpr uint16_t kFlagHasNormals = 1;

template <typename T>
void Store(char* at, T value) {
  std::memcpy(at, &value, sizeof(T));
}

template <typename T>
T Load(const char* at) {
  T value;
  std::memcpy(&value, at, sizeof(T));
  return value;
}

uint32_t PayloadChecksum(const char* payload, size_t size) {
  return static_cast<uint32_t>(XXH3_64bits(payload, size));
}

uint64_t RawPayloadSize(uint64_t vertex_count, uint64_t triangle_count, bool has_normals) {
  return vertex_count * (has_normals ? 24 : 12) + triangle_count * 13;
}

// Writes the header for a payload already placed at out[kChunkHeaderSize...].
absl::Status SealChunk(ChunkCodec codec, bool has_normals, size_t triangle_count,
                       size_t vertex_count, std::string* out) {
  const size_t payload_size = out->size() - kChunkHeaderSize;
  if (triangle_count > kMaxChunkTriangles) {
    return absl::InvalidArgumentError(absl::StrCat("chunk of ", triangle_count,
                                                   " triangles exceeds the limit of ",
                                                   kMaxChunkTriangles, "; split the range"));
  }
  if (payload_size > std::numeric_limits<uint32_t>::max()) {
    return absl::ResourceExhaustedError("chunk payload exceeds 4 GiB; split the range");
  }
  char* header = out->data();
  std::memcpy(header, kMagic, 4);
  Store<uint8_t>(header + 4, kChunkFormatVersion);
  Store<uint8_t>(header + 5, static_cast<uint8_t>(codec));
  Store<uint16_t>(header + 6, has_normals ? kFlagHasNormals : 0);
  Store<uint32_t>(header + 8, static_cast<uint32_t>(triangle_count));
  Store<uint32_t>(header + 12, static_cast<uint32_t>(vertex_count));
  Store<uint32_t>(header + 16, static_cast<uint32_t>(payload_size));
  Store<uint32_t>(header + 20, PayloadChecksum(header + kChunkHeaderSize, payload_size));
  return absl::OkStatus();
}

absl::Status EncodeDracoChunk(const internal::GatheredChunk& chunk, const CodecOptions& options,
                              std::string* out) {
  ISOSTREAM_RETURN_IF_ERROR(internal::CheckCodecOptions(options));
  const size_t triangle_count = chunk.triangle_count();
  const bool has_normals = !chunk.normals.empty() && triangle_count > 0;
  out->assign(kChunkHeaderSize, '\0');
  if (triangle_count == 0) {
    return SealChunk(ChunkCodec::kDraco, false, 0, 0, out);
  }
  // Codec 3's vertex coder checks the box while it quantizes.
  if (options.position_box && options.position_bits > 0 &&
      options.connectivity != CodecOptions::Connectivity::kEdgeCache) {
    ISOSTREAM_RETURN_IF_ERROR(internal::CheckInsideBox(chunk, *options.position_box));
  }

  internal::DracoEncodeSettings settings;
  settings.position_bits = options.position_bits;
  settings.normal_bits = options.normal_bits;
  settings.compress_connectivity = options.compress_connectivity;
  settings.position_box = options.position_box ? &*options.position_box : nullptr;
  ChunkCodec codec = ChunkCodec::kDraco;
  std::string payload;
  if (options.connectivity == CodecOptions::Connectivity::kEdgeCache) {
    codec = ChunkCodec::kDracoEdgeCache;
    // Room for a typical chunk (~3.5 bytes per triangle, 4 with 13-bit normals), so the parts
    // are appended without the string growing and copying itself along the way.
    payload.reserve(4 * triangle_count + 1024);
    payload.assign(4, '\0');
    ISOSTREAM_RETURN_IF_ERROR(internal::EncodeChunkVertices(
        chunk, options.position_bits, options.normal_bits, settings.position_box, &payload));
    Store<uint32_t>(payload.data(), static_cast<uint32_t>(payload.size() - 4));
    ISOSTREAM_RETURN_IF_ERROR(internal::EncodeOrderedConnectivity(
        chunk.triangles.data(), triangle_count, chunk.vertex_count(), &payload));
  } else {
    ISOSTREAM_RETURN_IF_ERROR(internal::EncodeDracoMesh(chunk, settings, &payload, nullptr));
  }
  // Plain indices take at least a byte each, which restores the floor decoders rely on.
  if (triangle_count > kMaxTrianglesPerDracoByte * payload.size()) {
    codec = ChunkCodec::kDraco;
    settings.compress_connectivity = false;
    ISOSTREAM_RETURN_IF_ERROR(internal::EncodeDracoMesh(chunk, settings, &payload, nullptr));
  }
  out->append(payload);
  return SealChunk(codec, has_normals, triangle_count, chunk.vertex_count(), out);
}

absl::Status EncodeRawChunk(const internal::GatheredChunk& chunk, std::string* out) {
  const size_t triangle_count = chunk.triangle_count();
  const bool has_normals = !chunk.normals.empty() && triangle_count > 0;
  const size_t vertex_count = chunk.vertex_count();
  out->assign(kChunkHeaderSize + RawPayloadSize(vertex_count, triangle_count, has_normals), '\0');
  char* p = out->data() + kChunkHeaderSize;
  auto put = [&p](const void* data, size_t bytes) {
    if (bytes > 0) std::memcpy(p, data, bytes);
    p += bytes;
  };
  put(chunk.positions.data(), chunk.positions.size() * sizeof(float));
  if (has_normals) put(chunk.normals.data(), chunk.normals.size() * sizeof(float));
  put(chunk.triangles.data(), chunk.triangles.size() * sizeof(uint32_t));
  put(chunk.surface.data(), chunk.surface.size());
  return SealChunk(ChunkCodec::kRaw, has_normals, triangle_count, vertex_count, out);
}

absl::Status DecodeRawPayload(const ChunkHeader& header, const char* payload,
                              OrderedMesh* append_to) {
  const size_t vertex_count = header.vertex_count;
  const size_t triangle_count = header.triangle_count;
  const char* positions = payload;
  const char* normals = positions + 12 * vertex_count;
  const char* triangles = normals + (header.has_normals ? 12 * vertex_count : 0);
  const char* surface = triangles + 12 * triangle_count;
  // check everything before appending anything
  for (size_t i = 0; i < 3 * vertex_count; ++i) {
    if (!std::isfinite(Load<float>(positions + 4 * i)))
      return absl::DataLossError(absl::StrCat("raw chunk vertex ", i / 3, " is not finite"));
    if (header.has_normals && !std::isfinite(Load<float>(normals + 4 * i)))
      return absl::DataLossError(absl::StrCat("raw chunk normal ", i / 3, " is not finite"));
  }
  for (size_t i = 0; i < 3 * triangle_count; ++i) {
    if (Load<uint32_t>(triangles + 4 * i) >= vertex_count) {
      return absl::DataLossError(
          absl::StrCat("raw chunk triangle ", i / 3, " uses a vertex outside the chunk"));
    }
  }
  for (size_t t = 0; t < triangle_count; ++t) {
    if (static_cast<uint8_t>(surface[t]) >= kMaxSurfaces) {
      return absl::DataLossError(absl::StrCat("raw chunk triangle ", t, " has surface ",
                                              int{static_cast<uint8_t>(surface[t])}));
    }
  }
  const size_t offset = append_to->vertex_count();
  if (offset + vertex_count >= std::numeric_limits<uint32_t>::max()) {
    return absl::OutOfRangeError("decoded mesh would exceed 2^32 - 1 vertices");
  }
  append_to->positions.resize(3 * (offset + vertex_count));
  if (vertex_count > 0) {
    std::memcpy(&append_to->positions[3 * offset], positions, 12 * vertex_count);
  }
  append_to->normals.resize(3 * (offset + vertex_count), 0.0f);
  if (header.has_normals && vertex_count > 0) {
    std::memcpy(&append_to->normals[3 * offset], normals, 12 * vertex_count);
  }
  const size_t first_index = append_to->triangles.size();
  append_to->triangles.resize(first_index + 3 * triangle_count);
  for (size_t i = 0; i < 3 * triangle_count; ++i) {
    append_to->triangles[first_index + i] =
        static_cast<uint32_t>(offset + Load<uint32_t>(triangles + 4 * i));
  }
  append_to->surface.insert(append_to->surface.end(), surface, surface + triangle_count);
  return absl::OkStatus();
}

// Header, size and checksum checks common to both decoders; returns the parsed header.
absl::StatusOr<ChunkHeader> CheckChunk(const char* data, size_t size) {
  ISOSTREAM_ASSIGN_OR_RETURN(const ChunkHeader header, ReadChunkHeader(data, size));
  if (size != kChunkHeaderSize + size_t{header.payload_size}) {
    return absl::DataLossError(absl::StrCat("chunk is ", size, " bytes but its header declares ",
                                            kChunkHeaderSize + size_t{header.payload_size}));
  }
  if (PayloadChecksum(data + kChunkHeaderSize, header.payload_size) != header.checksum) {
    return absl::DataLossError("chunk payload checksum mismatch (corrupted in transit?)");
  }
  return header;
}

// Codec 3: the vertex part's size, the vertex part, the connectivity.
absl::Status DecodeEdgeCachePayload(const ChunkHeader& header, const char* payload,
                                    OrderedMesh* append_to) {
  const size_t size = header.payload_size;
  if (size < 4) return absl::DataLossError("edge-cache payload is shorter than its size field");
  const size_t vertices_size = Load<uint32_t>(payload);
  if (vertices_size > size - 4) {
    return absl::DataLossError(absl::StrCat("edge-cache payload declares a ", vertices_size,
                                            "-byte vertex part in ", size - 4, " bytes"));
  }
  const char* vertices = payload + 4;
  // Connectivity first: it is cheaper and checks the vertex count.
  internal::DecodedChunk chunk;
  ISOSTREAM_RETURN_IF_ERROR(internal::DecodeOrderedConnectivity(
      vertices + vertices_size, size - 4 - vertices_size, header.triangle_count,
      header.vertex_count, &chunk.triangles));
  ISOSTREAM_RETURN_IF_ERROR(internal::DecodeChunkVertices(
      vertices, vertices_size, header.vertex_count, header.has_normals, &chunk));
  return internal::AppendDecodedChunk(&chunk, append_to);
}

absl::Status DecodeChecked(const ChunkHeader& header, const char* data, OrderedMesh* append_to) {
  ISOSTREAM_RETURN_IF_ERROR(ValidateMeshSizes(*append_to));
  const char* payload = data + kChunkHeaderSize;
  if (header.codec == ChunkCodec::kRaw) return DecodeRawPayload(header, payload, append_to);
  if (header.triangle_count == 0) return absl::OkStatus();
  if (header.codec == ChunkCodec::kDracoEdgeCache) {
    return DecodeEdgeCachePayload(header, payload, append_to);
  }
  return internal::DecodeDracoMesh(payload, header.payload_size, header.triangle_count,
                                   header.vertex_count, header.has_normals, append_to);
}

// Module edge: no exception (allocation failure included) escapes, and a failed decode leaves
// the destination's arrays at their previous sizes.
template <typename Body>
absl::Status GuardDecode(OrderedMesh* append_to, Body body) {
  if (append_to == nullptr) return absl::InvalidArgumentError("append_to is null");
  const size_t sizes[4] = {append_to->positions.size(), append_to->normals.size(),
                           append_to->triangles.size(), append_to->surface.size()};
  absl::Status status;
  try {
    status = body();
  } catch (const std::bad_alloc&) {
    status = absl::ResourceExhaustedError("out of memory while decoding a chunk");
  } catch (const std::exception& e) {
    status = absl::InternalError(absl::StrCat("decoding a chunk threw: ", e.what()));
  }
  if (!status.ok()) {
    append_to->positions.resize(sizes[0]);
    append_to->normals.resize(sizes[1]);
    append_to->triangles.resize(sizes[2]);
    append_to->surface.resize(sizes[3]);
  }
  return status;
}

template <typename Body>
absl::Status GuardEncode(std::string* out, Body body) {
  if (out == nullptr) return absl::InvalidArgumentError("out is null");
  try {
    return body();
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError("out of memory while encoding a chunk");
  } catch (const std::exception& e) {
    return absl::InternalError(absl::StrCat("encoding a chunk threw: ", e.what()));
  }
}

}  // namespace

QuantizationBox BoundingCube(const float* positions, size_t vertex_count) {
  QuantizationBox box;
  if (vertex_count == 0) return box;
  float low[3] = {positions[0], positions[1], positions[2]};
  float high[3] = {positions[0], positions[1], positions[2]};
  for (size_t v = 1; v < vertex_count; ++v) {
    for (int k = 0; k < 3; ++k) {
      low[k] = std::min(low[k], positions[3 * v + k]);
      high[k] = std::max(high[k], positions[3 * v + k]);
    }
  }
  box.range = 0.0f;
  for (int k = 0; k < 3; ++k) {
    box.origin[k] = low[k];
    box.range = std::max(box.range, high[k] - low[k]);
  }
  if (box.range == 0.0f) box.range = 1.0f;
  return box;
}

float PositionErrorBound(const QuantizationBox& box, int position_bits) {
  if (position_bits <= 0) return 0.0f;
  const double steps = std::ldexp(1.0, position_bits) - 1.0;
  const double largest_origin =
      std::max({std::fabs(box.origin[0]), std::fabs(box.origin[1]), std::fabs(box.origin[2])});
  const double bound = box.range / (2.0 * steps) + 4.0 * FLT_EPSILON * (largest_origin + box.range);
  return static_cast<float>(bound);
}

float NormalErrorBound(int normal_bits) {
  if (normal_bits <= 0) return 0.0f;
  const double center = std::ldexp(1.0, normal_bits - 1) - 1.0;
  return static_cast<float>(2.5 / center);
}

absl::StatusOr<ChunkHeader> ReadChunkHeader(const char* data, size_t size) {
  if (data == nullptr || size < kChunkHeaderSize) {
    return absl::DataLossError(absl::StrCat("chunk of ", size, " bytes is shorter than the ",
                                            kChunkHeaderSize, "-byte header"));
  }
  if (std::memcmp(data, kMagic, 4) != 0) {
    return absl::InvalidArgumentError("not an isostream mesh chunk (bad magic)");
  }
  const uint8_t version = Load<uint8_t>(data + 4);
  if (version != kChunkFormatVersion) {
    return absl::InvalidArgumentError(absl::StrCat("chunk format version ", int{version},
                                                   " is not supported (expected ",
                                                   kChunkFormatVersion, ")"));
  }
  const uint8_t codec = Load<uint8_t>(data + 5);
  if (codec != static_cast<uint8_t>(ChunkCodec::kRaw) &&
      codec != static_cast<uint8_t>(ChunkCodec::kDraco) &&
      codec != static_cast<uint8_t>(ChunkCodec::kDracoEdgeCache)) {
    return absl::InvalidArgumentError(absl::StrCat("unknown chunk codec id ", int{codec}));
  }
  const uint16_t flags = Load<uint16_t>(data + 6);
  if (flags & ~kFlagHasNormals) {
    return absl::InvalidArgumentError(absl::StrCat("unknown chunk flags 0x", absl::Hex(flags)));
  }
  ChunkHeader header;
  header.codec = static_cast<ChunkCodec>(codec);
  header.has_normals = (flags & kFlagHasNormals) != 0;
  header.triangle_count = Load<uint32_t>(data + 8);
  header.vertex_count = Load<uint32_t>(data + 12);
  header.payload_size = Load<uint32_t>(data + 16);
  header.checksum = Load<uint32_t>(data + 20);

  const uint64_t triangles = header.triangle_count;
  const uint64_t vertices = header.vertex_count;
  if (triangles > kMaxChunkTriangles) {
    return absl::InvalidArgumentError(absl::StrCat(
        "chunk declares ", triangles, " triangles, above the limit ", kMaxChunkTriangles));
  }
  // Vertices are those the triangles use: at least one and at most three per triangle.
  if (vertices > 3 * triangles || (triangles > 0 && vertices == 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("chunk declares ", vertices, " vertices for ", triangles, " triangles"));
  }
  if (triangles == 0 && (header.has_normals || header.payload_size != 0)) {
    return absl::InvalidArgumentError("empty chunk with normals flag or payload");
  }
  if (header.codec == ChunkCodec::kRaw) {
    const uint64_t expected = RawPayloadSize(vertices, triangles, header.has_normals);
    if (header.payload_size != expected) {
      return absl::InvalidArgumentError(absl::StrCat("raw chunk payload is ", header.payload_size,
                                                     " bytes; its counts need ", expected));
    }
  } else if (triangles > uint64_t{kMaxTrianglesPerDracoByte} * header.payload_size) {
    return absl::InvalidArgumentError(absl::StrCat("Draco chunk declares ", triangles,
                                                   " triangles in a payload of ",
                                                   header.payload_size, " bytes"));
  }
  return header;
}

absl::Status EncodeChunk(const OrderedMesh& mesh, size_t first_triangle, size_t triangle_count,
                         const CodecOptions& options, std::string* out) {
  return GuardEncode(out, [&]() -> absl::Status {
    internal::GatheredChunk chunk;
    ISOSTREAM_RETURN_IF_ERROR(
        internal::GatherTriangleRange(mesh, first_triangle, triangle_count, &chunk));
    return EncodeDracoChunk(chunk, options, out);
  });
}

absl::Status EncodeChunkRaw(const OrderedMesh& mesh, size_t first_triangle, size_t triangle_count,
                            std::string* out) {
  return GuardEncode(out, [&]() -> absl::Status {
    internal::GatheredChunk chunk;
    ISOSTREAM_RETURN_IF_ERROR(
        internal::GatherTriangleRange(mesh, first_triangle, triangle_count, &chunk));
    return EncodeRawChunk(chunk, out);
  });
}

ChunkCopy::ChunkCopy() = default;
ChunkCopy::~ChunkCopy() = default;
ChunkCopy::ChunkCopy(ChunkCopy&&) noexcept = default;
ChunkCopy& ChunkCopy::operator=(ChunkCopy&&) noexcept = default;

size_t ChunkCopy::triangle_count() const { return chunk_ ? chunk_->triangle_count() : 0; }

ChunkCopier::ChunkCopier() : scratch_(std::make_unique<internal::GatherScratch>()) {}
ChunkCopier::~ChunkCopier() = default;

absl::Status ChunkCopier::Copy(const OrderedMesh& mesh, size_t first_triangle,
                               size_t triangle_count, ChunkCopy* out) {
  if (out == nullptr) return absl::InvalidArgumentError("out is null");
  try {
    auto chunk = std::make_unique<internal::GatheredChunk>();
    ISOSTREAM_RETURN_IF_ERROR(internal::GatherTriangleRange(mesh, first_triangle, triangle_count,
                                                            chunk.get(), scratch_.get()));
    out->chunk_ = std::move(chunk);
    return absl::OkStatus();
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError("out of memory while copying a chunk");
  }
}

absl::Status EncodeChunk(const ChunkCopy& copy, const CodecOptions& options, std::string* out) {
  if (!copy.chunk_) return absl::InvalidArgumentError("empty ChunkCopy (nothing was copied)");
  return GuardEncode(out, [&] { return EncodeDracoChunk(*copy.chunk_, options, out); });
}

absl::Status EncodeChunkRaw(const ChunkCopy& copy, std::string* out) {
  if (!copy.chunk_) return absl::InvalidArgumentError("empty ChunkCopy (nothing was copied)");
  return GuardEncode(out, [&] { return EncodeRawChunk(*copy.chunk_, out); });
}

absl::Status DecodeChunk(const char* data, size_t size, OrderedMesh* append_to) {
  return GuardDecode(append_to, [&]() -> absl::Status {
    ISOSTREAM_ASSIGN_OR_RETURN(const ChunkHeader header, CheckChunk(data, size));
    if (header.codec == ChunkCodec::kRaw) {
      return absl::InvalidArgumentError("DecodeChunk given a raw chunk; use DecodeAnyChunk");
    }
    return DecodeChecked(header, data, append_to);
  });
}

absl::Status DecodeChunkRaw(const char* data, size_t size, OrderedMesh* append_to) {
  return GuardDecode(append_to, [&]() -> absl::Status {
    ISOSTREAM_ASSIGN_OR_RETURN(const ChunkHeader header, CheckChunk(data, size));
    if (header.codec != ChunkCodec::kRaw) {
      return absl::InvalidArgumentError("DecodeChunkRaw given a Draco chunk; use DecodeAnyChunk");
    }
    return DecodeChecked(header, data, append_to);
  });
}

absl::Status DecodeAnyChunk(const char* data, size_t size, OrderedMesh* append_to) {
  return GuardDecode(append_to, [&]() -> absl::Status {
    ISOSTREAM_ASSIGN_OR_RETURN(const ChunkHeader header, CheckChunk(data, size));
    return DecodeChecked(header, data, append_to);
  });
}

}  // namespace isostream
