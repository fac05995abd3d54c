// Headless EGL contexts on Mesa: creation with no X server, the framebuffer's size, several
// contexts alive at once, and statuses (not crashes) for the ways creation can fail.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "client/render/headless_context.h"
#include "client/render/mesh_renderer.h"
#include "client/render/opengl/egl_names.h"
#include "client/render/opengl/gl_api.h"

namespace isostream::render {
namespace {

HeadlessContextOptions Size(int w, int h) {
  HeadlessContextOptions options;
  options.width = w;
  options.height = h;
  return options;
}

// Clears through the renderer (an empty frame draws only the background) and reads back.
Image ClearedTo(HeadlessContext& context, MeshRenderer& renderer, const glm::vec4& rgba) {
  renderer.SetBackground(rgba);
  EXPECT_TRUE(renderer.Render(Camera()).ok());
  absl::StatusOr<Image> image = context.ReadPixels();
  EXPECT_TRUE(image.ok()) << image.status();
  return image.ok() ? *image : Image{};
}

TEST(HeadlessContextTest, CreatesWithoutADisplayServer) {
  auto context = HeadlessContext::Create(Size(31, 17));
  ASSERT_TRUE(context.ok()) << context.status();
  EXPECT_EQ((*context)->width(), 31);
  EXPECT_EQ((*context)->height(), 17);
  EXPECT_FALSE((*context)->renderer_name().empty());
  EXPECT_FALSE((*context)->platform_name().empty());
  auto renderer = MeshRenderer::Create();
  ASSERT_TRUE(renderer.ok()) << renderer.status();
  const Image image = ClearedTo(**context, **renderer, {0.0f, 0.5f, 1.0f, 1.0f});
  ASSERT_EQ(image.width, 31);
  ASSERT_EQ(image.height, 17);
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      const uint8_t* p = image.pixel(x, y);
      EXPECT_EQ(p[0], 0);
      EXPECT_NEAR(p[1], 128, 1);
      EXPECT_EQ(p[2], 255);
      EXPECT_EQ(p[3], 255);
    }
  }
}

// How many distinct colours a picture of one opaque, flat-lit triangle over a background holds.
size_t ColoursOfATriangle(int samples) {
  HeadlessContextOptions options = Size(64, 64);
  options.samples = samples;
  auto context = HeadlessContext::Create(options);
  EXPECT_TRUE(context.ok()) << context.status();
  if (!context.ok()) return 0;
  auto renderer = MeshRenderer::Create();
  EXPECT_TRUE(renderer.ok()) << renderer.status();
  if (!renderer.ok()) return 0;
  Palette palette = (*renderer)->palette();
  palette[0].opacity = 1.0f;
  (*renderer)->SetPalette(palette);
  OrderedMesh mesh;  // a slanted triangle facing the eye: its edges cross pixels at all angles
  mesh.positions = {-0.9f, -0.8f, 0.0f, 0.85f, -0.3f, 0.0f, -0.2f, 0.9f, 0.0f};
  mesh.normals = {0, 0, 1, 0, 0, 1, 0, 0, 1};
  mesh.triangles = {0, 1, 2};
  mesh.surface = {0};
  (*renderer)->BeginFrame();
  EXPECT_TRUE((*renderer)->AddChunk(mesh).ok());
  EXPECT_TRUE((*renderer)->EndFrame().ok());
  Camera camera;  // the eye on +z looking at the origin; orthographic: one shade for the face
  camera.projection = Projection::kOrthographic;
  EXPECT_TRUE((*renderer)->Render(camera).ok());
  const absl::StatusOr<Image> image = (*context)->ReadPixels();
  EXPECT_TRUE(image.ok()) << image.status();
  if (!image.ok()) return 0;
  // Reading resolved the samples elsewhere, and left reads and draws on the drawing buffer.
  GLint read = -1, draw = -2;
  glGetIntegerv(GL_READ_FRAMEBUFFER_BINDING, &read);
  glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &draw);
  EXPECT_EQ(read, draw) << samples << " samples";
  std::set<uint32_t> colours;
  for (size_t i = 0; i < image->rgba.size(); i += 4)
    colours.insert(uint32_t(image->rgba[i]) << 16 | uint32_t(image->rgba[i + 1]) << 8 |
                   image->rgba[i + 2]);
  return colours.size();
}

