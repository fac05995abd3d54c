#include "client/render/camera.h"

#include <algorithm>
#include <cfloat>
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
  const glm::dvec3 f(forward), u(up);
  if (glm::length(glm::cross(f, u)) > 1e-3 * glm::length(f) * glm::length(u)) return up;
  const glm::vec3 a = glm::abs(forward);
  if (a.x <= a.y && a.x <= a.z) return {1, 0, 0};
  return a.y <= a.z ? glm::vec3(0, 1, 0) : glm::vec3(0, 0, 1);
}

// In double, as the matrices below: a volume's box may be any size from ~1e-30 to ~1e30 world
// units, and float squares of its lengths underflow or overflow well inside that (a view of a
// box 1e-23 wide had no direction; one 1e21 wide, an infinite eye).
glm::vec3 Camera::Forward() const { return glm::normalize(glm::dvec3(target) - glm::dvec3(eye)); }
glm::vec3 Camera::Right() const {
  return glm::normalize(glm::cross(glm::dvec3(Forward()), glm::dvec3(up)));
}
glm::vec3 Camera::TrueUp() const { return glm::cross(Right(), Forward()); }

glm::mat4 Camera::ViewMatrix() const { return glm::mat4(ViewMatrixInDouble()); }
glm::mat4 Camera::ProjectionMatrix() const { return glm::mat4(ProjectionMatrixInDouble()); }
// The product in double: at extreme scales the factors' entries are far apart (1/size and
// size), their float product would round or overflow where the product itself is O(1).
glm::mat4 Camera::ViewProjection() const {
  return glm::mat4(ProjectionMatrixInDouble() * ViewMatrixInDouble());
}

glm::dmat4 Camera::ViewMatrixInDouble() const {
  return glm::lookAt(glm::dvec3(eye), glm::dvec3(target), glm::dvec3(up));
}

glm::dmat4 Camera::ProjectionMatrixInDouble() const {
  const double n = near_plane, f = far_plane;
  if (projection == Projection::kOrthographic) {
    const double hh = ortho_half_height, hw = hh * aspect;
    return glm::ortho(-hw, hw, -hh, hh, n, f);
  }
  return glm::perspective(glm::radians(double(fov_y_degrees)), double(aspect), n, f);
}

VerticalFrame FrameAbout(const glm::vec3& up) {
  VerticalFrame f;
  f.up = glm::vec3(glm::normalize(glm::dvec3(up)));
  const glm::vec3 along = std::abs(f.up.z) < 0.9f ? glm::vec3(0, 0, 1) : glm::vec3(1, 0, 0);
  f.front = glm::normalize(along - glm::dot(along, f.up) * f.up);
  f.side = glm::cross(f.up, f.front);
  return f;
}

float LengthOf(const glm::vec3& v) { return float(glm::length(glm::dvec3(v))); }

void EncloseSphere(float distance, float radius, Camera* camera) {
  camera->near_plane = std::max(distance - 1.1f * radius, 1e-3f * distance);
  camera->far_plane = distance + 1.1f * radius;
}

bool IsValidCamera(const Camera& c) {
  if (!Finite(c.eye) || !Finite(c.target) || !Finite(c.up)) return false;
  const glm::dvec3 d = glm::dvec3(c.target) - glm::dvec3(c.eye), up(c.up);
  if (!(glm::length(d) > 0.0) || !(glm::length(up) > 0.0)) return false;
  if (!(glm::length(glm::cross(glm::normalize(d), glm::normalize(up))) > 1e-6)) return false;
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
  // A point still gets a usable camera rather than a zero-size view: a radius of some float
  // steps of its coordinates (an absolute floor, 1e-6, made boxes smaller than it specks).
  const float point =
      64 * FLT_EPSILON *
      std::max({std::abs(center.x), std::abs(center.y), std::abs(center.z), FLT_MIN / FLT_EPSILON});
  const float radius = sphere_radius > point ? sphere_radius : point;
  const glm::dvec3 along(direction);
  const glm::vec3 dir =
      glm::length(along) > 0.0 ? glm::vec3(glm::normalize(along)) : glm::vec3(0, 0, 1);
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
  const glm::dvec3 l(lo), h(hi);
  return FrameSphere(glm::vec3(0.5 * (l + h)), 0.5f * LengthOf(hi - lo), direction, base);
}

std::vector<Camera> OrbitCameras(const Camera& base, int count) {
  return OrbitCameras(base, count, base.up);
}

std::vector<Camera> OrbitCameras(const Camera& base, int count, const glm::vec3& vertical) {
  std::vector<Camera> out;
  if (count <= 0) return out;
  out.reserve(count);
  const glm::vec3 axis = glm::normalize(vertical);
  for (int i = 0; i < count; ++i) {
    const float angle = glm::two_pi<float>() * float(i) / float(count);
    Camera c = base;
    c.eye = base.target + glm::angleAxis(angle, axis) * (base.eye - base.target);
    // The view's own up where it is not parallel to the vertical, else one that is.
    c.up = i == 0 ? base.up : UsableUp(c.target - c.eye, vertical);
    out.push_back(c);
  }
  return out;
}

}  // namespace isostream::render
