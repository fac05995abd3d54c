// isostream-render-mesh: draws a PLY frame (faces in draw order) headless and writes PNGs. A
// way to look at what the extractor produced before the streaming viewer exists; it uses the
// same MeshRenderer that viewer will.
//
// The faces are blended in file order whatever the camera: the picture is right for the eye the
// mesh was extracted for (isostream extract's default eye matches the default camera here when
// the mesh fills the volume) and only approximately so from other eyes, orbits included.
#include <absl/strings/str_cat.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/trigonometric.hpp>
#include <glm/vector_relational.hpp>
#include <new>
#include <string>
#include <vector>

#include "client/render/camera.h"
#include "client/render/headless_context.h"
#include "client/render/image.h"
#include "client/render/mesh_renderer.h"
#include "shared/number_list.h"
#include "shared/ply_io.h"

namespace isostream::render {
namespace {

struct Args {
  std::string input;
  std::string output;
  std::string size = "800x600";
  std::string eye;
  std::string target;
  std::string up = "0,1,0";
  std::string view_dir;
  std::string background;
  double fov = 0.0;  // 0: just wide enough to frame the mesh
  int orbit = 0;
};

absl::StatusOr<glm::dvec3> ParseVec3(const std::string& text, const char* what) {
  ISOSTREAM_ASSIGN_OR_RETURN(std::vector<double> v, ParseNumberList(text, what));
  if (v.size() != 3) return absl::InvalidArgumentError(absl::StrCat(what, " needs 3 numbers"));
  return glm::dvec3(v[0], v[1], v[2]);
}

absl::Status ParseSize(const std::string& text, int* width, int* height) {
  return ParseImageSize(text, "--size", 16384, width, height);
}

// The space the mesh is drawn in: world positions less the centre of the mesh's box, in units
// of the radius of the sphere about that centre through the farthest vertex, found in double.
// In single precision the framing of a mesh with coordinates near 1e20 overflowed (its squared
// lengths pass float's range), and GL would see a far-off mesh with most bits of its
// coordinates spent on the offset; drawn here, every mesh frames and renders as its copy at
// unit scale about the origin.
struct RenderSpace {
  glm::dvec3 centre{0.0};
  double scale = 1.0;         // world units per render unit
  float radius = 0.0f;        // of the framing sphere, in render units: 1, or 0 for a point
  float box_diagonal = 0.0f;  // of the mesh's box, in render units

