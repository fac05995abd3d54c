// Golden images: the rasterized frame of nested transparent spheres and a sphere behind them, drawn
// in a painter's order split into chunks, against an Embree ray-traced reference that composites
// every surface crossing in exact depth order. The reversed-order test shows the comparison can
// fail.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <vector>

#include "tests/render/embree_reference.h"
#include "tests/render/render_test_support.h"
#include "tests/render/test_spheres.h"

namespace isostream::render::testing {
namespace {

// The acceptance bound: mean absolute difference at most 2% of the range.
constexpr double kTolerance = 0.02;

// Frames the unit nest tightly; the clip planes are opened up for the sphere behind, which the
// framing box leaves out.
Camera TestCamera(Projection projection) {
  Camera base;
  base.projection = projection;
  base.aspect = 1.0f;
  base.fov_y_degrees = 40.0f;
  Camera camera = FrameBox(glm::vec3(-0.7f), glm::vec3(0.7f), glm::vec3(0.5f, 0.4f, 1.0f), base);
  if (projection == Projection::kOrthographic)
    camera.eye = camera.target + 5.0f * glm::normalize(camera.eye - camera.target);
  camera.near_plane = 0.1f;
  camera.far_plane = 10.0f;
  return camera;
}

OrderedMesh TestScene(const Camera& camera) {
  OrderedMesh mesh = MakeSpheres(NestBeforeSphere(camera), 3);
  SortShellsBackToFront(camera, kSphereThenNest, &mesh);
  return mesh;
}

// The mesh split into `count` consecutive chunks of nearly equal size, cut without regard for
// surfaces or hemispheres, as a network stream would cut it.
std::vector<std::pair<size_t, size_t>> Chunks(const OrderedMesh& mesh, size_t count) {
  std::vector<std::pair<size_t, size_t>> chunks;
  const size_t n = mesh.triangle_count();
  for (size_t i = 0; i < count; ++i)
    chunks.push_back({n * i / count, n * (i + 1) / count - n * i / count});
  return chunks;
}

class GoldenTest : public RenderTest {
 protected:
  Image Draw(const OrderedMesh& mesh, const std::vector<std::pair<size_t, size_t>>& chunks,
             const Camera& camera) {
    renderer_->BeginFrame();
    for (const auto& [first, count] : chunks) {
      const absl::Status added = renderer_->AddChunk(mesh, first, count);
      EXPECT_TRUE(added.ok()) << added;
    }
    EXPECT_TRUE(renderer_->EndFrame().ok());
    const absl::Status rendered = renderer_->Render(camera);
    EXPECT_TRUE(rendered.ok()) << rendered;
    absl::StatusOr<Image> image = context_->ReadPixels();
    EXPECT_TRUE(image.ok()) << image.status();
    return image.ok() ? *image : Image{};
  }

  Image Reference(const OrderedMesh& mesh, const Camera& camera) {
    absl::StatusOr<Image> image = TraceReference(mesh, camera, kSize, kSize, renderer_->palette(),
                                                 renderer_->lighting(), renderer_->background());
    EXPECT_TRUE(image.ok()) << image.status();
    return image.ok() ? *image : Image{};
  }

  // Guards against comparing two empty pictures.
  double Coverage(const Image& image) {
    return testing::Coverage(image, glm::vec3(renderer_->background()));
  }

  void ExpectMatchesReference(Projection projection, const char* name) {
    const Camera camera = TestCamera(projection);
    const OrderedMesh mesh = TestScene(camera);
    const Image drawn = Draw(mesh, Chunks(mesh, 5), camera);
    const Image reference = Reference(mesh, camera);
    MaybeSavePicture(drawn, std::string(name) + "_drawn");
    MaybeSavePicture(reference, std::string(name) + "_reference");
    EXPECT_GT(Coverage(drawn), 0.3);
    const double mad = MeanAbsoluteDifference(drawn, reference);
    std::printf("%s: mean absolute difference to the Embree reference %.5f (%.3f%% of range)\n",
                name, mad, 100.0 * mad);
    RecordProperty("mad_percent", std::to_string(100.0 * mad));
    EXPECT_GE(mad, 0.0);
    EXPECT_LE(mad, kTolerance);
  }
};

TEST_F(GoldenTest, PerspectiveMatchesRayTracedReference) {
  ExpectMatchesReference(Projection::kPerspective, "spheres_perspective");
}

TEST_F(GoldenTest, OrthographicMatchesRayTracedReference) {
  ExpectMatchesReference(Projection::kOrthographic, "spheres_orthographic");
}

TEST_F(GoldenTest, DarkBackgroundMatchesRayTracedReference) {
  renderer_->SetBackground({0.2f, 0.2f, 0.2f, 1.0f});
  ExpectMatchesReference(Projection::kPerspective, "spheres_dark");
}

// Chunks drawn last-first put the sphere behind over the nest (and far hemispheres over near
// ones): the comparison must see that, or the golden tests above could not fail.
TEST_F(GoldenTest, ReversedChunkOrderIsFarFromReference) {
  const Camera camera = TestCamera(Projection::kPerspective);
  const OrderedMesh mesh = TestScene(camera);
  std::vector<std::pair<size_t, size_t>> chunks = Chunks(mesh, 5);
  const Image in_order = Draw(mesh, chunks, camera);
  std::reverse(chunks.begin(), chunks.end());
  const Image reversed = Draw(mesh, chunks, camera);
  const Image reference = Reference(mesh, camera);
  MaybeSavePicture(reversed, "spheres_reversed_chunks");
  const double mad_in_order = MeanAbsoluteDifference(in_order, reference);
  const double mad_reversed = MeanAbsoluteDifference(reversed, reference);
  std::printf("reversed chunks: mean absolute difference %.5f (in order %.5f)\n", mad_reversed,
              mad_in_order);
  EXPECT_GT(mad_reversed, 2.0 * kTolerance);
  EXPECT_GT(mad_reversed, 10.0 * mad_in_order);
}

}  // namespace
}  // namespace isostream::render::testing
