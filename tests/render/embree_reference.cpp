#include "tests/render/embree_reference.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <glm/geometric.hpp>
#include <glm/mat4x4.hpp>
#include <memory>
#include <string>
#include <vector>

namespace isostream::render::testing {
namespace {

struct Hit {
  float t;
  unsigned prim;
  float u, v;
};

// Embree passes the context pointer through to the filter; extending the struct is its
// documented way of handing per-ray data to callbacks.
struct CollectingContext {
  RTCIntersectContext context;
  std::vector<Hit>* hits;
};

// Records every candidate and rejects it, so traversal goes on to the next surface along the
// ray instead of stopping at the nearest.
void CollectAllHits(const RTCFilterFunctionNArguments* args) {
  const auto* collector = reinterpret_cast<const CollectingContext*>(args->context);
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] != -1) continue;
    collector->hits->push_back(
        {RTCRayN_tfar(args->ray, args->N, i), RTCHitN_primID(args->hit, args->N, i),
         RTCHitN_u(args->hit, args->N, i), RTCHitN_v(args->hit, args->N, i)});
    args->valid[i] = 0;
  }
}

glm::vec3 Vertex(const std::vector<float>& a, uint32_t v) {
  return {a[3 * v], a[3 * v + 1], a[3 * v + 2]};
}

struct DeviceDeleter {
  void operator()(RTCDevice d) const { rtcReleaseDevice(d); }
};
struct SceneDeleter {
  void operator()(RTCScene s) const { rtcReleaseScene(s); }
};

}  // namespace

absl::StatusOr<Image> TraceReference(const OrderedMesh& mesh, const Camera& camera, int width,
                                     int height, const Palette& palette, const Lighting& lighting,
                                     const glm::vec4& background) {
  std::unique_ptr<RTCDeviceTy, DeviceDeleter> device(rtcNewDevice(nullptr));
  if (!device) return absl::InternalError("rtcNewDevice failed");
  std::unique_ptr<RTCSceneTy, SceneDeleter> scene(rtcNewScene(device.get()));
  // Robust mode makes rays through shared edges hit rather than slip between triangles, as the
  // rasterizer's fill rule never leaves such pixels empty.
  rtcSetSceneFlags(scene.get(), RTC_SCENE_FLAG_ROBUST);
  RTCGeometry geometry = rtcNewGeometry(device.get(), RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0,
                                                               RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                                               mesh.vertex_count()));
  std::memcpy(vertices, mesh.positions.data(), mesh.positions.size() * sizeof(float));
  auto* indices = static_cast<uint32_t*>(
      rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                              3 * sizeof(uint32_t), mesh.triangle_count()));
  std::memcpy(indices, mesh.triangles.data(), mesh.triangles.size() * sizeof(uint32_t));
  rtcSetGeometryIntersectFilterFunction(geometry, CollectAllHits);
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(scene.get(), geometry);
  rtcReleaseGeometry(geometry);
  rtcCommitScene(scene.get());
  if (rtcGetDeviceError(device.get()) != RTC_ERROR_NONE)
    return absl::InternalError("Embree could not build the scene");

  // Rays run from the near plane (t = 0) to the far plane (t = 1) through each pixel centre.
  const glm::dmat4 unproject = glm::inverse(glm::dmat4(camera.ViewProjection()));
  auto to_world = [&](double x, double y, double z) {
    const glm::dvec4 p = unproject * glm::dvec4(x, y, z, 1.0);
    return glm::dvec3(p) / p.w;
  };
  const bool orthographic = camera.projection == Projection::kOrthographic;
  const glm::vec3 forward = camera.Forward();
  const glm::vec3 light = LightDirectionInWorld(lighting, camera);

  Image image;
  image.width = width;
  image.height = height;
  image.rgba.resize(4 * size_t(width) * size_t(height));
  std::vector<Hit> hits;
  for (int py = 0; py < height; ++py) {
    for (int px = 0; px < width; ++px) {
      const double x = 2.0 * (px + 0.5) / width - 1.0;
      const double y = 1.0 - 2.0 * (py + 0.5) / height;  // image rows run top down
      const glm::dvec3 from = to_world(x, y, -1.0);
      const glm::dvec3 to = to_world(x, y, 1.0);
      RTCRayHit rh;
      std::memset(&rh, 0, sizeof(rh));
      rh.ray.org_x = float(from.x);
      rh.ray.org_y = float(from.y);
      rh.ray.org_z = float(from.z);
      rh.ray.dir_x = float(to.x - from.x);
      rh.ray.dir_y = float(to.y - from.y);
      rh.ray.dir_z = float(to.z - from.z);
      rh.ray.tnear = 0.0f;
      rh.ray.tfar = 1.0f;
      rh.ray.mask = 0xFFFFFFFFu;
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      hits.clear();
      CollectingContext collector;
      rtcInitIntersectContext(&collector.context);
      collector.hits = &hits;
      rtcIntersect1(scene.get(), &collector.context, &rh);

      // Farthest first. A triangle can be reported more than once when it sits in several BVH
      // leaves, and a ray through a shared edge meets both triangles at one point: either way
      // the surface is crossed once there, as the rasterizer draws it once.
      std::sort(hits.begin(), hits.end(), [](const Hit& a, const Hit& b) { return a.t > b.t; });
      glm::vec3 color(background);
      const Hit* previous = nullptr;
      for (const Hit& h : hits) {
        const uint8_t surface = mesh.surface[h.prim];
        if (previous != nullptr && mesh.surface[previous->prim] == surface &&
            std::abs(previous->t - h.t) < 1e-6f) {
          continue;
        }
        previous = &h;
        const uint32_t* tri = mesh.triangles.data() + 3 * size_t(h.prim);
        const float w = 1.0f - h.u - h.v;
        const glm::vec3 p = w * Vertex(mesh.positions, tri[0]) +
                            h.u * Vertex(mesh.positions, tri[1]) +
                            h.v * Vertex(mesh.positions, tri[2]);
        glm::vec3 n = w * Vertex(mesh.normals, tri[0]) + h.u * Vertex(mesh.normals, tri[1]) +
                      h.v * Vertex(mesh.normals, tri[2]);
        n = glm::normalize(n);
        const glm::vec3 v = orthographic ? -forward : glm::normalize(camera.eye - p);
        if (glm::dot(n, v) < 0.0f) n = -n;
        const glm::vec3 half = glm::normalize(light + v);
        const float lambert = std::max(glm::dot(n, light), 0.0f);
        const float highlight = std::pow(std::max(glm::dot(n, half), 0.0f), lighting.shininess);
        const SurfaceStyle& style = palette[surface];
        const glm::vec3 rgb =
            glm::min(style.color * (lighting.ambient + lighting.diffuse * lambert) +
                         glm::vec3(lighting.specular * highlight),
                     glm::vec3(1.0f));
        color = style.opacity * rgb + (1.0f - style.opacity) * color;
      }
      uint8_t* out = image.pixel(px, py);
      for (int c = 0; c < 3; ++c)
        out[c] = uint8_t(std::lround(std::clamp(color[c], 0.0f, 1.0f) * 255.0f));
      out[3] = 255;
    }
  }
  return image;
}

}  // namespace isostream::render::testing