  glm::vec3 FromWorld(const glm::dvec3& world) const { return glm::vec3((world - centre) / scale); }
  glm::dvec3 ToWorld(const glm::vec3& render) const { return centre + scale * glm::dvec3(render); }
};

glm::dvec3 Position(const OrderedMesh& mesh, size_t i) {
  return glm::dvec3(mesh.positions[3 * i], mesh.positions[3 * i + 1], mesh.positions[3 * i + 2]);
}

RenderSpace SpaceOf(const OrderedMesh& mesh) {
  glm::dvec3 lo(0.0), hi(0.0);
  for (size_t i = 0; i < mesh.vertex_count(); ++i) {
    lo = i == 0 ? Position(mesh, i) : glm::min(lo, Position(mesh, i));
    hi = i == 0 ? Position(mesh, i) : glm::max(hi, Position(mesh, i));
  }
  // Framing uses the sphere about the box centre through the farthest vertex: tighter than the
  // box's own bounding sphere for round meshes such as isosurfaces of blobs.
  RenderSpace space;
  space.centre = 0.5 * (lo + hi);
  double radius = 0.0;
  for (size_t i = 0; i < mesh.vertex_count(); ++i)
    radius = std::max(radius, glm::length(Position(mesh, i) - space.centre));
  if (radius > 0.0) {  // a point keeps world units
    space.scale = radius;
    space.radius = 1.0f;
  }
  space.box_diagonal = float(glm::length(hi - lo) / space.scale);
  return space;
}

// Positions in place, into `space`.
void MoveIntoSpace(const RenderSpace& space, OrderedMesh* mesh) {
  for (size_t i = 0; i < mesh->vertex_count(); ++i) {
    const glm::vec3 p = space.FromWorld(Position(*mesh, i));
    for (int a = 0; a < 3; ++a) mesh->positions[3 * i + a] = p[a];
  }
}

// The camera in `space`; --eye and --target are world positions.
absl::StatusOr<Camera> MakeCamera(const Args& args, const RenderSpace& space, float aspect) {
  const glm::vec3 centre(0.0f);
  const float radius = std::max(space.radius, 1e-6f);

  Camera camera;
  camera.aspect = aspect;
  ISOSTREAM_ASSIGN_OR_RETURN(const glm::dvec3 up, ParseVec3(args.up, "--up"));
  camera.up = glm::vec3(up);
  camera.target = centre;
  if (!args.target.empty()) {
    ISOSTREAM_ASSIGN_OR_RETURN(const glm::dvec3 target, ParseVec3(args.target, "--target"));
    camera.target = space.FromWorld(target);
  }
  if (!args.view_dir.empty()) {
    ISOSTREAM_ASSIGN_OR_RETURN(const glm::dvec3 d, ParseVec3(args.view_dir, "--view-dir"));
    if (d == glm::dvec3(0.0)) return absl::InvalidArgumentError("--view-dir is zero");
    camera.projection = Projection::kOrthographic;
    const glm::vec3 target = camera.target;
    camera = FrameSphere(centre, radius, glm::vec3(-glm::normalize(d)), camera);
    camera.eye += target - camera.target;
    camera.target = target;
  } else {
    if (!args.eye.empty()) {
      ISOSTREAM_ASSIGN_OR_RETURN(const glm::dvec3 eye, ParseVec3(args.eye, "--eye"));
      camera.eye = space.FromWorld(eye);
    } else {
      // isostream extract's default eye, with the mesh's box standing in for the volume's: for
      // a mesh that spans its volume both tools then use the same eye, and the draw order in
      // the file is exact for this picture.
      const glm::vec3 direction = glm::normalize(glm::vec3(0.8f, 0.6f, 1.0f));
      camera.eye = camera.target + 1.6f * std::max(space.box_diagonal, radius) * direction;
    }
    if (args.fov > 0.0) {
      camera.fov_y_degrees = float(args.fov);
    } else {
      // Just wide enough for the bounding sphere in the narrower image axis.
      const float distance = glm::length(centre - camera.eye);
      const float half =
          distance > 1.05f * radius ? std::asin(1.05f * radius / distance) : glm::radians(60.0f);
      const float half_v = std::atan(std::tan(half) / std::min(1.0f, aspect));
      camera.fov_y_degrees = std::min(glm::degrees(2.0f * half_v), 150.0f);
    }
  }
  // Clip planes that enclose the mesh's bounding sphere from wherever the eye ended up.
  const float distance = glm::dot(centre - camera.eye, camera.Forward());
  camera.far_plane = std::max(distance + 1.1f * radius, 2e-3f * radius);
  camera.near_plane = std::max(distance - 1.1f * radius, 1e-3f * camera.far_plane);
  if (!IsValidCamera(camera)) {
    // Named by cause: a far eye was reported as "--eye equals --target".
    const glm::vec3 e = camera.eye, t = camera.target;
    const bool finite = std::isfinite(e.x) && std::isfinite(e.y) && std::isfinite(e.z);
    if (finite && e == t)
      return absl::InvalidArgumentError("the camera is degenerate: --eye equals --target");
    if (finite && glm::length(glm::cross(t - e, camera.up)) == 0)
      return absl::InvalidArgumentError("the camera is degenerate: --up is parallel to the view");
    return absl::InvalidArgumentError(
        "the eye is too far from the mesh for its size (its distance and the mesh's extent "
        "cannot both be held in single precision): move --eye closer");
  }
  return camera;
}

absl::Status Run(const Args& args) {
  int width = 0, height = 0;
  ISOSTREAM_RETURN_IF_ERROR(ParseSize(args.size, &width, &height));
  // Before any work: unwritable files were found after rendering.
  ISOSTREAM_RETURN_IF_ERROR(CheckPngOutputs(args.output, args.orbit));
  ISOSTREAM_ASSIGN_OR_RETURN(OrderedMesh mesh, ReadPly(args.input));
  const RenderSpace space = SpaceOf(mesh);
  ISOSTREAM_ASSIGN_OR_RETURN(Camera camera, MakeCamera(args, space, float(width) / float(height)));
  MoveIntoSpace(space, &mesh);

  HeadlessContextOptions options;
  options.width = width;
  options.height = height;
  ISOSTREAM_ASSIGN_OR_RETURN(std::unique_ptr<HeadlessContext> context,
                             HeadlessContext::Create(options));
  ISOSTREAM_ASSIGN_OR_RETURN(std::unique_ptr<MeshRenderer> renderer, MeshRenderer::Create());
  if (!args.background.empty()) {
    ISOSTREAM_ASSIGN_OR_RETURN(const glm::dvec3 rgb, ParseVec3(args.background, "--background"));
    const glm::vec3 bg(rgb);
    if (glm::any(glm::lessThan(bg, glm::vec3(0.0f))) ||
        glm::any(glm::greaterThan(bg, glm::vec3(1.0f))))
      return absl::InvalidArgumentError("--background: r,g,b must be in 0..1");
    renderer->SetBackground(glm::vec4(bg, 1.0f));
  }

  const auto start = std::chrono::steady_clock::now();
  renderer->BeginFrame();
  ISOSTREAM_RETURN_IF_ERROR(renderer->AddChunk(mesh));
  ISOSTREAM_RETURN_IF_ERROR(renderer->EndFrame());

  const std::vector<Camera> cameras =
      args.orbit > 0 ? OrbitCameras(camera, args.orbit) : std::vector<Camera>{camera};
  for (size_t i = 0; i < cameras.size(); ++i) {
    ISOSTREAM_RETURN_IF_ERROR(renderer->Render(cameras[i]));
    ISOSTREAM_ASSIGN_OR_RETURN(Image image, context->ReadPixels());
    const std::string path =
        args.orbit > 0 ? NumberedPngPath(args.output, int(i), args.orbit) : args.output;
    ISOSTREAM_RETURN_IF_ERROR(WritePng(image, path));
  }
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  const glm::dvec3 eye = space.ToWorld(camera.eye), target = space.ToWorld(camera.target);
  std::fprintf(stderr,
               "%zu triangles, %zu image(s) %dx%d in %.1f ms on %s (%s); eye %.4g,%.4g,%.4g "
               "target %.4g,%.4g,%.4g\n",
               mesh.triangle_count(), cameras.size(), width, height, ms,
               context->renderer_name().c_str(), context->platform_name().c_str(), eye.x, eye.y,
               eye.z, target.x, target.y, target.z);
  return absl::OkStatus();
}

}  // namespace
}  // namespace isostream::render

