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
#include <functional>
#include <memory>
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

// The mesh the primitive's Draco extension holds, decoded by Draco itself; its attributes are
// looked up by the unique ids the extension names.
struct DecodedPrimitive {
  std::unique_ptr<draco::Mesh> mesh;
  const draco::PointAttribute* Attribute(const ParsedGlb& glb, const char* name) const {
    const json& extension = glb.document["meshes"][0]["primitives"][0]["extensions"][kDraco];
    return mesh->GetAttributeByUniqueId(extension["attributes"][name].get<uint32_t>());
  }
};
DecodedPrimitive Decode(const ParsedGlb& glb) {
  const json& extension = glb.document["meshes"][0]["primitives"][0]["extensions"][kDraco];
  const json& view = glb.document["bufferViews"][extension["bufferView"].get<size_t>()];
  draco::DecoderBuffer buffer;
  buffer.Init(glb.bin.data() + view.value("byteOffset", size_t{0}),
              view["byteLength"].get<size_t>());
  draco::Decoder decoder;
  auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
  EXPECT_TRUE(decoded.ok()) << decoded.status().error_msg();
  return {decoded.ok() ? std::move(decoded).value() : nullptr};
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
  const DecodedPrimitive decoded = Decode(glb);
  ASSERT_NE(decoded.mesh, nullptr);
  const draco::Mesh& draco_mesh = *decoded.mesh;
  const draco::PointAttribute* surface = decoded.Attribute(glb, "_SURFACE");
  const draco::PointAttribute* color = decoded.Attribute(glb, "COLOR_0");
  const draco::PointAttribute* position = decoded.Attribute(glb, "POSITION");
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

// glTF's unit is the meter. A volume in millimetres keeps its coordinates (as the daemon streams
// them) and the node scales them; no unit, or meters already, adds no scale.
TEST(MeshGlb, AKnownUnitBecomesTheNodesScaleToMeters) {
  const OrderedMesh mesh = MakeGrid(5, 1);
  GlbOptions mm;
  mm.meters_per_unit = 1e-3;
  const ParsedGlb glb = Parse(Serialize(mesh, mm));
  ASSERT_EQ(glb.document["nodes"].size(), 1u);
  EXPECT_EQ(glb.document["nodes"][0]["scale"], json::array({1e-3, 1e-3, 1e-3}));
  const absl::StatusOr<OrderedMesh> decoded = ParseGlb(Serialize(mesh, mm));
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  const absl::StatusOr<OrderedMesh> unscaled = ParseGlb(Serialize(mesh, GlbOptions{}));
  ASSERT_TRUE(unscaled.ok()) << unscaled.status();
  EXPECT_EQ(decoded->positions, unscaled->positions);  // the vertices are not scaled
  for (const double none : {0.0, 1.0}) {
    GlbOptions options;
    options.meters_per_unit = none;
    EXPECT_FALSE(Parse(Serialize(mesh, options)).document["nodes"][0].contains("scale")) << none;
  }
  ScratchDir dir;
  for (const double bad : {-1e-3, std::nan(""), HUGE_VAL}) {
    GlbOptions options;
    options.meters_per_unit = bad;
    EXPECT_EQ(WriteGlb(mesh, dir.File("unit.glb"), options).code(),
              absl::StatusCode::kInvalidArgument)
        << bad;
  }
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

// A GLB container around `document` and `bin` built here, not by the writer: each chunk padded
// to 4 bytes unless `pad` is false, the BIN chunk given `bin_type`.
std::string Container(const json& document, const std::string& bin, bool pad = true,
                      uint32_t bin_type = 0x004E4942) {
  std::string text = document.dump();
  if (pad) text.append((4 - text.size() % 4) % 4, ' ');
  std::string padded_bin = bin;
  padded_bin.append((4 - padded_bin.size() % 4) % 4, '\0');
  auto u32 = [](std::string* out, uint32_t v) {
    out->append(reinterpret_cast<const char*>(&v), 4);
  };
  std::string out;
  u32(&out, 0x46546C67);
  u32(&out, 2);
  u32(&out, uint32_t(12 + 8 + text.size() + 8 + padded_bin.size()));
  u32(&out, uint32_t(text.size()));
  u32(&out, 0x4E4F534A);
  out += text;
  u32(&out, uint32_t(padded_bin.size()));
  u32(&out, bin_type);
  out += padded_bin;
  return out;
}

// Colours are stored as 8-bit unorms: what is past [0, 1] is clamped, not wrapped, and what is
// not a number is 0.
TEST(MeshGlb, ColoursOutsideZeroToOneAreClamped) {
  GlbOptions options;
  options.surface_colors = {{2.0f, -1.0f, NAN, 0.5f}};
  const ParsedGlb glb = Parse(Serialize(MakeGrid(3), options));
  const DecodedPrimitive decoded = Decode(glb);
  ASSERT_NE(decoded.mesh, nullptr);
  const draco::PointAttribute* color = decoded.Attribute(glb, "COLOR_0");
  ASSERT_NE(color, nullptr);
  for (uint32_t p = 0; p < decoded.mesh->num_points(); ++p) {
    uint8_t rgba[4];
    color->GetMappedValue(draco::PointIndex(p), rgba);
    ASSERT_EQ(rgba[0], 255) << "point " << p;
    ASSERT_EQ(rgba[1], 0) << "point " << p;
    ASSERT_EQ(rgba[2], 0) << "point " << p;
    ASSERT_EQ(rgba[3], 128) << "point " << p;
  }
}

// The indices accessor's component type can hold every vertex index (glTF: UNSIGNED_SHORT up to
// 65535 vertices, UNSIGNED_INT past that), as a loader that reads accessors sizes its buffers.
TEST(MeshGlb, IndexComponentTypeHoldsEveryVertex) {
  for (const int n : {8, 260}) {  // 81 and 68,121 vertices
    SCOPED_TRACE(n);
    const OrderedMesh mesh = MakeGrid(n);
    const ParsedGlb glb = Parse(Serialize(mesh, GlbOptions{}));
    const json& primitive = glb.document["meshes"][0]["primitives"][0];
    const json& indices = glb.document["accessors"][primitive["indices"].get<size_t>()];
    const json& position =
        glb.document["accessors"][primitive["attributes"]["POSITION"].get<size_t>()];
    ASSERT_EQ(position["count"].get<size_t>(), mesh.vertex_count());
    EXPECT_EQ(indices["componentType"], mesh.vertex_count() > 65535 ? 5125 : 5123);
  }
}

// Documents the reader cannot take as written are refused with the reason, not read otherwise
// (a buffer view past its chunk read beyond the file's bytes).
TEST(MeshGlb, DocumentsItCannotReadAreRefusedWithTheReason) {
  const OrderedMesh mesh = MakeGrid(8);
  const ParsedGlb glb = Parse(Serialize(mesh, GlbOptions{}));
  ASSERT_TRUE(ParseGlb(Container(glb.document, glb.bin)).ok());  // the container itself reads
  auto refused = [&](const std::string& bytes, absl::StatusCode code, const std::string& message) {
    const absl::StatusOr<OrderedMesh> parsed = ParseGlb(bytes);
    ASSERT_FALSE(parsed.ok()) << message;
    EXPECT_EQ(parsed.status().code(), code) << parsed.status();
    EXPECT_EQ(parsed.status().message(), message);
  };
  auto edited = [&](const std::function<void(json&)>& edit) {
    json document = glb.document;
    edit(document);
    return Container(document, glb.bin);
  };
  refused(edited([](json& d) { d["extensionsRequired"].push_back("KHR_materials_volume"); }),
          absl::StatusCode::kUnimplemented, "GLB requires extension \"KHR_materials_volume\"");
  refused(edited([](json& d) { d["meshes"][0]["primitives"][0]["mode"] = 5; }),
          absl::StatusCode::kUnimplemented, "GLB primitive is not a triangle list");
  const size_t indices = glb.document["meshes"][0]["primitives"][0]["indices"].get<size_t>();
  refused(edited([&](json& d) {
            d["accessors"][indices]["count"] = 3 * mesh.triangle_count() - 3 + 1;
          }),
          absl::StatusCode::kInvalidArgument,
          "GLB primitive lacks consistent accessors or buffer view");
  const size_t position =
      glb.document["meshes"][0]["primitives"][0]["attributes"]["POSITION"].get<size_t>();
  refused(
      edited([&](json& d) { d["accessors"][position]["count"] = 3 * mesh.triangle_count() + 1; }),
      absl::StatusCode::kInvalidArgument, "GLB accessor counts are implausible");
  refused(edited([&](json& d) { d["bufferViews"][0]["byteLength"] = glb.bin.size() + 4; }),
          absl::StatusCode::kInvalidArgument, "Draco buffer view lies outside the BIN chunk");
  // The second chunk is the buffer only if it says it is BIN.
  refused(Container(glb.document, glb.bin, true, 0x5A5A5A5A), absl::StatusCode::kInvalidArgument,
          "Draco buffer view lies outside the BIN chunk");

  // The container: chunks are 4-byte aligned, and the header's length is the file's.
  json odd = glb.document;
  odd["asset"]["generator"] = "isostream";
  std::string text = odd.dump();
  if (text.size() % 4 == 0) odd["asset"]["generator"] = "isostream!";
  text = odd.dump();
  ASSERT_NE(text.size() % 4, 0u);
  refused(Container(odd, glb.bin, /*pad=*/false), absl::StatusCode::kInvalidArgument,
          "GLB chunk 0 has bad length " + std::to_string(text.size()));
  const std::string whole = Container(glb.document, glb.bin);
  std::string longer = whole + std::string(8, '\0');  // an empty chunk the header does not count
  refused(longer, absl::StatusCode::kInvalidArgument,
          "GLB header declares " + std::to_string(whole.size()) + " bytes; file has " +
              std::to_string(longer.size()));
}

// The spec pads the JSON chunk with spaces: a JSON parser stricter than ours stops at a NUL.
TEST(MeshGlb, TheJsonChunkIsPaddedWithSpaces) {
  int padded = 0;
  for (int n = 1; n <= 6; ++n) {
    const absl::StatusOr<GlbChunks> chunks = ParseGlbChunks(Serialize(MakeGrid(n), GlbOptions{}));
    ASSERT_TRUE(chunks.ok()) << chunks.status();
    const size_t end = chunks->json.find_last_of('}');
    ASSERT_NE(end, std::string::npos);
    padded += end + 1 < chunks->json.size();
    EXPECT_EQ(chunks->json.substr(end + 1), std::string(chunks->json.size() - end - 1, ' ')) << n;
  }
  EXPECT_GT(padded, 0);  // some of them needed padding
}

// A mesh that cannot be written is refused naming the file it was for.
TEST(MeshGlb, ARefusedWriteNamesTheFile) {
  ScratchDir dir;
  OrderedMesh bad = MakeGrid(2);
  bad.surface[1] = kMaxSurfaces;
  const std::string path = dir.File("named.glb");
  const absl::Status s = WriteGlb(bad, path);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(std::string(s.message()).rfind(path + ": ", 0), 0u) << s;
}

// At 65,536 vertices the largest index is 65,535, which glTF reserves in UNSIGNED_SHORT indices
// (primitive restart): the indices are UNSIGNED_INT from there.
TEST(MeshGlb, SixtyFiveThousandFiveHundredThirtySixVerticesTakeIntIndices) {
  const OrderedMesh mesh = MakeGrid(255);  // 256 x 256 vertices
  ASSERT_EQ(mesh.vertex_count(), 65536u);
  const ParsedGlb glb = Parse(Serialize(mesh, GlbOptions{}));
  const json& primitive = glb.document["meshes"][0]["primitives"][0];
  EXPECT_EQ(glb.document["accessors"][primitive["indices"].get<size_t>()]["componentType"], 5125);
}

// The Draco buffer view holds at least 3 bytes per face plus 64 (glb_writer.h: Draco 1.5.5
// decoders refuse a shorter one), however well the mesh compresses.
TEST(MeshGlb, TheDracoViewIsPaddedToThreeBytesPerFacePlus64) {
  GlbOptions coarse;  // few bits, no normals: Draco's bytes fall below the padding
  coarse.codec.position_bits = 4;
  int compressed_below = 0;
  for (const int n : {2, 8, 30}) {
    OrderedMesh mesh = MakeGrid(n);
    mesh.normals.clear();
    const ParsedGlb glb = Parse(Serialize(mesh, coarse));
    const size_t length = glb.document["bufferViews"][0]["byteLength"].get<size_t>();
    EXPECT_GE(length, 3 * mesh.triangle_count() + 64) << n;
    EXPECT_EQ(glb.document["buffers"][0]["byteLength"].get<size_t>(), length);
    compressed_below += length == 3 * mesh.triangle_count() + 64;
  }
  EXPECT_GT(compressed_below, 0) << "some mesh should compress below the padding";
}

// POSITION's bounds cover every vertex, the last one too.
TEST(MeshGlb, BoundsCoverTheLastVertex) {
  OrderedMesh mesh;
  mesh.positions = {0, 0, 0, 1, 0, 0, 0, 1, 0, 2.5f, 3.5f, 4.5f};
  mesh.normals = {0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1};
  mesh.triangles = {0, 1, 2, 1, 3, 2};
  mesh.surface = {0, 0};
  const ParsedGlb glb = Parse(Serialize(mesh, GlbOptions{}));
  const json& primitive = glb.document["meshes"][0]["primitives"][0];
  const json& position =
      glb.document["accessors"][primitive["attributes"]["POSITION"].get<size_t>()];
  const std::vector<float> high = position["max"].get<std::vector<float>>();
  ASSERT_EQ(high.size(), 3u);
  EXPECT_NEAR(high[0], 2.5f, 0.01f);
  EXPECT_NEAR(high[1], 3.5f, 0.01f);
  EXPECT_NEAR(high[2], 4.5f, 0.01f);
}

// An empty list of meshes is an empty mesh; two meshes are refused, not read as the first.
TEST(MeshGlb, NoMeshesReadEmptyAndTwoAreRefused) {
  const ParsedGlb glb = Parse(Serialize(MakeGrid(4), GlbOptions{}));
  json none = glb.document;
  none["meshes"] = json::array();
  const absl::StatusOr<OrderedMesh> empty = ParseGlb(Container(none, glb.bin));
  ASSERT_TRUE(empty.ok()) << empty.status();
  EXPECT_TRUE(empty->empty());
  json two = glb.document;
  two["meshes"].push_back(two["meshes"][0]);
  const absl::StatusOr<OrderedMesh> parsed = ParseGlb(Container(two, glb.bin));
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.status().code(), absl::StatusCode::kUnimplemented);
  EXPECT_EQ(parsed.status().message(), "GLB must hold exactly one mesh");
}

// What the reader takes as glTF says, and refuses otherwise: a primitive without a mode is a
// triangle list (glTF's default); a mesh of two primitives is refused; a buffer view inside the
// BIN chunk by its length but not by its offset plus length is outside it; the buffer is the
// second chunk, not a later one.
TEST(MeshGlb, PrimitivesViewsAndChunksAsGltfSays) {
  const OrderedMesh mesh = MakeGrid(4);
  const ParsedGlb glb = Parse(Serialize(mesh, GlbOptions{}));
  auto edited = [&](const std::function<void(json&)>& edit) {
    json document = glb.document;
    edit(document);
    return Container(document, glb.bin);
  };
  const absl::StatusOr<OrderedMesh> no_mode =
      ParseGlb(edited([](json& d) { d["meshes"][0]["primitives"][0].erase("mode"); }));
  ASSERT_TRUE(no_mode.ok()) << no_mode.status();
  EXPECT_EQ(no_mode->triangle_count(), mesh.triangle_count());

  auto refused = [&](const std::string& bytes, absl::StatusCode code, const std::string& message) {
    const absl::StatusOr<OrderedMesh> parsed = ParseGlb(bytes);
    ASSERT_FALSE(parsed.ok()) << message;
    EXPECT_EQ(parsed.status().code(), code) << parsed.status();
    EXPECT_EQ(parsed.status().message(), message);
  };
  refused(edited([](json& d) {
            json& primitives = d["meshes"][0]["primitives"];
            primitives.push_back(primitives[0]);
          }),
          absl::StatusCode::kUnimplemented, "GLB mesh must have exactly one primitive");
  refused(edited([&](json& d) {
            d["bufferViews"][0]["byteOffset"] = 4;
            d["bufferViews"][0]["byteLength"] = glb.bin.size();
          }),
          absl::StatusCode::kInvalidArgument, "Draco buffer view lies outside the BIN chunk");

  refused(edited([](json& d) { d["bufferViews"][0]["byteOffset"] = -4; }),
          absl::StatusCode::kInvalidArgument, "bad bufferView byteOffset");

  // The buffer as a third chunk, after a second that is not BIN.
  std::string third = Container(glb.document, glb.bin, true, 0x5A5A5A5A);
  const uint32_t length = uint32_t(glb.bin.size()), bin_type = 0x004E4942;
  ASSERT_EQ(length % 4, 0u);
  third.append(reinterpret_cast<const char*>(&length), 4);
  third.append(reinterpret_cast<const char*>(&bin_type), 4);
  third += glb.bin;
  const uint32_t total = uint32_t(third.size());
  std::memcpy(third.data() + 8, &total, 4);
  const absl::StatusOr<GlbChunks> chunks = ParseGlbChunks(third);
  ASSERT_TRUE(chunks.ok()) << chunks.status();
  EXPECT_TRUE(chunks->bin.empty());
  refused(third, absl::StatusCode::kInvalidArgument,
          "Draco buffer view lies outside the BIN chunk");
}

// A header alone, whose length is the file's, is too short: a GLB holds a JSON chunk.
TEST(MeshGlb, AHeaderAloneIsTooShort) {
  std::string header;
  for (const uint32_t v : {0x46546C67u, 2u, 12u})
    header.append(reinterpret_cast<const char*>(&v), 4);
  const absl::StatusOr<GlbChunks> chunks = ParseGlbChunks(header);
  ASSERT_FALSE(chunks.ok());
  EXPECT_EQ(chunks.status().message(), "too short for a GLB file");
}

}  // namespace
}  // namespace isostream