// Multisampling blends the pixels an edge crosses: without it a flat triangle over a background
// is two colours; with 4 samples its edges add the shades between (the viewer's --samples).
TEST(HeadlessContextTest, MultisamplingSmoothsEdges) {
  EXPECT_EQ(ColoursOfATriangle(1), 2u);
  EXPECT_GE(ColoursOfATriangle(4), 4u);
}

TEST(HeadlessContextTest, ResizeChangesTheReadback) {
  HeadlessContextOptions options = Size(8, 8);
  options.depth_buffer = true;
  auto context = HeadlessContext::Create(options);
  ASSERT_TRUE(context.ok()) << context.status();
  ASSERT_TRUE((*context)->Resize(40, 12).ok());
  auto renderer = MeshRenderer::Create();
  ASSERT_TRUE(renderer.ok());
  const Image image = ClearedTo(**context, **renderer, {1, 0, 0, 1});
  EXPECT_EQ(image.width, 40);
  EXPECT_EQ(image.height, 12);
  EXPECT_EQ(image.pixel(39, 11)[0], 255);
  EXPECT_EQ((*context)->Resize(0, 12).code(), absl::StatusCode::kInvalidArgument);
}

// Destroying one context must not take the (process-wide) EGL display from the other.
TEST(HeadlessContextTest, TwoContextsLiveSideBySide) {
  auto first = HeadlessContext::Create(Size(4, 4));
  ASSERT_TRUE(first.ok()) << first.status();
  {
    auto second = HeadlessContext::Create(Size(6, 6));
    ASSERT_TRUE(second.ok()) << second.status();
    auto renderer = MeshRenderer::Create();
    ASSERT_TRUE(renderer.ok());
    EXPECT_EQ(ClearedTo(**second, **renderer, {0, 1, 0, 1}).pixel(5, 5)[1], 255);
  }
  ASSERT_TRUE((*first)->MakeCurrent().ok());
  auto renderer = MeshRenderer::Create();
  ASSERT_TRUE(renderer.ok()) << renderer.status();
  const Image image = ClearedTo(**first, **renderer, {0, 0, 1, 1});
  EXPECT_EQ(image.width, 4);
  EXPECT_EQ(image.pixel(3, 3)[2], 255);
}

TEST(HeadlessContextTest, BadSizeIsInvalidArgument) {
  for (auto [w, h] : {std::pair{0, 10}, std::pair{10, -1}, std::pair{100000, 10}}) {
    auto context = HeadlessContext::Create(Size(w, h));
    ASSERT_FALSE(context.ok());
    EXPECT_EQ(context.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(context.status().message().find("framebuffer size"), std::string::npos);
  }
}

// A device that does not exist stands in for a machine without EGL: the status says which
// platform failed, why, and what to install.
TEST(HeadlessContextTest, MissingDeviceIsUnavailableWithReasons) {
  HeadlessContextOptions options = Size(8, 8);
  options.platform = EglPlatform::kDevice;
  options.device_index = 1000;
  auto context = HeadlessContext::Create(options);
  ASSERT_FALSE(context.ok());
  EXPECT_EQ(context.status().code(), absl::StatusCode::kUnavailable);
  const std::string message(context.status().message());
  EXPECT_NE(message.find("device platform"), std::string::npos) << message;
  EXPECT_NE(message.find("libegl-mesa0"), std::string::npos) << message;
  EXPECT_EQ(message.find("surfaceless:"), std::string::npos) << message;
}

TEST(HeadlessContextTest, SurfacelessOnlyWorksOnMesa) {
  HeadlessContextOptions options = Size(8, 8);
  options.platform = EglPlatform::kSurfaceless;
  auto context = HeadlessContext::Create(options);
  ASSERT_TRUE(context.ok()) << context.status();
  EXPECT_EQ((*context)->platform_name(), "surfaceless");
}

TEST(HeadlessContextTest, ErrorNames) {
  EXPECT_EQ(egl::EglErrorName(0x3009), "EGL_BAD_MATCH");
  EXPECT_EQ(egl::EglErrorName(0x3000), "EGL_SUCCESS");
  EXPECT_EQ(egl::EglErrorName(0x1234), "EGL error 0x1234");
  EXPECT_EQ(gl::GlErrorName(GL_INVALID_OPERATION), "GL_INVALID_OPERATION");
  EXPECT_EQ(gl::GlErrorName(0x9999), "GL error 0x9999");
}

}  // namespace
}  // namespace isostream::render
