// GLB writer: the container and JSON follow glTF 2.0 and KHR_draco_mesh_compression, the Draco
// buffer decodes to the same triangles in the same order, Draco's own glTF reader loads the file,
// and malformed files are rejected.
#include <draco/compression/decode.h>
#include <draco/io/mesh_io.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "mesh_test_meshes.h"
#include "shared/file_io.h"
#include "shared/glb_writer.h"

namespace isostream {
namespace {

using nlohmann::json;
using testing::Concatenate;
using testing::ExpectSameTrianglesInOrder;
using testing::MakeGrid;
using testing::MakeSphere;
using testing::ScratchDir;
using testing::Shuffled;

constexpr const char* kDraco = "KHR_draco_mesh_compression";

// Two nested spheres on surfaces 0 and 2, interleaved by a shuffle so surface order matters.
OrderedMesh TwoSurfaces() {
  const float center[3] = {0.2f, 0.1f, -0.3f};
  return Shuffled(
      Concatenate(MakeSphere(3000, 1.0f, nullptr, 0), MakeSphere(2000, 0.4f, center, 2)), 17);
}

GlbOptions ColouredOptions() {
  GlbOptions options;
  options.surface_colors = {
      {1.0f, 0.0f, 0.0f, 0.25f}, {0.0f, 1.0f, 0.0f, 0.5f}, {0.0f, 0.0f, 1.0f, 1.0f}};
  return options;
}

struct ParsedGlb {
  json document;
  std::string bin;
};

ParsedGlb Parse(const std::string& bytes) {
  const absl::StatusOr<GlbChunks> chunks = ParseGlbChunks(bytes);
  EXPECT_TRUE(chunks.ok()) << chunks.status();
  if (!chunks.ok()) return {};
  ParsedGlb parsed{json::parse(chunks->json, nullptr, false), chunks->bin};
  EXPECT_FALSE(parsed.document.is_discarded());
  return parsed;
}

std::string Serialize(const OrderedMesh& mesh, const GlbOptions& options) {
  std::string bytes;
  const absl::Status status = SerializeGlb(mesh, options, &bytes);
  EXPECT_TRUE(status.ok()) << status;
  return bytes;
}

bool Contains(const json& list, const char* name) {
  return list.is_array() && std::find(list.begin(), list.end(), name) != list.end();
}

TEST(MeshGlb, StructureFollowsTheKhrDracoSpec) {
  const OrderedMesh mesh = TwoSurfaces();
  const std::string bytes = Serialize(mesh, ColouredOptions());
  ASSERT_EQ(bytes.size() % 4, 0u);
  const ParsedGlb glb = Parse(bytes);
  const json& doc = glb.document;
  EXPECT_EQ(doc["asset"]["version"], "2.0");
  EXPECT_TRUE(Contains(doc["extensionsUsed"], kDraco));
  EXPECT_TRUE(Contains(doc["extensionsRequired"], kDraco));
  ASSERT_EQ(doc["meshes"].size(), 1u);
  ASSERT_EQ(doc["meshes"][0]["primitives"].size(), 1u);
  const json& primitive = doc["meshes"][0]["primitives"][0];
  EXPECT_EQ(primitive["mode"], 4);

  const json& accessors = doc["accessors"];
  const json& attributes = primitive["attributes"];
  for (const char* name : {"POSITION", "NORMAL", "_SURFACE", "COLOR_0"}) {
    ASSERT_TRUE(attributes.contains(name)) << name;
    const json& accessor = accessors[attributes[name].get<size_t>()];
    // Draco-compressed accessors are definitions only: the extension supplies the data.
    EXPECT_FALSE(accessor.contains("bufferView")) << name;
    EXPECT_TRUE(accessor.contains("count") && accessor.contains("componentType") &&
                accessor.contains("type"))
        << name;
  }
  const json& position = accessors[attributes["POSITION"].get<size_t>()];
  EXPECT_EQ(position["type"], "VEC3");
  EXPECT_EQ(position["componentType"], 5126);
  ASSERT_EQ(position["min"].size(), 3u);
  ASSERT_EQ(position["max"].size(), 3u);
  const json& color = accessors[attributes["COLOR_0"].get<size_t>()];
  EXPECT_EQ(color["type"], "VEC4");
  EXPECT_EQ(color["normalized"], true);
  const json& indices = accessors[primitive["indices"].get<size_t>()];
  EXPECT_FALSE(indices.contains("bufferView"));
  EXPECT_EQ(indices["count"], 3 * mesh.triangle_count());
  EXPECT_EQ(indices["type"], "SCALAR");

  const json& extension = primitive["extensions"][kDraco];
  for (const auto& [name, accessor] : attributes.items()) {
    EXPECT_TRUE(extension["attributes"].contains(name)) << name;
  }
  const json& view = doc["bufferViews"][extension["bufferView"].get<size_t>()];
  EXPECT_GE(view["byteLength"].get<size_t>(), 3 * mesh.triangle_count() + 64);
  EXPECT_LE(view.value("byteOffset", size_t{0}) + view["byteLength"].get<size_t>(), glb.bin.size());
  EXPECT_EQ(doc["buffers"][0]["byteLength"], view["byteLength"]);

  const json& material = doc["materials"][primitive["material"].get<size_t>()];
  EXPECT_EQ(material["alphaMode"], "BLEND");
  EXPECT_EQ(material["doubleSided"], true);
  EXPECT_EQ(doc["scenes"][doc["scene"].get<size_t>()]["nodes"].size(), 1u);
}

TEST(MeshGlb, DracoBufferDecodesToTheSameTrianglesInOrder) {
  const OrderedMesh mesh = TwoSurfaces();
  const std::string bytes = Serialize(mesh, ColouredOptions());
  const absl::StatusOr<OrderedMesh> decoded = ParseGlb(bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  ASSERT_EQ(decoded->triangle_count(), mesh.triangle_count());
  EXPECT_EQ(decoded->surface, mesh.surface);
  QuantizationBox cube = BoundingCube(mesh.positions.data(), mesh.vertex_count());
  ExpectSameTrianglesInOrder(mesh, 0, mesh.triangle_count(), *decoded, 0,
                             PositionErrorBound(cube, 14), NormalErrorBound(10));
}

TEST(MeshGlb, AttributeIdsColoursAndBoundsMatchTheDracoData) {
  const OrderedMesh mesh = TwoSurfaces();
  const GlbOptions options = ColouredOptions();
  const ParsedGlb glb = Parse(Serialize(mesh, options));
  const json& primitive = glb.document["meshes"][0]["primitives"][0];
  const json& extension = primitive["extensions"][kDraco];
  const json& view = glb.document["bufferViews"][extension["bufferView"].get<size_t>()];

  // Decode with Draco directly and look attributes up by the unique ids the extension names.
  draco::DecoderBuffer buffer;
  buffer.Init(glb.bin.data() + view.value("byteOffset", size_t{0}),
              view["byteLength"].get<size_t>());
  draco::Decoder decoder;
  auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
  ASSERT_TRUE(decoded.ok()) << decoded.status().error_msg();
  const draco::Mesh& draco_mesh = *decoded.value();
  auto attribute = [&](const char* name) {
    return draco_mesh.GetAttributeByUniqueId(extension["attributes"][name].get<uint32_t>());
  };
  const draco::PointAttribute* surface = attribute("_SURFACE");
  const draco::PointAttribute* color = attribute("COLOR_0");
  const draco::PointAttribute* position = attribute("POSITION");
  ASSERT_TRUE(surface && color && position);
  EXPECT_EQ(surface->attribute_type(), draco::GeometryAttribute::GENERIC);
  EXPECT_EQ(color->attribute_type(), draco::GeometryAttribute::COLOR);
  EXPECT_EQ(position->attribute_type(), draco::GeometryAttribute::POSITION);

  const json& accessor =
      glb.document["accessors"][primitive["attributes"]["POSITION"].get<size_t>()];
  float low[3] = {INFINITY, INFINITY, INFINITY}, high[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (uint32_t p = 0; p < draco_mesh.num_points(); ++p) {
    uint8_t s = 0, rgba[4];
    float xyz[3];
    surface->GetMappedValue(draco::PointIndex(p), &s);
    color->GetMappedValue(draco::PointIndex(p), rgba);
    position->GetMappedValue(draco::PointIndex(p), xyz);
    ASSERT_LT(s, options.surface_colors.size());
    for (int k = 0; k < 4; ++k) {
      ASSERT_EQ(rgba[k], std::lround(options.surface_colors[s][k] * 255.0f)) << "point " << p;
    }
    for (int k = 0; k < 3; ++k) {
      low[k] = std::min(low[k], xyz[k]);
      high[k] = std::max(high[k], xyz[k]);
    }
  }
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(accessor["min"][k].get<float>(), low[k]);
    EXPECT_EQ(accessor["max"][k].get<float>(), high[k]);
  }
}

TEST(MeshGlb, DracosOwnGltfReaderLoadsTheFile) {
  const OrderedMesh mesh = TwoSurfaces();
  ScratchDir dir;
  const std::string path = dir.File("two_surfaces.glb");
  ASSERT_TRUE(WriteGlb(mesh, path, ColouredOptions()).ok());
  const auto loaded = draco::ReadMeshFromFile(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status().error_msg();
  EXPECT_EQ(loaded.value()->num_faces(), mesh.triangle_count());
}

TEST(MeshGlb, OptionalAttributesFollowTheInput) {
  OrderedMesh bare = MakeGrid(5, 1);
  bare.normals.clear();
  const ParsedGlb glb = Parse(Serialize(bare, GlbOptions{}));
  const json& attributes = glb.document["meshes"][0]["primitives"][0]["attributes"];
  EXPECT_TRUE(attributes.contains("POSITION"));
  EXPECT_TRUE(attributes.contains("_SURFACE"));
  EXPECT_FALSE(attributes.contains("NORMAL"));
  EXPECT_FALSE(attributes.contains("COLOR_0"));
  const absl::StatusOr<OrderedMesh> decoded = ParseGlb(Serialize(bare, GlbOptions{}));
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  EXPECT_EQ(decoded->surface, bare.surface);
}

TEST(MeshGlb, EmptyMeshGivesAValidEmptyScene) {
  const std::string bytes = Serialize(OrderedMesh{}, GlbOptions{});
  const ParsedGlb glb = Parse(bytes);
  EXPECT_EQ(glb.document["asset"]["version"], "2.0");
  EXPECT_FALSE(glb.document.contains("meshes"));
  const absl::StatusOr<OrderedMesh> decoded = ParseGlb(bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  EXPECT_TRUE(decoded->empty());
}

TEST(MeshGlb, InvalidMeshesAreNotWritten) {
  ScratchDir dir;
  OrderedMesh bad = MakeGrid(2);
  bad.surface[1] = kMaxSurfaces;
  const std::string path = dir.File("bad.glb");
  EXPECT_EQ(WriteGlb(bad, path).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_FALSE(std::filesystem::exists(path));
  GlbOptions options;
  options.codec.position_bits = 40;
  EXPECT_EQ(WriteGlb(MakeGrid(2), path, options).code(), absl::StatusCode::kInvalidArgument);
}

TEST(MeshGlb, MalformedFilesAreRejected) {
  const std::string bytes = Serialize(MakeGrid(8), GlbOptions{});
  for (size_t length = 0; length < bytes.size(); length += 7) {
    EXPECT_FALSE(ParseGlb(bytes.substr(0, length)).ok()) << "length " << length;
  }
  std::string edited = bytes;
  edited[0] = 'x';
  EXPECT_FALSE(ParseGlbChunks(edited).ok());
  edited = bytes;
  edited[4] = 1;  // version
  EXPECT_FALSE(ParseGlbChunks(edited).ok());
  // Corrupt the JSON text and, separately, the Draco data.
  edited = bytes;
  edited[21] = '}';
  EXPECT_FALSE(ParseGlb(edited).ok());
  uint32_t json_length = 0;
  std::memcpy(&json_length, bytes.data() + 12, 4);
  edited = bytes;
  for (size_t i = 20 + json_length + 8; i < 20 + json_length + 40; ++i) edited[i] = '\x7f';
  EXPECT_FALSE(ParseGlb(edited).ok());
}

}  // namespace
}  // namespace isostream
