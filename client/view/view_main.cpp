// isostream-view: the thin client. It opens a Session with isostreamd, sends a view, decodes
// the chunks as they arrive and uploads them in arrival order; the triangles come already
// sorted back to front, so drawing them in that order with alpha blending is the whole job.
// Headless by default (EGL surfaceless/device, PNG out); --orbit N writes N views around the
// volume, each one a fresh frame ordered by the server for its own eye.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/trigonometric.hpp>
#include <mutex>
#include <new>
#include <string>
#include <thread>
#include <vector>

#include "client/net/session_client.h"
#include "client/render/camera.h"
#include "client/render/headless_context.h"
#include "client/render/image.h"
#include "client/render/mesh_renderer.h"
#include "client/view/frame_upload.h"
#include "client/view/view_request.h"
#include "client/view/window_view.h"
#include "shared/file_io.h"
#include "shared/frame_notes.h"
#include "shared/given_number.h"
#include "shared/malloc_tuning.h"
#include "shared/number_list.h"

namespace isostream::view {
namespace {

namespace pb = ::isostream::v1;

struct Args {
  std::string server = "127.0.0.1:7878";
  std::string volume;
  std::string iso;
  double eps = std::nan("");  // NaN: not given
  int64_t budget = -1;
  std::string eye;
  std::string up = "0,1,0";
  int samples = 4;
  std::string size = "800x800";
  std::string output;
  std::string token;
  std::string tls_ca;
  int64_t max_frame_triangles = net::kDefaultMaxFrameTriangles;
  std::string codec = "draco";
  int orbit = 0;
  bool window = false;
  int exit_after_frames = 0;
  bool progressive = true;
  int timeout_s = 60;  // headless: give up after this long without data from the server
};

absl::StatusOr<std::vector<double>> ParseNumbers(const std::string& text, const char* what) {
  return ParseNumberList(text, what);
}

// Cancels a session that has heard nothing from the server for `limit` (0: never): a Session
// has no deadline (it lives as long as views come), so a stalled daemon would otherwise hold
// the viewer forever.
class Watchdog {
 public:
  Watchdog(net::Session& session, std::chrono::seconds limit) : session_(session), limit_(limit) {
    if (limit_.count() > 0) thread_ = std::thread([this] { Watch(); });
  }
  ~Watchdog() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
  }
  void Touch() {
    std::lock_guard<std::mutex> lock(mu_);
    last_ = Clock::now();
  }
  bool fired() const { return fired_.load(); }