int main(int argc, char** argv) {
  isostream::render::Args args;
  CLI::App app{
      "Draw a PLY mesh (faces in back-to-front draw order) with alpha blending, headless, to "
      "PNG. Faces are blended in file order for every camera, so the picture is exact only for "
      "the eye the mesh was extracted for."};
  app.add_option("input", args.input, "PLY file written by isostream extract")->required();
  app.add_option("-o,--output", args.output, "PNG to write (with --orbit: name_000.png, ...)")
      ->required();
  app.add_option("--size", args.size, "image size WxH")->capture_default_str();
  auto* eye = app.add_option("--eye", args.eye, "perspective eye x,y,z (default: frame the mesh)");
  app.add_option("--target", args.target, "look-at point x,y,z (default: centre of the mesh)");
  app.add_option("--up", args.up, "up direction x,y,z")->capture_default_str();
  auto* dir = app.add_option("--view-dir", args.view_dir, "orthographic view direction x,y,z");
  eye->excludes(dir);
  app.add_option("--fov", args.fov, "vertical field of view, degrees (default: fit the mesh)")
      ->check(CLI::Range(1.0, 179.0));
  app.add_option("--orbit", args.orbit, "write N images on a full turn about --up")
      ->check(CLI::Range(1, 100000));
  app.add_option("--background", args.background, "background r,g,b in 0..1 (default white)");
  CLI11_PARSE(app, argc, argv);

  absl::Status status;
  try {
    status = isostream::render::Run(args);
  } catch (const std::bad_alloc&) {
    status = absl::ResourceExhaustedError("out of memory");
  } catch (const std::exception& e) {
    status = absl::InternalError(e.what());
  }
  if (!status.ok()) {
    std::fprintf(stderr, "isostream-render-mesh: %s\n", std::string(status.message()).c_str());
    return 1;
  }
  return 0;
}
