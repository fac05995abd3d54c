#include "client/render/camera.h"

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>

namespace isostream::render {
namespace {

bool Finite(const glm::vec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

}  // namespace

glm::vec3 UsableUp(const glm::vec3& forward, const glm::vec3& up) {
  const float scale = glm::length(forward) * glm::length(up);
  if (glm::length(glm::cross(forward, up)) > 1e-3f * scale) return up;
  const glm::vec3 a = glm::abs(forward);
  if (a.x <= a.y && a.x <= a.z) return {1, 0, 0};
  return a.y <= a.z ? glm::vec3(0, 1, 0) : glm::vec3(0, 0, 1);
}

glm::vec3 Camera::Forward() const { return glm::normalize(target - eye); }
glm::vec3 Camera::Right() const { return glm::normalize(glm::cross(Forward(), up)); }
glm::vec3 Camera::TrueUp() const { return glm::cross(Right(), Forward()); }

glm::mat4 Camera::ViewMatrix() const { return glm::lookAt(eye, target, up); }

glm::mat4 Camera::ProjectionMatrix() const {
  if (projection == Projection::kOrthographic) {
    const float hw = ortho_half_height * aspect;
    return glm::ortho(-hw, hw, -ortho_half_height, ortho_half_height, near_plane, far_plane);
  }
  return glm::perspective(glm::radians(fov_y_degrees), aspect, near_plane, far_plane);
}

void EncloseSphere(float distance, float radius, Camera* camera) {
  camera->near_plane = std::max(distance - 1.1f * radius, 1e-3f * distance);
  camera->far_plane = distance + 1.1f * radius;
}

bool IsValidCamera(const Camera& c) {
  if (!Finite(c.eye) || !Finite(c.target) || !Finite(c.up)) return false;
  const glm::vec3 d = c.target - c.eye;
  if (!(glm::length(d) > 0.0f) || !(glm::length(c.up) > 0.0f)) return false;
  if (!(glm::length(glm::cross(glm::normalize(d), glm::normalize(c.up))) > 1e-6f)) return false;
  if (!(c.near_plane > 0.0f) || !(c.far_plane > c.near_plane) || !std::isfinite(c.far_plane))
    return false;
  if (!(c.aspect > 0.0f) || !std::isfinite(c.aspect)) return false;
  if (c.projection == Projection::kOrthographic)
    return c.ortho_half_height > 0.0f && std::isfinite(c.ortho_half_height);
  return c.fov_y_degrees > 0.0f && c.fov_y_degrees < 180.0f;
}

Camera FrameSphere(const glm::vec3& center, float sphere_radius, const glm::vec3& direction,
                   const Camera& base) {
  Camera c = base;
  c.target = center;
  // A point still gets a usable camera rather than a zero-size view.
  const float radius = std::max(sphere_radius, 1e-6f);
  const glm::vec3 dir =
      glm::length(direction) > 0.0f ? glm::normalize(direction) : glm::vec3(0, 0, 1);
  c.up = UsableUp(-dir, base.up);
  const float margin = 1.05f;
  float distance;
  if (c.projection == Projection::kOrthographic) {
    // The narrower image axis must still cover the sphere's diameter.
    c.ortho_half_height = margin * radius / std::min(1.0f, c.aspect);
    distance = 2.0f * radius;
  } else {
    const float half_v = 0.5f * glm::radians(c.fov_y_degrees);
    const float half_h = std::atan(c.aspect * std::tan(half_v));
    distance = margin * radius / std::sin(std::min(half_v, half_h));
  }
  c.eye = c.target + distance * dir;
  EncloseSphere(distance, radius, &c);
  return c;
}

Camera FrameBox(const glm::vec3& lo, const glm::vec3& hi, const glm::vec3& direction,
                const Camera& base) {
  return FrameSphere(0.5f * (lo + hi), 0.5f * glm::length(hi - lo), direction, base);
}

std::vector<Camera> OrbitCameras(const Camera& base, int count) {
  std::vector<Camera> out;
  if (count <= 0) return out;
  out.reserve(count);
  const glm::vec3 axis = glm::normalize(base.up);
  for (int i = 0; i < count; ++i) {
    const float angle = glm::two_pi<float>() * float(i) / float(count);
    Camera c = base;
    c.eye = base.target + glm::angleAxis(angle, axis) * (base.eye - base.target);
    out.push_back(c);
  }
  return out;
}

}  // namespace isostream::render
