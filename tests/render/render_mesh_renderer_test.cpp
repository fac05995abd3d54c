// MeshRenderer behaviour with exact expectations: frames replaced whole, per-triangle surface
// colours, the "over" blend, chunk ranges equal to whole chunks, and statuses for misuse.
#include <gtest/gtest.h>

#include "tests/render/render_test_support.h"
#include "tests/render/test_spheres.h"

namespace isostream::render::testing {
namespace {

// Looks down -z at the square [-1, 1]^2 of the z = 0 plane, which exactly fills the view.
Camera SquareCamera() {
  Camera c;
  c.projection = Projection::kOrthographic;
  c.eye = {0, 0, 2};
  c.target = {0, 0, 0};
  c.ortho_half_height = 1.0f;
  c.near_plane = 0.5f;
  c.far_plane = 4.0f;
  return c;
}

// Two triangles covering the left half [-1, 0] x [-1, 1] (surface `left`) and two covering the
// right half (surface `right`), at z, facing +z.
OrderedMesh Halves(uint8_t left, uint8_t right, float z = 0.0f) {
  OrderedMesh m;
  for (float x : {-1.0f, 0.0f, 1.0f}) {
    for (float y : {-1.0f, 1.0f}) {
      m.positions.insert(m.positions.end(), {x, y, z});
      m.normals.insert(m.normals.end(), {0.0f, 0.0f, 1.0f});
    }
  }
  // Vertex 2*i + j is (x_i, y_j).
  m.triangles = {0, 2, 3, 0, 3, 1, 2, 4, 5, 2, 5, 3};
  m.surface = {left, left, right, right};
  return m;
}

// Lighting that passes surface colours through unchanged.
Lighting Flat() {
  Lighting l;
  l.ambient = 1.0f;
  l.diffuse = 0.0f;
  l.specular = 0.0f;
  return l;
}

class MeshRendererTest : public RenderTest {
 protected:
  Image DrawChunks(const std::vector<OrderedMesh>& chunks, const Camera& camera) {
    renderer_->BeginFrame();
    for (const OrderedMesh& c : chunks) EXPECT_TRUE(renderer_->AddChunk(c).ok());
    EXPECT_TRUE(renderer_->EndFrame().ok());
    return RenderNow(camera);
  }
  Image RenderNow(const Camera& camera) {
    const absl::Status status = renderer_->Render(camera);
    EXPECT_TRUE(status.ok()) << status;
    absl::StatusOr<Image> image = context_->ReadPixels();
    EXPECT_TRUE(image.ok()) << image.status();
    return image.ok() ? *image : Image{};
  }
  static void ExpectPixel(const Image& image, int x, int y, int r, int g, int b) {
    const uint8_t* p = image.pixel(x, y);
    EXPECT_NEAR(p[0], r, 1) << "at " << x << "," << y;
    EXPECT_NEAR(p[1], g, 1) << "at " << x << "," << y;
    EXPECT_NEAR(p[2], b, 1) << "at " << x << "," << y;
    EXPECT_EQ(p[3], 255) << "at " << x << "," << y;
  }
};

TEST_F(MeshRendererTest, EmptyFrameIsBackground) {
  renderer_->SetBackground({0.2f, 0.4f, 0.6f, 1.0f});
  const Image image = DrawChunks({}, SquareCamera());
  ExpectPixel(image, 0, 0, 51, 102, 153);
  ExpectPixel(image, kSize - 1, kSize - 1, 51, 102, 153);
  EXPECT_EQ(renderer_->chunk_count(), 0u);
}

// Surfaces are per triangle and gl_PrimitiveID restarts in every chunk: each chunk's triangles
// must find their own surface, whatever came before.
TEST_F(MeshRendererTest, EachTriangleGetsItsSurfaceColour) {
  Palette palette = DefaultPalette();
  palette[3] = {{1, 0, 0}, 1.0f};
  palette[7] = {{0, 1, 0}, 1.0f};
  palette[15] = {{0, 0, 1}, 1.0f};
  renderer_->SetPalette(palette);
  renderer_->SetLighting(Flat());
  const Image one = DrawChunks({Halves(3, 7)}, SquareCamera());
  ExpectPixel(one, kSize / 4, kSize / 2, 255, 0, 0);
  ExpectPixel(one, 3 * kSize / 4, kSize / 2, 0, 255, 0);
  // Second chunk on top: only the right half changes surface, to 15.
  OrderedMesh right_only = Halves(15, 15);
  right_only.triangles.erase(right_only.triangles.begin(), right_only.triangles.begin() + 6);
  right_only.surface = {15, 15};
  const Image two = DrawChunks({Halves(3, 7), right_only}, SquareCamera());
  ExpectPixel(two, kSize / 4, kSize / 2, 255, 0, 0);
  ExpectPixel(two, 3 * kSize / 4, kSize / 2, 0, 0, 255);
  EXPECT_EQ(renderer_->chunk_count(), 2u);
  EXPECT_EQ(renderer_->triangle_count(), 6u);
}

// colour = alpha * source + (1 - alpha) * destination, layer by layer, in chunk order.
TEST_F(MeshRendererTest, BlendsOverInDrawOrder) {
  Palette palette = DefaultPalette();
  palette[0] = {{1, 0, 0}, 0.5f};
  palette[1] = {{0, 0, 1}, 0.25f};
  renderer_->SetPalette(palette);
  renderer_->SetLighting(Flat());
  renderer_->SetBackground({1, 1, 1, 1});
  // Red (0.5) then blue (0.25) over white: r = 0.75 * 1, g = 0.75 * 0.5, b = 0.25 + 0.75 * 0.5.
  const Image image = DrawChunks({Halves(0, 0, -0.5f), Halves(1, 1, 0.5f)}, SquareCamera());
  ExpectPixel(image, kSize / 2, kSize / 2, 191, 96, 159);
  // Blue then red: r = 0.5 + 0.5 * 0.75, g = 0.5 * 0.75, b = 0.5 * 1. Order decides, not depth.
  const Image swapped = DrawChunks({Halves(1, 1, 0.5f), Halves(0, 0, -0.5f)}, SquareCamera());
  ExpectPixel(swapped, kSize / 2, kSize / 2, 223, 96, 128);
}

TEST_F(MeshRendererTest, OldFrameStaysUntilTheNewOneEnds) {
  Palette palette = DefaultPalette();
  palette[0] = {{1, 0, 0}, 1.0f};
  palette[1] = {{0, 1, 0}, 1.0f};
  renderer_->SetPalette(palette);
  renderer_->SetLighting(Flat());
  const Image first = DrawChunks({Halves(0, 0)}, SquareCamera());
  ExpectPixel(first, 10, 10, 255, 0, 0);

  renderer_->BeginFrame();
  ASSERT_TRUE(renderer_->AddChunk(Halves(1, 1)).ok());
  EXPECT_TRUE(renderer_->frame_pending());
  ExpectPixel(RenderNow(SquareCamera()), 10, 10, 255, 0, 0);  // still the complete old frame
  ASSERT_TRUE(renderer_->EndFrame().ok());
  EXPECT_FALSE(renderer_->frame_pending());
  ExpectPixel(RenderNow(SquareCamera()), 10, 10, 0, 255, 0);

  // A frame begun again before it ended is dropped, not merged.
  renderer_->BeginFrame();
  ASSERT_TRUE(renderer_->AddChunk(Halves(0, 0)).ok());
  renderer_->BeginFrame();
  ASSERT_TRUE(renderer_->EndFrame().ok());
  EXPECT_EQ(renderer_->chunk_count(), 0u);
}

TEST_F(MeshRendererTest, MisuseAndBadChunksGiveStatuses) {
  EXPECT_EQ(renderer_->AddChunk(Halves(0, 0)).code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(renderer_->EndFrame().code(), absl::StatusCode::kFailedPrecondition);

  renderer_->BeginFrame();
  OrderedMesh bad_index = Halves(0, 0);
  bad_index.triangles[4] = 6;
  EXPECT_EQ(renderer_->AddChunk(bad_index).code(), absl::StatusCode::kInvalidArgument);
  OrderedMesh bad_surface = Halves(0, 0);
  bad_surface.surface[1] = kMaxSurfaces;
  EXPECT_EQ(renderer_->AddChunk(bad_surface).code(), absl::StatusCode::kInvalidArgument);
  OrderedMesh bad_sizes = Halves(0, 0);
  bad_sizes.normals.pop_back();
  EXPECT_EQ(renderer_->AddChunk(bad_sizes).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(renderer_->AddChunk(Halves(0, 0), 3, 2).code(), absl::StatusCode::kOutOfRange);
  EXPECT_TRUE(renderer_->AddChunk(OrderedMesh()).ok());  // empty: accepted, adds nothing
  ASSERT_TRUE(renderer_->EndFrame().ok());
  EXPECT_EQ(renderer_->chunk_count(), 0u);

  Camera degenerate = SquareCamera();
  degenerate.target = degenerate.eye;
  EXPECT_EQ(renderer_->Render(degenerate).code(), absl::StatusCode::kInvalidArgument);
}

// Uploading ranges (vertices compacted) must draw exactly what uploading whole chunks draws.
TEST_F(MeshRendererTest, RangesDrawExactlyLikeWholeChunks) {
  Camera camera = FrameBox(glm::vec3(-1.0f), glm::vec3(1.0f), glm::vec3(0.3f, 0.2f, 1.0f), {});
  OrderedMesh mesh = MakeSpheres(ThreeNestedSpheres(), 2);
  SortShellsBackToFront(camera, {}, &mesh);
  const Image whole = DrawChunks({mesh}, camera);

  renderer_->BeginFrame();
  const size_t n = mesh.triangle_count();
  for (size_t first = 0; first < n; first += 97) {
    ASSERT_TRUE(renderer_->AddChunk(mesh, first, std::min<size_t>(97, n - first)).ok());
  }
  ASSERT_TRUE(renderer_->EndFrame().ok());
  EXPECT_EQ(renderer_->triangle_count(), n);
  const Image ranges = RenderNow(camera);
  EXPECT_EQ(MeanAbsoluteDifference(whole, ranges), 0.0);
}

// Zero normals mean "undefined"; the facet normal takes over, so the mesh is still shaded
// (a NaN normal would leave black or background pixels).
TEST_F(MeshRendererTest, MeshWithoutNormalsIsStillLit) {
  Camera camera = FrameBox(glm::vec3(-1.0f), glm::vec3(1.0f), glm::vec3(0.3f, 0.2f, 1.0f), {});
  OrderedMesh mesh = MakeSpheres({{{0, 0, 0}, 1.0f, 0}}, 2);
  mesh.normals.clear();
  Palette palette = DefaultPalette();
  palette[0] = {{1, 1, 1}, 1.0f};
  renderer_->SetPalette(palette);
  renderer_->SetBackground({0, 0, 0, 1});
  const Image image = DrawChunks({mesh}, camera);
  const uint8_t* centre = image.pixel(kSize / 2, kSize / 2);
  // Facing the headlight almost head on: close to ambient + diffuse.
  EXPECT_GT(centre[0], 200);
  EXPECT_EQ(centre[0], centre[1]);
}

}  // namespace
}  // namespace isostream::render::testing