 private:
  using Clock = std::chrono::steady_clock;
  void Watch() {
    std::unique_lock<std::mutex> lock(mu_);
    while (!cv_.wait_for(lock, std::chrono::milliseconds(100), [&] { return stop_; })) {
      if (Clock::now() - last_ > limit_) {
        fired_ = true;
        session_.TryCancel();  // the blocked Read returns false
        return;
      }
    }
  }
  net::Session& session_;
  const std::chrono::seconds limit_;
  std::mutex mu_;
  std::condition_variable cv_;
  Clock::time_point last_ = Clock::now();
  bool stop_ = false;
  std::atomic<bool> fired_{false};
  std::thread thread_;
};

// Receives one view's frame: chunks are uploaded as they arrive into the renderer's pending
// frame, which replaces the shown one whole when complete. Coarse frames of a progressive view
// are shown on the way (a window would display them); the refined frame is returned.
// Gives up after `idle_limit` without a chunk (0: never).
absl::StatusOr<net::Frame> ReceiveFrame(net::Session& session, uint64_t request_id,
                                        render::MeshRenderer& renderer, int* coarse_frames,
                                        std::chrono::seconds idle_limit,
                                        int64_t max_frame_triangles) {
  net::FrameAssembler assembler(max_frame_triangles);
  pb::FrameChunk chunk;
  bool frame_open = false;
  Watchdog watchdog(session, idle_limit);
  while (session.Read(&chunk)) {
    // Only this view's chunks are progress: a server sending others' for ever (or an older
    // view's frame that never ends) kept the watchdog quiet past --timeout-s.
    if (chunk.frame_id() != request_id) continue;  // an older view's frame, superseded
    watchdog.Touch();
    ISOSTREAM_RETURN_IF_ERROR(AddAndUpload(assembler, chunk, renderer, &frame_open));
    if (!assembler.complete()) continue;
    ISOSTREAM_RETURN_IF_ERROR(renderer.EndFrame());
    frame_open = false;
    if (assembler.frame().coarse) {
      ++*coarse_frames;
      continue;
    }
    return assembler.Take();
  }
  if (watchdog.fired())
    return absl::DeadlineExceededError("no data from the server for " +
                                       std::to_string(idle_limit.count()) + " s");
  const absl::Status status = session.Finish();
  if (!status.ok()) return status;
  // Ended with OK mid-frame: the server broke the protocol (a daemon that stops says so).
  return absl::DataLossError("the stream ended without a complete frame");
}

render::Camera FitToMesh(const render::Camera& unfitted, const OrderedMesh& mesh) {
  render::Camera camera = unfitted;
  if (mesh.vertex_count() == 0) return camera;
  glm::vec3 lo(mesh.positions[0], mesh.positions[1], mesh.positions[2]), hi = lo;
  for (size_t i = 0; i < mesh.vertex_count(); ++i) {
    const glm::vec3 p(mesh.positions[3 * i], mesh.positions[3 * i + 1], mesh.positions[3 * i + 2]);
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  const glm::vec3 center = 0.5f * (lo + hi);
  const float distance = render::LengthOf(camera.eye - center);
  // At least a millionth of the distance: a frame whose vertices all fall on one point
  // (a single bright voxel's surface, 26 vertices in one place) left near and far equal in
  // single precision, and the frame could not be drawn.
  const float radius = std::max(0.5f * render::LengthOf(hi - lo), 1e-6f * distance);
  if (distance <= radius * 1.05f) return camera;  // eye inside: keep the volume framing
  if (camera.projection == render::Projection::kPerspective) {
    camera.target = center;
    camera.fov_y_degrees = std::min(170.0f, 2.1f * glm::degrees(std::asin(radius / distance)));
    if (camera.aspect < 1) {
      const float half =
          std::atan(std::tan(glm::radians(camera.fov_y_degrees) / 2) / camera.aspect);
      camera.fov_y_degrees = std::min(170.0f, glm::degrees(2 * half));
    }
  }
  render::EncloseSphere(distance, radius, &camera);
  return render::IsValidCamera(camera) ? camera : unfitted;
}

// Exits 2 for a request that cannot be made as given (as usage errors do), 1 for anything that
// went wrong while making it.
int Fail(const absl::Status& status) {
  std::fprintf(stderr, "isostream-view: %s\n", std::string(status.message()).c_str());
  return status.code() == absl::StatusCode::kInvalidArgument ? 2 : 1;
}

int Run(const Args& args) {
  if (args.window) {
    const char* display = std::getenv("DISPLAY");
    const char* wayland = std::getenv("WAYLAND_DISPLAY");
    if ((!display || !*display) && (!wayland || !*wayland)) {
      std::fprintf(stderr,
                   "isostream-view: --window needs a display, and neither DISPLAY nor "
                   "WAYLAND_DISPLAY is set; render headless with -o frame.png instead\n");
      return 2;
    }
  } else if (args.output.empty()) {
    return Fail(absl::InvalidArgumentError("give -o frame.png (or --window)"));
  }
  // The files it will write (with --orbit, name_000.png, ...), before any work.
  if (!args.output.empty())
    // A window writes one screenshot, whatever its orbit.
    if (const absl::Status writable =
            render::CheckPngOutputs(args.output, args.window ? 0 : args.orbit);
        !writable.ok())
      return Fail(absl::InvalidArgumentError(writable.message()));  // an argument: exit 2
  int width = 0, height = 0;
  const absl::Status size_ok = ParseImageSize(args.size, "--size", 16384, &width, &height);
  if (!size_ok.ok()) return Fail(size_ok);

  net::ClientOptions options;
  options.max_frame_triangles = args.max_frame_triangles;
  // Connecting and the volume's description wait no longer than the frames do; frames are
  // bounded by silence, not as a whole (Connection): only the unary calls by the call timeout.
  net::ConnectionFlags flags;
  flags.server = args.server;
  flags.token = args.token;
  flags.tls_ca = args.tls_ca;
  flags.timeout_s = args.timeout_s;
  flags.timeout_means = "--timeout-s bounds each wait for the server";
  auto client = net::ConnectWith(flags, &options);
  if (!client.ok()) return Fail(client.status());
  // Errors of calls to the daemon, with a hint where the code alone says little.
  auto call_failed = [&](const absl::Status& s) {
    return Fail(absl::Status(s.code(), net::ExplainCallError(s, options)));
  };
  // The bounds and the value range are all the viewer needs: one bin costs the server nothing.
  auto info = (*client)->GetVolumeInfo(args.volume, 1);
  if (!info.ok()) return call_failed(info.status());
  if (info->dims_size() != 3)
    return Fail(absl::DataLossError("the server described the volume with " +
                                    std::to_string(info->dims_size()) + " dims, not 3"));

  // The volume's box frames the default camera and gives default isovalues.
  glm::vec3 lo, hi;
  for (int a = 0; a < 3; ++a) {
    const float s = a == 0   ? info->spacing().x()
                    : a == 1 ? info->spacing().y()
                             : info->spacing().z();
    const float o = a == 0 ? info->origin().x() : a == 1 ? info->origin().y() : info->origin().z();
    lo[a] = o;
    hi[a] = o + s * float(info->dims(a) - 1);
  }
  // In double: the float range of values near +-FLT_MAX overflows.
  const double min_value = info->min_value(), value_range = double(info->max_value()) - min_value;
  std::vector<double> iso;
  bool some_inside = true;  // some isovalue within the values: the defaults are
  if (args.iso.empty() && value_range == 0) {
    std::fprintf(stderr, "isostream-view: %s holds the one value %s: it has no isosurface\n",
                 args.volume.c_str(), ShortestText(min_value).c_str());
    iso.push_back(min_value);
  } else if (args.iso.empty()) {
    const std::string coarse = CoarseValuesNote(info->min_value(), info->max_value(), args.volume);
    if (!coarse.empty()) std::fprintf(stderr, "isostream-view: note: %s\n", coarse.c_str());
    // As the server holds them (float), distinct and above the lowest value (a crossing needs a
    // corner below the isovalue): a range of a few float steps (float64 data far from 0) rounded
    // them into one, "given twice". Fewer then, else the top value.
    for (double f : {0.2, 0.4, 0.6}) {
      const double v = double(static_cast<float>(min_value + f * value_range));
      if (v > min_value && std::find(iso.begin(), iso.end(), v) == iso.end()) iso.push_back(v);
    }
    if (iso.empty()) iso.push_back(info->max_value());
  } else {
    auto parsed = ParseNumbers(args.iso, "--iso");
    if (!parsed.ok()) return Fail(parsed.status());
    iso = *parsed;
    some_inside = NoteIsovaluesOutside("isostream-view", iso, info->min_value(), info->max_value(),
                                       args.volume);
  }
  render::Camera base;
  base.aspect = float(width) / float(height);
  auto up = ParseNumbers(args.up, "--up");
  if (!up.ok()) return Fail(up.status());
  if (up->size() != 3) return Fail(absl::InvalidArgumentError("--up needs x,y,z"));
  base.up = glm::vec3((*up)[0], (*up)[1], (*up)[2]);
  if (!(render::LengthOf(base.up) > 0) || !std::isfinite(render::LengthOf(base.up)))
    return Fail(absl::InvalidArgumentError("--up " + args.up + " has no direction"));
  // From the front, a little to the side and above, whatever the vertical.
  const render::VerticalFrame vertical = render::FrameAbout(base.up);
  glm::vec3 direction = 0.8f * vertical.side + 0.6f * vertical.up + 1.0f * vertical.front;
  const glm::vec3 center = 0.5f * (lo + hi);
  render::Camera camera = render::FrameBox(lo, hi, direction, base);
  // Single precision places boxes from ~1e-30 to ~1e30 world units, not all of them viewably.
  if (args.eye.empty() && !render::IsValidCamera(camera))
    return Fail(absl::InvalidArgumentError(
        "the volume's box, from (" + ShortestText(lo.x) + ", " + ShortestText(lo.y) + ", " +
        ShortestText(lo.z) + ") to (" + ShortestText(hi.x) + ", " + ShortestText(hi.y) + ", " +
        ShortestText(hi.z) + "), cannot be framed in single precision"));
  if (!args.eye.empty()) {
    auto e = ParseNumbers(args.eye, "--eye");
    if (!e.ok()) return Fail(e.status());
    if (e->size() != 3) return Fail(absl::InvalidArgumentError("--eye needs x,y,z"));
    direction = glm::vec3((*e)[0], (*e)[1], (*e)[2]) - center;
    if (render::LengthOf(direction) == 0)
      return Fail(absl::InvalidArgumentError("--eye is at the volume's centre"));
    // Keep the given eye: aim at the centre, open the field of view to the bounding sphere and
    // put near and far around it (FrameBox's own planes belong to its own eye distance).
    const glm::vec3 eye((*e)[0], (*e)[1], (*e)[2]);
    const float radius = 0.5f * render::LengthOf(hi - lo);
    const float distance = render::LengthOf(eye - center);
    camera = base;
    camera.eye = eye;
    camera.target = center;
    camera.up = render::UsableUp(center - eye, base.up);  // a view from straight above or below
    camera.fov_y_degrees = distance > radius
                               ? std::min(170.0f, 2.1f * glm::degrees(std::asin(radius / distance)))
                               : 90.0f;
    render::EncloseSphere(distance, radius, &camera);
    // Refused before any frame is fetched: an eye so far that single precision cannot tell
    // near from far (1e30, say) has no projection to draw with.
    if (!render::IsValidCamera(camera))
      return Fail(absl::InvalidArgumentError(
          "--eye " + args.eye + " is too far from the volume (or too close to it) to draw from"));
  }

  ViewState state;
  state.volume = args.volume;
  state.isovalues = iso;
  state.budget = args.budget;
  // Not given: 0.2% of the value range. A given eps goes to the server as it is: the server
  // validates it and says what is wrong.
  state.eps = !std::isnan(args.eps) ? args.eps : 0.002 * value_range;
  state.raw_codec = args.codec == "raw";
  state.progressive = args.progressive;

  render::HeadlessContextOptions ctx_options;
  ctx_options.width = width;
  ctx_options.height = height;
  ctx_options.samples = args.samples;
  auto context = render::HeadlessContext::Create(ctx_options);
  if (!context.ok()) return Fail(context.status());
  auto renderer = render::MeshRenderer::Create();
  if (!renderer.ok()) return Fail(renderer.status());
  render::Palette palette = render::DefaultPalette();
  (*renderer)->SetPalette(palette);

  if (args.window) {
    WindowOptions window;
    window.width = width;
    window.height = height;
    window.state = state;
    window.camera = camera;
    window.world_up = base.up;
    window.samples = args.samples;
    window.value_range = value_range;
    window.scene_radius = 0.5f * render::LengthOf(hi - lo);
    window.exit_after_frames = args.exit_after_frames;
    window.orbit = args.orbit;
    window.timeout_s = args.timeout_s;
    window.screenshot = args.output;
    renderer->reset();  // the window makes its own context and renderer
    context->reset();
    const absl::Status shown = RunWindow(**client, window);
    return shown.ok() ? 0 : Fail(shown);
  }

  auto session = (*client)->OpenSession();
  if (!session.ok()) return call_failed(session.status());
  const std::vector<render::Camera> cameras =
      args.orbit > 0 ? render::OrbitCameras(camera, args.orbit, base.up)
                     : std::vector<render::Camera>{camera};
  for (size_t i = 0; i < cameras.size(); ++i) {
    const render::Camera& cam = cameras[i];
    const pb::ViewRequest view = MakeViewRequest(state, cam, palette, i + 1);
    const auto t0 = std::chrono::steady_clock::now();
    const absl::Status sent = (*session)->Send(view);
    if (!sent.ok()) {
      // A write fails once the stream has ended: its status says why (a full daemon's
      // RESOURCE_EXHAUSTED, say), not the failed write.
      const absl::Status ended = (*session)->Finish();
      return call_failed(ended.ok() ? sent : ended);
    }
    int coarse = 0;
    auto frame = ReceiveFrame(**session, i + 1, **renderer, &coarse,
                              std::chrono::seconds(args.timeout_s), args.max_frame_triangles);
    if (!frame.ok()) return call_failed(frame.status());
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    // The draw order depends on the eye only, so the field of view can wait for the frame:
    // aim at the mesh's bounding sphere from the same eye.
    const absl::Status drawn = (*renderer)->Render(FitToMesh(cam, frame->mesh));
    if (!drawn.ok()) return Fail(drawn);
    auto image = (*context)->ReadPixels();
    if (!image.ok()) return Fail(image.status());
    const std::string path =
        args.orbit > 0 ? render::NumberedPngPath(args.output, int(i), args.orbit) : args.output;
    const absl::Status written = render::WritePng(*image, path);
    if (!written.ok()) return Fail(written);
    std::printf(
        "%s: %lld triangles in %d chunks (%.1f KiB), eps %s, %d coarse frame(s) first, %.0f ms\n",
        path.c_str(), (long long)frame->mesh.triangle_count(), frame->chunks, frame->bytes / 1024.0,
        ShortestText(frame->stats.eps_used()).c_str(), coarse, ms);
    const std::string note =
        FrameNote(int64_t(frame->mesh.triangle_count()), state.budget,
                  frame->stats.triangle_budget(), frame->stats.eps_used(), some_inside);
    if (!note.empty() && i == 0) std::fprintf(stderr, "isostream-view: note: %s\n", note.c_str());
  }
  // Every frame asked for is written: how the stream ends now (a daemon stopping, say) changes
  // nothing the user asked for.
  // Bounded: a server that never ends the stream held the process after its last PNG.
  (*session)->CloseSend().IgnoreError();
  {
    Watchdog watchdog(**session, std::chrono::seconds(args.timeout_s > 0 ? args.timeout_s : 5));
    (*session)->Finish().IgnoreError();
  }
  return 0;
}

}  // namespace
}  // namespace isostream::view

