// One headless context and renderer shared by the tests of a suite (creating a context costs
// more than most tests), and a place to drop pictures for a human to look at.
#pragma once

#include <gtest/gtest.h>

#include <cstdlib>
#include <glm/vec3.hpp>
#include <memory>
#include <string>

#include "client/render/headless_context.h"
#include "client/render/image.h"
#include "client/render/mesh_renderer.h"
#include "tests/common/image_coverage.h"

namespace isostream::render::testing {

class RenderTest : public ::testing::Test {
 protected:
  static constexpr int kSize = 192;

  static void SetUpTestSuite() {
    HeadlessContextOptions options;
    options.width = kSize;
    options.height = kSize;
    auto context = HeadlessContext::Create(options);
    ASSERT_TRUE(context.ok()) << context.status();
    context_ = std::move(*context).release();
    auto renderer = MeshRenderer::Create();
    ASSERT_TRUE(renderer.ok()) << renderer.status();
    renderer_ = std::move(*renderer).release();
  }
  static void TearDownTestSuite() {
    delete renderer_;  // GL objects first, while their context exists
    renderer_ = nullptr;
    delete context_;
    context_ = nullptr;
  }
  void SetUp() override {
    ASSERT_NE(context_, nullptr);
    ASSERT_NE(renderer_, nullptr);
    ASSERT_TRUE(context_->MakeCurrent().ok());
    // Each test starts from the renderer's defaults.
    renderer_->SetPalette(DefaultPalette());
    renderer_->SetLighting(Lighting());
    renderer_->SetBackground(kDefaultBackground);
  }

  static inline HeadlessContext* context_ = nullptr;
  static inline MeshRenderer* renderer_ = nullptr;
};

using isostream::testing::Coverage;

// Writes `image` as <ISOSTREAM_RENDER_TEST_OUT>/<name>.png when that variable is set, so the
// pictures behind a golden test can be inspected; does nothing otherwise.
inline void MaybeSavePicture(const Image& image, const std::string& name) {
  const char* dir = std::getenv("ISOSTREAM_RENDER_TEST_OUT");
  if (dir == nullptr || *dir == '\0') return;
  const absl::Status status = WritePng(image, std::string(dir) + "/" + name + ".png");
  EXPECT_TRUE(status.ok()) << status;
}

}  // namespace isostream::render::testing
