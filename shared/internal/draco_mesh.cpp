#include "shared/internal/draco_mesh.h"

#include <absl/strings/str_cat.h>
#include <draco/compression/config/compression_shared.h>
#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/core/decoder_buffer.h>
#include <draco/core/encoder_buffer.h>
#include <draco/mesh/mesh.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>

#include "shared/internal/varint.h"

namespace isostream::internal {
namespace {

// Draco's bitstream header: "DRACO", version major and minor, encoder type, encoder method,
// uint16 flags. Sequential mesh connectivity follows at once (from bitstream 2.2 on) with the
// face and point counts as varints.
constexpr size_t kDracoHeaderSize = 11;
constexpr uint16_t kDracoMetadataFlag = 0x8000;

int AddAttribute(draco::PointCloud* points, draco::GeometryAttribute::Type type, int components,
                 draco::DataType data_type, bool normalized, const void* values,
                 size_t value_bytes) {
  auto attribute = std::make_unique<draco::PointAttribute>();
  attribute->Init(type, static_cast<int8_t>(components), data_type, normalized,
                  points->num_points());
  attribute->buffer()->Write(0, values, value_bytes);
  return points->AddAttribute(std::move(attribute));
}

bool IsZero(const float* v) { return v[0] == 0.0f && v[1] == 0.0f && v[2] == 0.0f; }

// Copies one value per point from a decoded attribute whose layout was checked by the caller.
template <typename T>
bool CopyPointValues(const draco::PointAttribute& attribute, size_t point_count, int components,
                     T* out) {
  const size_t value_bytes = sizeof(T) * static_cast<size_t>(components);
  if (attribute.byte_stride() != static_cast<int64_t>(value_bytes)) return false;
  if (attribute.is_mapping_identity()) {
    if (attribute.size() < point_count) return false;
    if (point_count > 0) {
      std::memcpy(out, attribute.GetAddress(draco::AttributeValueIndex(0)),
                  point_count * value_bytes);
    }
    return true;
  }
  for (size_t p = 0; p < point_count; ++p) {
    const draco::AttributeValueIndex index =
        attribute.mapped_index(draco::PointIndex(static_cast<uint32_t>(p)));
    if (index.value() >= attribute.size()) return false;
    std::memcpy(out + p * components, attribute.GetAddress(index), value_bytes);
  }
  return true;
}

bool HasLayout(const draco::PointAttribute* attribute, int components, draco::DataType type) {
  return attribute && attribute->num_components() == components && attribute->data_type() == type;
}

}  // namespace

absl::Status CheckCodecOptions(const CodecOptions& options) {
  if (options.position_bits < 0 || options.position_bits > 30) {
    return absl::InvalidArgumentError(
        absl::StrCat("position_bits ", options.position_bits, " is outside 0 (lossless) or 1..30"));
  }
  if (options.normal_bits < 0 || options.normal_bits == 1 || options.normal_bits > 30) {
    return absl::InvalidArgumentError(
        absl::StrCat("normal_bits ", options.normal_bits, " is outside 0 (lossless) or 2..30"));
  }
  if (options.position_box) {
    const QuantizationBox& box = *options.position_box;
    if (!(box.range > 0.0f) || !std::isfinite(box.range) || !std::isfinite(box.origin[0]) ||
        !std::isfinite(box.origin[1]) || !std::isfinite(box.origin[2])) {
      return absl::InvalidArgumentError("position_box needs a finite origin and a positive range");
    }
  }
  return absl::OkStatus();
}

absl::Status CheckInsideBox(const GatheredChunk& chunk, const QuantizationBox& box) {
  for (size_t v = 0; v < chunk.vertex_count(); ++v) {
    for (int k = 0; k < 3; ++k) {
      // The same difference Draco quantizes; inside means it maps onto the grid's 0..2^bits-1.
      const float offset = chunk.positions[3 * v + k] - box.origin[k];
      if (!(offset >= 0.0f && offset <= box.range)) {
        return absl::InvalidArgumentError(absl::StrCat(
            "chunk vertex ", v, " coordinate ", k, " = ", chunk.positions[3 * v + k],
            " lies outside position_box [", box.origin[k], ", ", box.origin[k] + box.range, "]"));
      }
    }
  }
  return absl::OkStatus();
}

namespace {

// Adds the chunk's vertex attributes to `points` (whose point count must be set): one value per
// point (identity mapping), in chunk order.
DracoAttributeIds AddChunkAttributes(const GatheredChunk& chunk,
                                     const DracoEncodeSettings& settings,
                                     draco::PointCloud* points) {
  const size_t vertex_count = chunk.vertex_count();
  const bool has_normals = !chunk.normals.empty();
  DracoAttributeIds attribute_ids;
  attribute_ids.position =
      AddAttribute(points, draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32, false,
                   chunk.positions.data(), chunk.positions.size() * sizeof(float));
  if (has_normals) {
    attribute_ids.normal =
        AddAttribute(points, draco::GeometryAttribute::NORMAL, 3, draco::DT_FLOAT32, false,
                     chunk.normals.data(), chunk.normals.size() * sizeof(float));
  }
  std::vector<uint8_t> tags(chunk.vertex_surface.begin(), chunk.vertex_surface.end());
  if (has_normals && settings.mark_undefined_normals) {
    for (size_t v = 0; v < vertex_count; ++v) {
      if (IsZero(&chunk.normals[3 * v])) tags[v] |= kUndefinedNormalBit;
    }
  }
  attribute_ids.surface = AddAttribute(points, draco::GeometryAttribute::GENERIC, 1,
                                       draco::DT_UINT8, false, tags.data(), tags.size());
  if (!settings.surface_colors.empty()) {
    std::vector<uint8_t> colors(4 * vertex_count, 255);
    for (size_t v = 0; v < vertex_count; ++v) {
      const size_t surface = chunk.vertex_surface[v];
      if (surface < settings.surface_colors.size()) {
        std::copy_n(settings.surface_colors[surface].data(), 4, &colors[4 * v]);
      }
    }
    attribute_ids.color = AddAttribute(points, draco::GeometryAttribute::COLOR, 4, draco::DT_UINT8,
                                       true, colors.data(), colors.size());
  }
  return attribute_ids;
}

void ConfigureQuantization(const DracoEncodeSettings& settings, bool has_normals,
                           draco::Encoder* encoder) {
  if (settings.position_bits > 0) {
    if (settings.position_box) {
      encoder->SetAttributeExplicitQuantization(
          draco::GeometryAttribute::POSITION, settings.position_bits, 3,
          settings.position_box->origin, settings.position_box->range);
    } else {
      encoder->SetAttributeQuantization(draco::GeometryAttribute::POSITION, settings.position_bits);
    }
  }
  if (has_normals && settings.normal_bits > 0) {
    encoder->SetAttributeQuantization(draco::GeometryAttribute::NORMAL, settings.normal_bits);
  }
}

}  // namespace

absl::Status EncodeDracoMesh(const GatheredChunk& chunk, const DracoEncodeSettings& settings,
                             std::string* out, DracoAttributeIds* ids) {
  const size_t triangle_count = chunk.triangle_count();
  const bool has_normals = !chunk.normals.empty();

  draco::Mesh mesh;
  mesh.set_num_points(static_cast<uint32_t>(chunk.vertex_count()));
  const DracoAttributeIds attribute_ids = AddChunkAttributes(chunk, settings, &mesh);
  mesh.SetNumFaces(triangle_count);
  for (size_t t = 0; t < triangle_count; ++t) {
    const uint32_t* corner = &chunk.triangles[3 * t];
    mesh.SetFace(
        draco::FaceIndex(static_cast<uint32_t>(t)),
        {draco::PointIndex(corner[0]), draco::PointIndex(corner[1]), draco::PointIndex(corner[2])});
  }

  // encode: sequential keeps face, corner and point order exactly as built above
  draco::Encoder encoder;
  encoder.SetEncodingMethod(draco::MESH_SEQUENTIAL_ENCODING);
  ConfigureQuantization(settings, has_normals, &encoder);
  encoder.options().SetGlobalBool("compress_connectivity", settings.compress_connectivity);
  draco::EncoderBuffer buffer;
  const draco::Status status = encoder.EncodeMeshToBuffer(mesh, &buffer);
  if (!status.ok()) {
    return absl::InternalError(absl::StrCat("Draco encoding failed: ", status.error_msg()));
  }
  out->assign(buffer.data(), buffer.size());
  if (ids) {
    // Draco numbers unique ids as it adds attributes; glTF needs the unique ids, not indices.
    ids->position = static_cast<int>(mesh.attribute(attribute_ids.position)->unique_id());
    ids->normal =
        has_normals ? static_cast<int>(mesh.attribute(attribute_ids.normal)->unique_id()) : -1;
    ids->surface = static_cast<int>(mesh.attribute(attribute_ids.surface)->unique_id());
    ids->color = attribute_ids.color >= 0
                     ? static_cast<int>(mesh.attribute(attribute_ids.color)->unique_id())
                     : -1;
  }
  return absl::OkStatus();
}

absl::Status EncodeDracoPoints(const GatheredChunk& chunk, const DracoEncodeSettings& settings,
                               std::string* out) {
  draco::PointCloud points;
  points.set_num_points(static_cast<uint32_t>(chunk.vertex_count()));
  AddChunkAttributes(chunk, settings, &points);
  draco::Encoder encoder;
  // Sequential keeps point order (the kd-tree method, Draco's other one, sorts the points).
  encoder.SetEncodingMethod(draco::POINT_CLOUD_SEQUENTIAL_ENCODING);
  ConfigureQuantization(settings, !chunk.normals.empty(), &encoder);
  draco::EncoderBuffer buffer;
  const draco::Status status = encoder.EncodePointCloudToBuffer(points, &buffer);
  if (!status.ok()) {
    return absl::InternalError(absl::StrCat("Draco encoding failed: ", status.error_msg()));
  }
  out->append(buffer.data(), buffer.size());
  return absl::OkStatus();
}

absl::Status ReadDracoSequentialCounts(const char* data, size_t size, uint32_t* face_count,
                                       uint32_t* point_count) {
  if (size < kDracoHeaderSize || std::memcmp(data, "DRACO", 5) != 0) {
    return absl::DataLossError("payload is not a Draco bitstream");
  }
  const auto* bytes = reinterpret_cast<const uint8_t*>(data);
  const uint8_t major = bytes[5];
  const uint8_t minor = bytes[6];
  // Bitstream 2.2 is what Draco 1.5 writes; older ones store counts differently.
  if (major != 2 || minor != 2) {
    return absl::DataLossError(absl::StrCat("unsupported Draco bitstream version ", int{major}, ".",
                                            int{minor}, " (expected 2.2)"));
  }
  if (bytes[7] != draco::TRIANGULAR_MESH || bytes[8] != draco::MESH_SEQUENTIAL_ENCODING) {
    return absl::DataLossError(
        "Draco payload is not a sequentially encoded mesh (other methods lose triangle order)");
  }
  const uint16_t flags = static_cast<uint16_t>(bytes[9] | (bytes[10] << 8));
  if (flags & kDracoMetadataFlag) return absl::DataLossError("Draco payload carries metadata");
  size_t at = kDracoHeaderSize;
  if (!GetVarint32(bytes, size, &at, face_count) || !GetVarint32(bytes, size, &at, point_count)) {
    return absl::DataLossError("Draco payload ends inside its connectivity header");
  }
  return absl::OkStatus();
}

absl::Status ReadDracoPointCloudCount(const char* data, size_t size, uint32_t* point_count) {
  if (size < kDracoHeaderSize || std::memcmp(data, "DRACO", 5) != 0) {
    return absl::DataLossError("vertex payload is not a Draco bitstream");
  }
  const auto* bytes = reinterpret_cast<const uint8_t*>(data);
  if (bytes[5] != draco::kDracoPointCloudBitstreamVersionMajor ||
      bytes[6] != draco::kDracoPointCloudBitstreamVersionMinor) {
    return absl::DataLossError(absl::StrCat("unsupported Draco point cloud bitstream version ",
                                            int{bytes[5]}, ".", int{bytes[6]}));
  }
  if (bytes[7] != draco::POINT_CLOUD || bytes[8] != draco::POINT_CLOUD_SEQUENTIAL_ENCODING) {
    return absl::DataLossError(
        "Draco vertex payload is not a sequentially encoded point cloud (others reorder points)");
  }
  const uint16_t flags = static_cast<uint16_t>(bytes[9] | (bytes[10] << 8));
  if (flags & kDracoMetadataFlag) return absl::DataLossError("Draco payload carries metadata");
  // The sequential point cloud decoder reads the count as a little-endian int32.
  if (size < kDracoHeaderSize + 4) {
    return absl::DataLossError("Draco payload ends inside its point count");
  }
  int32_t count;
  std::memcpy(&count, data + kDracoHeaderSize, 4);
  if (count < 0) return absl::DataLossError("Draco payload declares a negative point count");
  *point_count = static_cast<uint32_t>(count);
  return absl::OkStatus();
}

namespace {

// Copies the chunk attributes out of a decoded Draco mesh or point cloud.
absl::Status ReadVertexAttributes(const draco::PointCloud& points, uint32_t vertex_count,
                                  bool expect_normals, DecodedChunk* out) {
  const draco::PointAttribute* position =
      points.GetNamedAttribute(draco::GeometryAttribute::POSITION);
  const draco::PointAttribute* normal = points.GetNamedAttribute(draco::GeometryAttribute::NORMAL);
  const draco::PointAttribute* surface =
      points.GetNamedAttribute(draco::GeometryAttribute::GENERIC);
  if (!HasLayout(position, 3, draco::DT_FLOAT32) || !HasLayout(surface, 1, draco::DT_UINT8)) {
    return absl::DataLossError(
        "Draco payload lacks float32 x3 POSITION or uint8 surface attribute");
  }
  if (expect_normals != (normal != nullptr) ||
      (normal && !HasLayout(normal, 3, draco::DT_FLOAT32))) {
    return absl::DataLossError(expect_normals
                                   ? "Draco payload lacks the float32 x3 NORMAL attribute"
                                   : "Draco payload has normals the header does not declare");
  }
  out->positions.resize(3 * size_t{vertex_count});
  out->normals.resize(expect_normals ? 3 * size_t{vertex_count} : 0);
  out->tags.resize(vertex_count);
  if (!CopyPointValues(*position, vertex_count, 3, out->positions.data()) ||
      !CopyPointValues(*surface, vertex_count, 1, out->tags.data()) ||
      (normal && !CopyPointValues(*normal, vertex_count, 3, out->normals.data()))) {
    return absl::DataLossError("Draco attribute values do not cover every point");
  }
  if (expect_normals) {
    for (uint32_t v = 0; v < vertex_count; ++v) {
      if (out->tags[v] & kUndefinedNormalBit) std::fill_n(&out->normals[3 * size_t{v}], 3, 0.0f);
    }
  }
  // As the other codecs check: a lossless Draco attribute can carry any float.
  for (const float x : out->positions)
    if (!std::isfinite(x))
      return absl::DataLossError("Draco payload holds a position that is not finite");
  for (const float x : out->normals)
    if (!std::isfinite(x))
      return absl::DataLossError("Draco payload holds a normal that is not finite");
  return absl::OkStatus();
}

// Checks that each triangle's corners agree on a valid surface and records it.
absl::Status AssignTriangleSurfaces(DecodedChunk* chunk) {
  const size_t triangle_count = chunk->triangles.size() / 3;
  chunk->triangle_surface.resize(triangle_count);
  for (size_t t = 0; t < triangle_count; ++t) {
    const uint32_t* corner = &chunk->triangles[3 * t];
    const uint8_t s = chunk->tags[corner[0]] & kSurfaceMask;
    if ((chunk->tags[corner[1]] & kSurfaceMask) != s ||
        (chunk->tags[corner[2]] & kSurfaceMask) != s || s >= kMaxSurfaces) {
      return absl::DataLossError(absl::StrCat("face ", t, " has inconsistent or invalid surface"));
    }
    chunk->triangle_surface[t] = s;
  }
  return absl::OkStatus();
}

absl::Status Append(const DecodedChunk& chunk, OrderedMesh* append_to) {
  const size_t vertex_count = chunk.tags.size();
  const size_t offset = append_to->vertex_count();
  if (offset + vertex_count >= std::numeric_limits<uint32_t>::max()) {
    return absl::OutOfRangeError("decoded mesh would exceed 2^32 - 1 vertices");
  }
  append_to->normals.resize(3 * offset, 0.0f);  // back-fill a mesh that had no normals
  append_to->positions.insert(append_to->positions.end(), chunk.positions.begin(),
                              chunk.positions.end());
  if (!chunk.normals.empty()) {
    append_to->normals.insert(append_to->normals.end(), chunk.normals.begin(), chunk.normals.end());
  } else {
    append_to->normals.resize(append_to->positions.size(), 0.0f);
  }
  // resize, not reserve: reserve allocates exactly what is asked, so a frame's index array was
  // reallocated and copied whole at every chunk (~11 k page faults per 64 k-triangle chunk of a
  // 6.9 M-triangle frame), where resize grows it geometrically.
  const size_t first = append_to->triangles.size();
  append_to->triangles.resize(first + chunk.triangles.size());
  uint32_t* out = append_to->triangles.data() + first;
  for (size_t i = 0; i < chunk.triangles.size(); ++i)
    out[i] = static_cast<uint32_t>(offset + chunk.triangles[i]);
  append_to->surface.insert(append_to->surface.end(), chunk.triangle_surface.begin(),
                            chunk.triangle_surface.end());
  return absl::OkStatus();
}

}  // namespace

absl::Status AppendDecodedChunk(DecodedChunk* chunk, OrderedMesh* append_to) {
  ISOSTREAM_RETURN_IF_ERROR(AssignTriangleSurfaces(chunk));
  return Append(*chunk, append_to);
}

absl::Status DecodeDracoMesh(const char* data, size_t size, uint32_t triangle_count,
                             uint32_t vertex_count, bool expect_normals, OrderedMesh* append_to) {
  uint32_t draco_faces = 0;
  uint32_t draco_points = 0;
  ISOSTREAM_RETURN_IF_ERROR(ReadDracoSequentialCounts(data, size, &draco_faces, &draco_points));
  if (draco_faces != triangle_count || draco_points != vertex_count) {
    return absl::DataLossError(absl::StrCat("Draco payload holds ", draco_faces, " faces and ",
                                            draco_points, " points; expected ", triangle_count,
                                            " and ", vertex_count));
  }

  // Draco 1.5.5 checks compressed connectivity against 3 bytes per face of remaining input, a
  // bound the compressed stream need not meet; trailing zeros satisfy it and are never read.
  const size_t padded_size = 3 * size_t{triangle_count} + 64;
  std::vector<char> padded;
  const char* input = data;
  size_t input_size = size;
  if (size < padded_size) {
    padded.assign(padded_size, 0);
    std::memcpy(padded.data(), data, size);
    input = padded.data();
    input_size = padded.size();
  }

  draco::DecoderBuffer buffer;
  buffer.Init(input, input_size);
  draco::Decoder decoder;
  draco::StatusOr<std::unique_ptr<draco::Mesh>> decoded = decoder.DecodeMeshFromBuffer(&buffer);
  if (!decoded.ok()) {
    return absl::DataLossError(
        absl::StrCat("Draco decoding failed: ", decoded.status().error_msg()));
  }
  const draco::Mesh& mesh = *decoded.value();
  if (mesh.num_faces() != triangle_count || mesh.num_points() != vertex_count) {
    return absl::DataLossError("Draco decoded a different number of faces or points than declared");
  }

  // check and read everything into scratch before touching append_to
  DecodedChunk chunk;
  ISOSTREAM_RETURN_IF_ERROR(ReadVertexAttributes(mesh, vertex_count, expect_normals, &chunk));
  chunk.triangles.resize(3 * size_t{triangle_count});
  for (uint32_t t = 0; t < triangle_count; ++t) {
    const draco::Mesh::Face& face = mesh.face(draco::FaceIndex(t));
    for (int c = 0; c < 3; ++c) {
      const uint32_t v = face[c].value();
      if (v >= vertex_count)
        return absl::DataLossError(absl::StrCat("face ", t, " index out of range"));
      chunk.triangles[3 * size_t{t} + c] = v;
    }
  }
  ISOSTREAM_RETURN_IF_ERROR(AssignTriangleSurfaces(&chunk));
  return Append(chunk, append_to);
}

absl::Status DecodeDracoPoints(const char* data, size_t size, std::vector<uint32_t> triangles,
                               uint32_t vertex_count, bool expect_normals, OrderedMesh* append_to) {
  uint32_t draco_points = 0;
  ISOSTREAM_RETURN_IF_ERROR(ReadDracoPointCloudCount(data, size, &draco_points));
  if (draco_points != vertex_count) {
    return absl::DataLossError(
        absl::StrCat("Draco payload holds ", draco_points, " points; expected ", vertex_count));
  }
  draco::DecoderBuffer buffer;
  buffer.Init(data, size);
  draco::Decoder decoder;
  draco::StatusOr<std::unique_ptr<draco::PointCloud>> decoded =
      decoder.DecodePointCloudFromBuffer(&buffer);
  if (!decoded.ok()) {
    return absl::DataLossError(
        absl::StrCat("Draco decoding failed: ", decoded.status().error_msg()));
  }
  if (decoded.value()->num_points() != vertex_count) {
    return absl::DataLossError("Draco decoded a different number of points than declared");
  }
  DecodedChunk chunk;
  ISOSTREAM_RETURN_IF_ERROR(
      ReadVertexAttributes(*decoded.value(), vertex_count, expect_normals, &chunk));
  for (uint32_t v : triangles) {
    if (v >= vertex_count) return absl::DataLossError("triangle index out of range");
  }
  chunk.triangles = std::move(triangles);
  ISOSTREAM_RETURN_IF_ERROR(AssignTriangleSurfaces(&chunk));
  return Append(chunk, append_to);
}

}  // namespace isostream::internal