int main(int argc, char** argv) {
  isostream::KeepFreedMemoryForReuse();  // each chunk's decode buffers reuse the last one's
  isostream::net::QuietGrpcLogs();
  isostream::view::Args args;
  CLI::App app{
      "isostream-view: draw isostreamd's view-ordered transparent isosurfaces (headless, PNG)"};
  app.add_option("--server", args.server, "daemon address (default 127.0.0.1:7878)");
  app.add_option("--volume", args.volume, "catalogue name, e.g. buckyball:129")->required();
  app.add_option("--iso", args.iso, "isovalues, comma separated (default: 20/40/60% of the range)")
      ->check(isostream::GivenNumber());  // given but empty: an error, not the defaults
  const CLI::Validator given_number = isostream::GivenNumber();
  auto* eps = app.add_option("--eps", args.eps,
                             "error bound in data units (default, without --budget: 0.2% of the "
                             "volume's value range)")
                  ->check(given_number);
  auto* budget = app.add_option("--budget", args.budget, "triangle budget")
                     ->transform(isostream::GivenCount());
  eps->excludes(budget);
  app.add_option("--samples", args.samples,
                 "anti-aliasing: samples per pixel (default 4; 1: none; fewer where the GL or "
                 "the picture's size allows fewer)")
      ->check(CLI::Range(1, 16));
  app.add_option("--up", args.up,
                 "the picture's vertical x,y,z: the default view stands on it, --orbit and the "
                 "window's drag turn about it (default 0,1,0)");
  app.add_option("--eye", args.eye, "perspective eye x,y,z (default: framing the volume)")
      ->check(given_number);  // given but empty: an error, as fetch says, not the default view
  app.add_option("--size", args.size, "image size WxH (default 800x800)");
  app.add_option("-o,--output", args.output, "PNG to write (with --orbit: name_000.png, ...)");
  app.add_option("--orbit", args.orbit, "write N views on a full turn around the volume")
      ->check(CLI::Range(1, 3600));
  app.add_option("--token", args.token, "bearer token");
  app.add_option("--tls-ca", args.tls_ca, "PEM root certificates: connect with TLS");
  app.add_option("--max-frame-triangles", args.max_frame_triangles,
                 "refuse a frame past this many triangles (default 2^26)")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 40));
  app.add_option("--codec", args.codec, "draco (default) or raw")
      ->check(CLI::IsMember({"draco", "raw"}));
  app.add_flag(
      "--window", args.window,
      "interactive window (needs a display): drag to orbit, wheel to zoom, +/- finer/coarser, "
      "[ ] isovalues, R reset, Q quit");
  auto* exit_after =
      app.add_option("--exit-after", args.exit_after_frames,
                     "with --window: close after N refined frames, writing -o as a screenshot "
                     "(frames after the first come from moves, or from --orbit)")
          ->check(CLI::Range(1, 1 << 30));
  app.add_option("--timeout-s", args.timeout_s,
                 "headless, or --window with --exit-after: fail after this many seconds without "
                 "an answer or data from the server, connecting included, or (--window) without "
                 "a move once its frames are in (default 60; 0: wait forever)")
      ->check(CLI::Range(0, 86400));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // Usage errors exit 2, as argument errors do; --help 0 if the help could be written.
    if (app.exit(e) != 0) return 2;
    return isostream::FlushStandardOutput("isostream-view") ? 0 : 1;
  }
  if (*exit_after && !args.window) {
    std::fprintf(stderr,
                 "isostream-view: --exit-after closes a --window; headless runs end "
                 "after their frames anyway\n");
    return 2;
  }
  if (args.window && !args.output.empty() && !*exit_after) {
    std::fprintf(stderr,
                 "isostream-view: -o with --window is the screenshot taken when the window "
                 "closes itself: give --exit-after N too\n");
    return 2;
  }
  // Given values are checked here (NaN and -1 also mean "not given" inside Run).
  if (*eps && !(args.eps >= 0 && std::isfinite(args.eps))) {
    std::fprintf(stderr, "isostream-view: --eps must be a finite number >= 0\n");
    return 2;
  }
  if (*budget && args.budget <= 0) {
    std::fprintf(stderr, "isostream-view: --budget must be a positive triangle count\n");
    return 2;
  }
  try {
    const int code = isostream::view::Run(args);
    if (!isostream::FlushStandardOutput("isostream-view") && code == 0) return 1;
    return code;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "isostream-view: out of memory\n");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "isostream-view: %s\n", e.what());
  }
  return 1;
}
