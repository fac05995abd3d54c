// PLY reading and writing: exact round trips in both encodings, files from other writers, and
// clear errors (never crashes) for missing files, bad headers, truncation and bad indices.
#include <draco/io/mesh_io.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>

#include "mesh_test_meshes.h"
#include "shared/file_io.h"
#include "shared/ply_io.h"

namespace isostream {
namespace {

using testing::MakeGrid;
using testing::MakeSphere;
using testing::ScratchDir;
using testing::Shuffled;

// Values that stress shortest-form float printing: tiny, huge, negative zero, many digits.
OrderedMesh AwkwardMesh() {
  OrderedMesh mesh = Shuffled(MakeSphere(500), 3);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> jitter(-1.0f, 1.0f);
  for (float& p : mesh.positions) p = p * 1234.5678f + jitter(rng) * 1e-3f;
  mesh.positions[0] = 1e-38f;
  mesh.positions[1] = -0.0f;
  mesh.positions[2] = 3.4e38f;
  mesh.positions[3] = std::numeric_limits<float>::denorm_min();
  mesh.positions[4] = 0.1f;
  for (size_t t = 0; t < mesh.triangle_count(); ++t) mesh.surface[t] = t % kMaxSurfaces;
  return mesh;
}

void ExpectIdentical(const OrderedMesh& expected, const OrderedMesh& actual) {
  ASSERT_EQ(actual.positions.size(), expected.positions.size());
  for (size_t i = 0; i < expected.positions.size(); ++i) {
    // Bitwise, so -0.0 and denormals count.
    ASSERT_EQ(std::signbit(actual.positions[i]), std::signbit(expected.positions[i])) << i;
    ASSERT_EQ(actual.positions[i], expected.positions[i]) << i;
  }
  EXPECT_EQ(actual.normals, expected.normals);
  EXPECT_EQ(actual.triangles, expected.triangles);
  EXPECT_EQ(actual.surface, expected.surface);
}

std::string Serialize(const OrderedMesh& mesh, bool binary) {
  std::string bytes;
  const absl::Status status = SerializePly(mesh, binary, &bytes);
  EXPECT_TRUE(status.ok()) << status;
  return bytes;
}

TEST(MeshPly, BinaryAndAsciiRoundTripExactly) {
  const OrderedMesh mesh = AwkwardMesh();
  ScratchDir dir;
  for (bool binary : {true, false}) {
    const std::string path = dir.File(binary ? "mesh_bin.ply" : "mesh_ascii.ply");
    ASSERT_TRUE(WritePly(mesh, path, binary).ok());
    const absl::StatusOr<OrderedMesh> read = ReadPly(path);
    ASSERT_TRUE(read.ok()) << read.status();
    ExpectIdentical(mesh, *read);
  }
}

TEST(MeshPly, BinaryLayoutIsTheDocumentedOne) {
  const OrderedMesh mesh = MakeGrid(2, 7);
  const std::string bytes = Serialize(mesh, true);
  const size_t header_end = bytes.find("end_header\n") + 11;
  const std::string header = bytes.substr(0, header_end);
  EXPECT_NE(header.find("format binary_little_endian 1.0\n"), std::string::npos);
  EXPECT_NE(header.find("element vertex 9\nproperty float x\nproperty float y\nproperty float "
                        "z\nproperty float nx\nproperty float ny\nproperty float nz\n"),
            std::string::npos);
  EXPECT_NE(header.find("element face 8\nproperty list uchar uint vertex_indices\nproperty "
                        "uchar surface\nend_header\n"),
            std::string::npos);
  EXPECT_EQ(bytes.size(), header_end + 9 * 24 + 8 * 14);
  // First face: count 3, indices 0 1 3, surface 7.
  const char* face = bytes.data() + header_end + 9 * 24;
  uint32_t indices[3];
  std::memcpy(indices, face + 1, 12);
  EXPECT_EQ(face[0], 3);
  EXPECT_EQ(indices[0], 0u);
  EXPECT_EQ(indices[1], 1u);
  EXPECT_EQ(indices[2], 3u);
  EXPECT_EQ(face[13], 7);
}

TEST(MeshPly, EmptyMeshAndMissingNormalsRoundTrip) {
  OrderedMesh empty;
  absl::StatusOr<OrderedMesh> read = ParsePly(Serialize(empty, true));
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_TRUE(read->empty());
  OrderedMesh bare = MakeGrid(3);
  bare.normals.clear();
  read = ParsePly(Serialize(bare, false));
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(read->normals, std::vector<float>(bare.positions.size(), 0.0f));
  EXPECT_EQ(read->triangles, bare.triangles);
}

TEST(MeshPly, ReadsFilesFromOtherWriters) {
  // No normals, no surface, extra properties and elements, vertex_index, int list types, CRLF.
  const std::string ascii =
      "ply\r\nformat ascii 1.0\r\ncomment from elsewhere\r\nobj_info x\r\n"
      "element vertex 4\r\nproperty double x\r\nproperty double y\r\nproperty double z\r\n"
      "property uchar red\r\nproperty list uchar float extra\r\n"
      "element face 2\r\nproperty uchar flags\r\nproperty list int int vertex_index\r\n"
      "element edge 1\r\nproperty int vertex1\r\nproperty int vertex2\r\n"
      "end_header\r\n"
      "0 0 0 255 0\r\n1 0 0 128 2 0.5 +1.5\r\n0 1 0 0 1 7\r\n1 1 1e-3 9 0\r\n"
      "4 3 0 1 2\r\n0 3 3 2 1\r\n"
      "0 1\r\n";
  const absl::StatusOr<OrderedMesh> mesh = ParsePly(ascii);
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  EXPECT_EQ(mesh->positions, (std::vector<float>{0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 1e-3f}));
  EXPECT_EQ(mesh->normals, std::vector<float>(12, 0.0f));
  EXPECT_EQ(mesh->triangles, (std::vector<uint32_t>{0, 1, 2, 3, 2, 1}));
  EXPECT_EQ(mesh->surface, (std::vector<uint8_t>{0, 0}));
}

TEST(MeshPly, DracosReaderAgreesWithOurBinaryFile) {
  const OrderedMesh mesh = Shuffled(MakeSphere(2000), 9);
  ScratchDir dir;
  const std::string path = dir.File("sphere.ply");
  ASSERT_TRUE(WritePly(mesh, path).ok());
  const auto draco_mesh = draco::ReadMeshFromFile(path);
  ASSERT_TRUE(draco_mesh.ok()) << draco_mesh.status().error_msg();
  EXPECT_EQ(draco_mesh.value()->num_faces(), mesh.triangle_count());
}

TEST(MeshPly, MissingFileIsNotFound) {
  ScratchDir dir;
  const absl::StatusOr<OrderedMesh> read = ReadPly(dir.File("absent.ply"));
  EXPECT_EQ(read.status().code(), absl::StatusCode::kNotFound) << read.status();
  EXPECT_NE(read.status().message().find("absent.ply"), absl::string_view::npos);
  // A device is refused up front: /dev/zero would be read until memory ran out.
  const absl::StatusOr<OrderedMesh> device = ReadPly("/dev/zero");
  EXPECT_EQ(device.status().code(), absl::StatusCode::kInvalidArgument) << device.status();
  EXPECT_EQ(ReadPly(dir.File("")).status().code(), absl::StatusCode::kInvalidArgument);
}

// A count the body cannot hold at its properties' size is refused before anything is
// allocated for it: 1 M float vertices (12 bytes each) with 1.5 MB of body would have asked
// for 24 MB of positions and normals.
TEST(MeshPly, CountsTheBodyCannotHoldAreDataLoss) {
  ScratchDir dir;
  const std::string path = dir.File("short_body.ply");
  {
    std::ofstream out(path, std::ios::binary);
    out << "ply\nformat binary_little_endian 1.0\nelement vertex 1000000\n"
           "property float x\nproperty float y\nproperty float z\nelement face 0\n"
           "property list uchar uint vertex_indices\nend_header\n";
    out << std::string(1500000, '\0');
  }
  const absl::StatusOr<OrderedMesh> read = ReadPly(path);
  EXPECT_EQ(read.status().code(), absl::StatusCode::kDataLoss) << read.status();
  EXPECT_NE(read.status().message().find("at least 12 bytes"), absl::string_view::npos)
      << read.status();
}

TEST(MeshPly, WriteRejectsInvalidMeshesAndBadPaths) {
  ScratchDir dir;
  OrderedMesh bad = MakeGrid(2);
  bad.triangles[4] = 9;
  const std::string path = dir.File("bad.ply");
  EXPECT_EQ(WritePly(bad, path).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_FALSE(std::filesystem::exists(path));
  bad = MakeGrid(2);
  bad.normals[5] = std::numeric_limits<float>::infinity();
  EXPECT_EQ(WritePly(bad, path).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_FALSE(WritePly(MakeGrid(2), dir.File("no/such/dir/x.ply")).ok());
}

TEST(MeshPly, BadHeadersAreRejectedWithReasons) {
  const std::string body = "0 0 0\n";
  const std::pair<std::string, const char*> cases[] = {
      {"plyx\nformat ascii 1.0\nend_header\n", "first line"},
      {"ply\nelement vertex 1\nproperty float x\nend_header\n", "no format"},
      {"ply\nformat binary_big_endian 1.0\nend_header\n", "big-endian"},
      {"ply\nformat ascii 2.0\nend_header\n", "format"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty half x\nend_header\n", "type"},
      {"ply\nformat ascii 1.0\nproperty float x\nend_header\n", "before any element"},
      {"ply\nformat ascii 1.0\nelement vertex -1\nend_header\n", "count"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
       "end_header\n",
       "\"z\""},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
       "property float z\nproperty float nx\nend_header\n",
       "nx, ny, nz"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
       "property float z\nelement face 1\nproperty list float int vertex_indices\nend_header\n",
       "count type"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
       "property float z\nelement face 1\nproperty int vertex_indices\nend_header\n",
       "not a list"},
      {"ply\nformat ascii 1.0\nelement face 0\nend_header\n", "no vertex element"},
      {"ply\nformat ascii 1.0\nelement vertex 1000\nproperty float x\nproperty float y\n"
       "property float z\nend_header\n",
       "declares 1000"},
      {"ply\nformat ascii 1.0\nfoo bar\nend_header\n", "unknown keyword"},
  };
  for (const auto& [text, reason] : cases) {
    const absl::StatusOr<OrderedMesh> mesh = ParsePly(text + body);
    ASSERT_FALSE(mesh.ok()) << text;
    EXPECT_NE(mesh.status().message().find(reason), absl::string_view::npos)
        << mesh.status() << " / expected mention of " << reason;
  }
  EXPECT_NE(ParsePly("").status().message().find("empty"), absl::string_view::npos);
  EXPECT_NE(
      ParsePly("ply\nformat ascii 1.0\nelement vertex 1\n").status().message().find("end_header"),
      absl::string_view::npos);
  EXPECT_EQ(ParsePly("ply\nformat binary_big_endian 1.0\nend_header\n").status().code(),
            absl::StatusCode::kUnimplemented);
}

TEST(MeshPly, BadContentIsRejected) {
  const std::string header =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar uint vertex_indices\n"
      "property uchar surface\nend_header\n0 0 0\n1 0 0\n0 1 0\n";
  const std::pair<std::string, const char*> cases[] = {
      {"3 0 1 3 0\n", "vertex index 3"},
      {"3 0 1 -1 0\n", "vertex index -1"},
      {"3 0 1 1.5 0\n", "vertex index 1.5"},
      {"4 0 1 2 2 0\n", "only triangles"},
      {"3 0 1 2 16\n", "surface 16"},
      {"3 0 1 2\n", "ends early"},
      {"3 0 1 x 0\n", "malformed"},
      // Values run together, and text after the last face (both were read as a whole mesh).
      {"3 0 1 2-0\n", "malformed"},
      {"3 0 1 2 0\n7 7\n", "text follows"},
  };
  for (const auto& [faces, reason] : cases) {
    const absl::StatusOr<OrderedMesh> mesh = ParsePly(header + faces);
    ASSERT_FALSE(mesh.ok()) << faces;
    EXPECT_NE(mesh.status().message().find(reason), absl::string_view::npos)
        << mesh.status() << " / expected mention of " << reason;
  }
  const absl::StatusOr<OrderedMesh> nan_vertex = ParsePly(
      "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
      "property float z\nend_header\nnan 0 0\n");
  EXPECT_FALSE(nan_vertex.ok());
}

TEST(MeshPly, TruncatedFilesAreErrors) {
  const OrderedMesh mesh = MakeGrid(6, 2);
  const std::string binary = Serialize(mesh, true);
  for (size_t length = 0; length < binary.size(); length += 7) {
    const absl::StatusOr<OrderedMesh> read = ParsePly(binary.substr(0, length));
    EXPECT_FALSE(read.ok()) << "length " << length;
  }
  // In ascii a cut inside the last number can still parse; every cut before the last line fails.
  const std::string ascii = Serialize(mesh, false);
  const size_t last_line = ascii.rfind('\n', ascii.size() - 2);
  for (size_t length = 0; length < last_line; length += 7) {
    const absl::StatusOr<OrderedMesh> read = ParsePly(ascii.substr(0, length));
    EXPECT_FALSE(read.ok()) << "length " << length;
  }
}

TEST(MeshPly, GarbageNeverCrashes) {
  std::mt19937 rng(13);
  const std::string valid = Serialize(MakeGrid(4), true);
  const size_t header_end = valid.find("end_header\n") + 11;
  for (int trial = 0; trial < 500; ++trial) {
    std::string edited = valid;
    for (int f = 0; f < 4; ++f) {
      // Half the edits hit the header, half the data.
      const size_t at =
          trial % 2 ? rng() % header_end : header_end + rng() % (valid.size() - header_end);
      edited[at] = static_cast<char>(rng());
    }
    const absl::StatusOr<OrderedMesh> read = ParsePly(edited);
    if (read.ok()) {
      for (uint32_t index : read->triangles) ASSERT_LT(index, read->vertex_count());
    }
  }
}

}  // namespace
}  // namespace isostream
