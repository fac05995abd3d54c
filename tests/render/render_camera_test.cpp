// Camera math: the view and projection conventions the shaders and the Embree reference rely
// on, framing that really contains the box, and orbits that keep distance and height.
#include <gtest/gtest.h>

#include <cmath>
#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>
#include <glm/mat4x4.hpp>

#include "client/render/camera.h"

namespace isostream::render {
namespace {

glm::vec3 Project(const Camera& c, const glm::vec3& p) {
  const glm::vec4 clip = c.ViewProjection() * glm::vec4(p, 1.0f);
  return glm::vec3(clip) / clip.w;
}

TEST(CameraTest, ViewLooksDownMinusZFromTheEye) {
  Camera c;
  c.eye = {1, 2, 3};
  c.target = {4, -1, 0};
  c.up = {0, 0, 1};
  const glm::mat4 view = c.ViewMatrix();
  const glm::vec4 eye = view * glm::vec4(c.eye, 1.0f);
  EXPECT_NEAR(glm::length(glm::vec3(eye)), 0.0f, 1e-5f);
  const glm::vec4 target = view * glm::vec4(c.target, 1.0f);
  EXPECT_NEAR(target.x, 0.0f, 1e-5f);
  EXPECT_NEAR(target.y, 0.0f, 1e-5f);
  EXPECT_NEAR(target.z, -glm::length(c.target - c.eye), 1e-4f);
}

TEST(CameraTest, BasisIsRightHandedAndOrthonormal) {
  Camera c;
  c.eye = {0.3f, -2.0f, 5.0f};
  c.target = {0.0f, 0.5f, 0.0f};
  c.up = {0.2f, 1.0f, 0.1f};
  const glm::vec3 f = c.Forward(), r = c.Right(), u = c.TrueUp();
  EXPECT_NEAR(glm::length(f), 1.0f, 1e-6f);
  EXPECT_NEAR(glm::length(r), 1.0f, 1e-6f);
  EXPECT_NEAR(glm::length(u), 1.0f, 1e-6f);
  EXPECT_NEAR(glm::dot(f, r), 0.0f, 1e-6f);
  EXPECT_NEAR(glm::dot(f, u), 0.0f, 1e-6f);
  EXPECT_NEAR(glm::length(glm::cross(r, u) + f), 0.0f, 1e-5f);  // r x u = backwards
  EXPECT_GT(glm::dot(u, c.up), 0.0f);
  // Right maps to +x on screen, up to +y.
  const glm::vec3 right_of_target = Project(c, c.target + 0.1f * r);
  const glm::vec3 above_target = Project(c, c.target + 0.1f * u);
  EXPECT_GT(right_of_target.x, 0.0f);
  EXPECT_GT(above_target.y, 0.0f);
}

TEST(CameraTest, RejectsDegenerateCameras) {
  Camera ok;
  EXPECT_TRUE(IsValidCamera(ok));
  Camera c = ok;
  c.target = c.eye;
  EXPECT_FALSE(IsValidCamera(c));
  c = ok;
  c.up = c.target - c.eye;
  EXPECT_FALSE(IsValidCamera(c));
  c = ok;
  c.near_plane = c.far_plane;
  EXPECT_FALSE(IsValidCamera(c));
  c = ok;
  c.near_plane = 0.0f;
  EXPECT_FALSE(IsValidCamera(c));
  c = ok;
  c.fov_y_degrees = 180.0f;
  EXPECT_FALSE(IsValidCamera(c));
  c = ok;
  c.projection = Projection::kOrthographic;
  c.ortho_half_height = 0.0f;
  EXPECT_FALSE(IsValidCamera(c));
  c = ok;
  c.eye.x = std::nanf("");
  EXPECT_FALSE(IsValidCamera(c));
}

TEST(CameraTest, FrameBoxKeepsEveryCornerInView) {
  struct Box {
    glm::vec3 lo, hi;
    bool cube;
  };
  for (const Box& box : {Box{{-2.0f, 0.5f, 1.0f}, {3.0f, 1.5f, 4.0f}, false},
                         Box{{-1.0f, 0.0f, 1.0f}, {1.0f, 2.0f, 3.0f}, true}}) {
    for (Projection projection : {Projection::kPerspective, Projection::kOrthographic}) {
      for (float aspect : {0.4f, 1.0f, 2.5f}) {
        for (glm::vec3 dir : {glm::vec3(0, 0, 1), glm::vec3(1, 1, 1), glm::vec3(0, 1, 0)}) {
          Camera base;
          base.projection = projection;
          base.aspect = aspect;
          const Camera c = FrameBox(box.lo, box.hi, dir, base);
          ASSERT_TRUE(IsValidCamera(c));
          EXPECT_NEAR(glm::length(c.target - 0.5f * (box.lo + box.hi)), 0.0f, 1e-5f);
          EXPECT_NEAR(glm::dot(glm::normalize(c.eye - c.target), glm::normalize(dir)), 1.0f, 1e-5f);
          float widest = 0.0f;
          for (int k = 0; k < 8; ++k) {
            const glm::vec3 corner(k & 1 ? box.hi.x : box.lo.x, k & 2 ? box.hi.y : box.lo.y,
                                   k & 4 ? box.hi.z : box.lo.z);
            const glm::vec3 ndc = Project(c, corner);
            EXPECT_LE(std::abs(ndc.x), 1.0f);
            EXPECT_LE(std::abs(ndc.y), 1.0f);
            EXPECT_LE(std::abs(ndc.z), 1.0f);
            widest = std::max({widest, std::abs(ndc.x), std::abs(ndc.y)});
          }
          // Framed, not lost in the middle: a cube's corners reach at least 1/sqrt(3) of its
          // bounding sphere, less the margin, in the narrower image axis.
          if (box.cube) {
            EXPECT_GT(widest, 0.5f);
          }
        }
      }
    }
  }
}

// Volumes may be placed with any spacing from 1e-30 to 1e30: framing and projecting their boxes
// must not depend on float squares of their lengths (at 1e-16 the view was a speck, past 1e19
// the eye infinite).
TEST(CameraTest, FrameBoxKeepsEveryCornerInViewAtAnyScale) {
  for (const float scale : {1e-30f, 1e-20f, 1e-16f, 1.0f, 1e19f, 1e30f}) {
    SCOPED_TRACE(scale);
    const glm::vec3 lo = scale * glm::vec3(-2.0f, 0.5f, 1.0f), hi = scale * glm::vec3(3, 1.5f, 4);
    for (Projection projection : {Projection::kPerspective, Projection::kOrthographic}) {
      Camera base;
      base.projection = projection;
      const Camera c = FrameBox(lo, hi, glm::vec3(0.8f, 0.6f, 1.0f), base);
      ASSERT_TRUE(IsValidCamera(c));
      const double size = glm::length(glm::dvec3(hi - lo));
      EXPECT_NEAR(glm::length(glm::dvec3(c.eye - c.target)) / size, 1.0, 1.0);  // about its size
      float widest = 0.0f;
      for (int k = 0; k < 8; ++k) {
        const glm::vec3 corner(k & 1 ? hi.x : lo.x, k & 2 ? hi.y : lo.y, k & 4 ? hi.z : lo.z);
        const glm::vec3 ndc = Project(c, corner);
        EXPECT_LE(std::abs(ndc.x), 1.0f);
        EXPECT_LE(std::abs(ndc.y), 1.0f);
        EXPECT_LE(std::abs(ndc.z), 1.0f);
        widest = std::max({widest, std::abs(ndc.x), std::abs(ndc.y)});
      }
      EXPECT_GT(widest, 0.3f);  // framed, not a speck
    }
  }
}

TEST(CameraTest, OrbitKeepsDistanceAndHeightAndTurnsEvenly) {
  Camera base;
  base.eye = {3.0f, 1.0f, 0.0f};
  base.target = {0.0f, 0.0f, 0.0f};
  base.up = {0.0f, 1.0f, 0.0f};
  const std::vector<Camera> orbit = OrbitCameras(base, 4);
  ASSERT_EQ(orbit.size(), 4u);
  EXPECT_EQ(orbit[0].eye, base.eye);
  for (const Camera& c : orbit) {
    EXPECT_NEAR(glm::length(c.eye - c.target), glm::length(base.eye - base.target), 1e-5f);
    EXPECT_NEAR(c.eye.y, 1.0f, 1e-5f);
    EXPECT_EQ(c.target, base.target);
  }
  // A quarter turn about +y takes +x to -z.
  EXPECT_NEAR(orbit[1].eye.x, 0.0f, 1e-5f);
  EXPECT_NEAR(orbit[1].eye.z, -3.0f, 1e-5f);
  EXPECT_NEAR(orbit[2].eye.x, -3.0f, 1e-5f);
  EXPECT_TRUE(OrbitCameras(base, 0).empty());
}

}  // namespace
}  // namespace isostream::render
