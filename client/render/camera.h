// Camera for the client renderer: where the eye is and how the scene is projected. Plain data
// plus the matrices OpenGL needs; the same camera drives the rasterizer, the Embree reference
// in the tests and the request a future session client sends to the server, so everything the
// shading needs (eye, viewing direction, basis) is derived here in one place.
#pragma once

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>
#include <vector>

namespace isostream::render {

enum class Projection { kPerspective, kOrthographic };

struct Camera {
  Projection projection = Projection::kPerspective;
  glm::vec3 eye{0.0f, 0.0f, 3.0f};
  glm::vec3 target{0.0f};
  glm::vec3 up{0.0f, 1.0f, 0.0f};  // need not be orthogonal to the view, must not be parallel
  float fov_y_degrees = 40.0f;     // perspective: full vertical field of view
  float ortho_half_height = 1.0f;  // orthographic: half the height of the view volume, world units
  float near_plane = 0.1f;         // distances along the viewing direction from the eye, > 0
  float far_plane = 100.0f;        // orthographic too: the eye is the centre of the near plane
  float aspect = 1.0f;             // width / height of the viewport

  // Unit vectors of the right-handed eye frame: forward points from the eye to the target,
  // right and true_up span the image plane (true_up is `up` made orthogonal to forward).
  glm::vec3 Forward() const;
  glm::vec3 Right() const;
  glm::vec3 TrueUp() const;

  glm::mat4 ViewMatrix() const;        // world -> eye space, eye at origin looking down -z
  glm::mat4 ProjectionMatrix() const;  // eye space -> clip space, OpenGL depth range [-1, 1]
  glm::mat4 ViewProjection() const;    // world -> clip space
  glm::dmat4 ViewMatrixInDouble() const;
  glm::dmat4 ProjectionMatrixInDouble() const;
};

// A right-handed frame about a vertical `up` (any length): side, up and front unit vectors,
// the world's x, y and z for +y. Front is the world's z made perpendicular to up (its x where
// up lies near z). Default views and orbits are laid out in it, so --up turns them whole.
struct VerticalFrame {
  glm::vec3 side, up, front;
};
VerticalFrame FrameAbout(const glm::vec3& up);

// |v|, computed in double: the square of a float vector's length underflows below ~1e-19 and
// overflows above ~1e19, inside the sizes a volume may have.
float LengthOf(const glm::vec3& v);

// Near and far planes enclosing the sphere of `radius` about a point `distance` from the eye,
// with a margin (near stays at least 1e-3 of the distance: an eye inside the sphere still
// gets a depth range single precision can resolve).
void EncloseSphere(float distance, float radius, Camera* camera);

// True when the camera's fields describe a projection: finite values, eye != target, up not
// parallel to the viewing direction, 0 < near < far, aspect > 0, and a field of view in (0, 180)
// or a positive orthographic half height.
bool IsValidCamera(const Camera& camera);

// An up vector usable with `forward`: `up` if it is not (nearly) parallel, otherwise the world
// axis least aligned with forward, so a view straight down or up never has a degenerate basis.
glm::vec3 UsableUp(const glm::vec3& forward, const glm::vec3& up);

// A camera looking at `center` from `direction` (from the target towards the eye; any length),
// placed so that the sphere of `radius` about `center` fits the view in both axes for the
// camera's aspect, projection and field of view, with a 5% margin. Near and far enclose the
// sphere with a margin. `base` supplies projection, fov, up (replaced by a usable one if it is
// parallel to the direction) and aspect.
Camera FrameSphere(const glm::vec3& center, float radius, const glm::vec3& direction,
                   const Camera& base);

// FrameSphere for the bounding sphere of the axis-aligned box [lo, hi].
Camera FrameBox(const glm::vec3& lo, const glm::vec3& hi, const glm::vec3& direction,
                const Camera& base);

// `count` cameras evenly spaced on a full turn around base.target about the axis base.up,
// starting at base itself (element 0 equals base). Distance to the target, height along the
// axis and all other fields are kept. count <= 0 gives an empty vector.
std::vector<Camera> OrbitCameras(const Camera& base, int count);
// The same about the axis `vertical` (the viewer's --up), which base.up may not be (a view along
// the vertical takes another up): each camera's up is a usable one for its own view.
std::vector<Camera> OrbitCameras(const Camera& base, int count, const glm::vec3& vertical);

}  // namespace isostream::render
