#include "shared/glb_writer.h"

#include <absl/strings/str_cat.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <exception>
#include <new>
#include <nlohmann/json.hpp>

#include "shared/file_io.h"
#include "shared/internal/chunk_gather.h"
#include "shared/internal/draco_mesh.h"
#include "shared/mesh_validate.h"

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "glb_writer assumes a little-endian host");

namespace isostream {
namespace {

using nlohmann::json;

constexpr uint32_t kGlbMagic = 0x46546C67;  // "glTF"
constexpr uint32_t kGlbVersion = 2;
constexpr uint32_t kChunkJson = 0x4E4F534A;  // "JSON"
constexpr uint32_t kChunkBin = 0x004E4942;   // "BIN\0"
constexpr size_t kGlbHeaderSize = 12;
constexpr size_t kGlbChunkHeaderSize = 8;
constexpr const char* kDracoExtension = "KHR_draco_mesh_compression";

// glTF componentType values.
constexpr int kUnsignedByte = 5121;
constexpr int kUnsignedShort = 5123;
constexpr int kUnsignedInt = 5125;
constexpr int kFloat = 5126;

template <typename T>
void AppendRaw(std::string* out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out->append(bytes, sizeof(T));
}

template <typename T>
T Load(const char* at) {
  T value;
  std::memcpy(&value, at, sizeof(T));
  return value;
}

size_t PadTo4(size_t n) { return (n + 3) & ~size_t{3}; }

void AppendGlbChunk(uint32_t type, const std::string& data, char pad, std::string* out) {
  const size_t padded = PadTo4(data.size());
  AppendRaw<uint32_t>(out, static_cast<uint32_t>(padded));
  AppendRaw<uint32_t>(out, type);
  out->append(data);
  out->append(padded - data.size(), pad);
}

std::string AssembleGlb(const json& document, const std::string& bin) {
  const std::string text = document.dump();
  std::string out;
  const size_t total = kGlbHeaderSize + kGlbChunkHeaderSize + PadTo4(text.size()) +
                       (bin.empty() ? 0 : kGlbChunkHeaderSize + PadTo4(bin.size()));
  out.reserve(total);
  AppendRaw<uint32_t>(&out, kGlbMagic);
  AppendRaw<uint32_t>(&out, kGlbVersion);
  AppendRaw<uint32_t>(&out, static_cast<uint32_t>(total));
  // The spec pads JSON with spaces and binary data with zeros.
  AppendGlbChunk(kChunkJson, text, ' ', &out);
  if (!bin.empty()) AppendGlbChunk(kChunkBin, bin, '\0', &out);
  return out;
}

json Accessor(size_t count, int component_type, const char* type) {
  return json{{"count", count}, {"componentType", component_type}, {"type", type}};
}

uint8_t ToUnorm8(float value) {
  const float clamped = std::clamp(std::isfinite(value) ? value : 0.0f, 0.0f, 1.0f);
  return static_cast<uint8_t>(std::lround(clamped * 255.0f));
}

absl::Status SerializeGlbUnguarded(const OrderedMesh& mesh, const GlbOptions& options,
                                   std::string* out) {
  ISOSTREAM_RETURN_IF_ERROR(ValidateMesh(mesh));
  ISOSTREAM_RETURN_IF_ERROR(internal::CheckCodecOptions(options.codec));
  if (!(options.meters_per_unit >= 0 && std::isfinite(options.meters_per_unit)))
    return absl::InvalidArgumentError("meters per unit must be a finite number >= 0");
  json document = {{"asset", {{"version", "2.0"}, {"generator", "isostream"}}}, {"scene", 0}};
  if (mesh.empty()) {
    // glTF forbids empty arrays, so the scene simply has no "nodes".
    document["scenes"] = json::array({json::object()});
    *out = AssembleGlb(document, "");
    return absl::OkStatus();
  }

  // gather and encode the whole mesh as one Draco mesh in triangle order
  internal::GatheredChunk chunk;
  ISOSTREAM_RETURN_IF_ERROR(internal::GatherTriangleRange(mesh, 0, mesh.triangle_count(), &chunk));
  if (options.codec.position_box && options.codec.position_bits > 0) {
    ISOSTREAM_RETURN_IF_ERROR(internal::CheckInsideBox(chunk, *options.codec.position_box));
  }
  internal::DracoEncodeSettings settings;
  settings.position_bits = options.codec.position_bits;
  settings.normal_bits = options.codec.normal_bits;
  settings.compress_connectivity = options.codec.compress_connectivity;
  settings.position_box = options.codec.position_box ? &*options.codec.position_box : nullptr;
  settings.mark_undefined_normals = false;
  for (const std::array<float, 4>& color : options.surface_colors) {
    settings.surface_colors.push_back(
        {ToUnorm8(color[0]), ToUnorm8(color[1]), ToUnorm8(color[2]), ToUnorm8(color[3])});
  }
  std::string draco_bytes;
  internal::DracoAttributeIds ids;
  ISOSTREAM_RETURN_IF_ERROR(internal::EncodeDracoMesh(chunk, settings, &draco_bytes, &ids));

  // POSITION min/max must describe the decoded (quantized) values, so decode and measure.
  const size_t vertex_count = chunk.vertex_count();
  const size_t triangle_count = chunk.triangle_count();
  const bool has_normals = ids.normal >= 0;
  OrderedMesh decoded;
  ISOSTREAM_RETURN_IF_ERROR(internal::DecodeDracoMesh(
      draco_bytes.data(), draco_bytes.size(), static_cast<uint32_t>(triangle_count),
      static_cast<uint32_t>(vertex_count), has_normals, &decoded));
  std::array<float, 3> low = {decoded.positions[0], decoded.positions[1], decoded.positions[2]};
  std::array<float, 3> high = low;
  for (size_t v = 0; v < vertex_count; ++v) {
    for (int k = 0; k < 3; ++k) {
      low[k] = std::min(low[k], decoded.positions[3 * v + k]);
      high[k] = std::max(high[k], decoded.positions[3 * v + k]);
    }
  }

  // accessors: definitions only; the data lives in the Draco buffer view
  json accessors = json::array();
  json attributes = json::object();
  json draco_attributes = json::object();
  auto add_attribute = [&](const char* semantic, json accessor, int unique_id) {
    attributes[semantic] = accessors.size();
    accessors.push_back(std::move(accessor));
    draco_attributes[semantic] = unique_id;
  };
  json position = Accessor(vertex_count, kFloat, "VEC3");
  position["min"] = low;
  position["max"] = high;
  add_attribute("POSITION", std::move(position), ids.position);
  if (has_normals) add_attribute("NORMAL", Accessor(vertex_count, kFloat, "VEC3"), ids.normal);
  add_attribute("_SURFACE", Accessor(vertex_count, kUnsignedByte, "SCALAR"), ids.surface);
  if (ids.color >= 0) {
    json color = Accessor(vertex_count, kUnsignedByte, "VEC4");
    color["normalized"] = true;
    add_attribute("COLOR_0", std::move(color), ids.color);
  }
  const size_t indices_accessor = accessors.size();
  accessors.push_back(
      Accessor(3 * triangle_count, vertex_count > 65535 ? kUnsignedInt : kUnsignedShort, "SCALAR"));

  // see the header: stock Draco 1.5.5 decoders need >= 3 bytes per face in the buffer view
  std::string bin = std::move(draco_bytes);
  bin.resize(std::max(bin.size(), 3 * triangle_count + 64), '\0');

  json primitive = {
      {"attributes", attributes},
      {"indices", indices_accessor},
      {"material", 0},
      {"mode", 4},
      {"extensions", {{kDracoExtension, {{"bufferView", 0}, {"attributes", draco_attributes}}}}}};
  json material = {{"name", "isosurface"},
                   {"pbrMetallicRoughness",
                    {{"baseColorFactor", {1.0, 1.0, 1.0, 1.0}},
                     {"metallicFactor", 0.0},
                     {"roughnessFactor", 1.0}}},
                   {"alphaMode", "BLEND"},
                   {"doubleSided", true}};
  document["extensionsUsed"] = {kDracoExtension};
  document["extensionsRequired"] = {kDracoExtension};
  document["scenes"] = json::array({json{{"nodes", {0}}}});
  json node = {{"mesh", 0}};
  // The vertices stay in the volume's units (as the daemon streams them); the node turns them
  // into glTF's meters.
  const double scale = options.meters_per_unit;
  if (scale > 0 && scale != 1) node["scale"] = {scale, scale, scale};
  document["nodes"] = json::array({node});
  document["meshes"] = json::array({json{{"primitives", json::array({primitive})}}});
  document["materials"] = json::array({material});
  document["accessors"] = std::move(accessors);
  document["bufferViews"] =
      json::array({json{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", bin.size()}}});
  document["buffers"] = json::array({json{{"byteLength", bin.size()}}});
  *out = AssembleGlb(document, bin);
  return absl::OkStatus();
}

// Reads the unsigned integer at document[key] or fails; keeps ParseGlb free of json throws.
bool GetIndex(const json& object, const char* key, size_t* value) {
  if (!object.is_object()) return false;
  const auto it = object.find(key);
  if (it == object.end() || !it->is_number_unsigned()) return false;
  *value = it->get<size_t>();
  return true;
}

absl::StatusOr<OrderedMesh> ParseGlbUnguarded(std::string_view bytes) {
  ISOSTREAM_ASSIGN_OR_RETURN(const GlbChunks chunks, ParseGlbChunks(bytes));
  const json document = json::parse(chunks.json, nullptr, /*allow_exceptions=*/false);
  if (document.is_discarded() || !document.is_object()) {
    return absl::InvalidArgumentError("GLB JSON chunk does not parse");
  }
  if (const auto required = document.find("extensionsRequired"); required != document.end()) {
    if (!required->is_array())
      return absl::InvalidArgumentError("extensionsRequired is not a list");
    for (const json& name : *required) {
      if (name != kDracoExtension) {
        return absl::UnimplementedError(absl::StrCat("GLB requires extension ", name.dump()));
      }
    }
  }
  OrderedMesh mesh;
  const auto meshes = document.find("meshes");
  if (meshes == document.end() || (meshes->is_array() && meshes->empty())) return mesh;
  if (!meshes->is_array() || meshes->size() != 1) {
    return absl::UnimplementedError("GLB must hold exactly one mesh");
  }
  const json& primitives = (*meshes)[0].value("primitives", json::array());
  if (!primitives.is_array() || primitives.size() != 1) {
    return absl::UnimplementedError("GLB mesh must have exactly one primitive");
  }
  const json& primitive = primitives[0];
  if (primitive.value("mode", 4) != 4) {
    return absl::UnimplementedError("GLB primitive is not a triangle list");
  }
  const json* extension = nullptr;
  if (const auto extensions = primitive.find("extensions");
      extensions != primitive.end() && extensions->is_object()) {
    if (const auto found = extensions->find(kDracoExtension); found != extensions->end()) {
      extension = &*found;
    }
  }
  if (!extension) return absl::UnimplementedError("GLB primitive is not Draco-compressed");

  const json& accessors = document.value("accessors", json::array());
  const json& views = document.value("bufferViews", json::array());
  const json& attributes = primitive.value("attributes", json::object());
  size_t view_index, position_accessor, indices_accessor, vertex_count, index_count;
  if (!GetIndex(*extension, "bufferView", &view_index) || view_index >= views.size() ||
      !GetIndex(attributes, "POSITION", &position_accessor) ||
      position_accessor >= accessors.size() ||
      !GetIndex(accessors[position_accessor], "count", &vertex_count) ||
      !GetIndex(primitive, "indices", &indices_accessor) || indices_accessor >= accessors.size() ||
      !GetIndex(accessors[indices_accessor], "count", &index_count) || index_count % 3 != 0) {
    return absl::InvalidArgumentError("GLB primitive lacks consistent accessors or buffer view");
  }
  size_t offset = 0, length = 0;
  const json& view = views[view_index];
  if (view.is_object() && view.contains("byteOffset") && !GetIndex(view, "byteOffset", &offset)) {
    return absl::InvalidArgumentError("bad bufferView byteOffset");
  }
  if (!GetIndex(view, "byteLength", &length) || offset > chunks.bin.size() ||
      length > chunks.bin.size() - offset) {
    return absl::InvalidArgumentError("Draco buffer view lies outside the BIN chunk");
  }
  const size_t triangle_count = index_count / 3;
  if (triangle_count > kMaxChunkTriangles || vertex_count > 3 * triangle_count) {
    return absl::InvalidArgumentError("GLB accessor counts are implausible");
  }
  const bool has_normals = attributes.contains("NORMAL");
  ISOSTREAM_RETURN_IF_ERROR(internal::DecodeDracoMesh(
      chunks.bin.data() + offset, length, static_cast<uint32_t>(triangle_count),
      static_cast<uint32_t>(vertex_count), has_normals, &mesh));
  return mesh;
}

}  // namespace

absl::Status SerializeGlb(const OrderedMesh& mesh, const GlbOptions& options, std::string* out) {
  try {
    return SerializeGlbUnguarded(mesh, options, out);
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError("out of memory while writing GLB");
  } catch (const std::exception& e) {
    return absl::InternalError(absl::StrCat("writing GLB threw: ", e.what()));
  }
}

absl::Status WriteGlb(const OrderedMesh& mesh, const std::string& path, const GlbOptions& options) {
  std::string bytes;
  ISOSTREAM_RETURN_IF_ERROR(PrefixStatus(path, SerializeGlb(mesh, options, &bytes)));
  return WriteFileBytes(path, bytes);
}

absl::StatusOr<GlbChunks> ParseGlbChunks(std::string_view bytes) {
  if (bytes.size() < kGlbHeaderSize + kGlbChunkHeaderSize) {
    return absl::InvalidArgumentError("too short for a GLB file");
  }
  const char* data = bytes.data();
  if (Load<uint32_t>(data) != kGlbMagic) return absl::InvalidArgumentError("not a GLB file");
  if (Load<uint32_t>(data + 4) != kGlbVersion) {
    return absl::InvalidArgumentError("GLB version is not 2");
  }
  if (Load<uint32_t>(data + 8) != bytes.size()) {
    return absl::InvalidArgumentError(absl::StrCat("GLB header declares ", Load<uint32_t>(data + 8),
                                                   " bytes; file has ", bytes.size()));
  }
  GlbChunks chunks;
  size_t pos = kGlbHeaderSize;
  for (int index = 0; pos < bytes.size(); ++index) {
    if (bytes.size() - pos < kGlbChunkHeaderSize) {
      return absl::InvalidArgumentError("GLB ends inside a chunk header");
    }
    const uint32_t length = Load<uint32_t>(data + pos);
    const uint32_t type = Load<uint32_t>(data + pos + 4);
    pos += kGlbChunkHeaderSize;
    if (length > bytes.size() - pos || length % 4 != 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("GLB chunk ", index, " has bad length ", length));
    }
    if (index == 0 && type != kChunkJson) {
      return absl::InvalidArgumentError("first GLB chunk is not JSON");
    }
    if (index == 0) chunks.json.assign(data + pos, length);
    if (index == 1 && type == kChunkBin) chunks.bin.assign(data + pos, length);
    pos += length;
  }
  return chunks;
}

absl::StatusOr<OrderedMesh> ParseGlb(std::string_view bytes) {
  try {
    return ParseGlbUnguarded(bytes);
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError("out of memory while reading GLB");
  } catch (const std::exception& e) {
    return absl::InvalidArgumentError(absl::StrCat("malformed GLB: ", e.what()));
  }
}

}  // namespace isostream
