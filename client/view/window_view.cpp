#include "client/view/window_view.h"

#ifndef GL_GLEXT_PROTOTYPES
#define GL_GLEXT_PROTOTYPES 1
#endif
#define GLFW_INCLUDE_NONE
#include <GL/glcorearb.h>
#include <GLFW/glfw3.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>
#include <mutex>
#include <thread>

#include "client/render/image.h"
#include "client/view/frame_upload.h"
#include "shared/number_list.h"

namespace isostream::view {
namespace {

std::string g_glfw_error;  // GLFW reports errors through a callback, before any window exists

// The orbit the mouse drives: the eye on a sphere around the target, yaw about the vertical
// (--up) and pitch towards it, in the frame about it (render::FrameAbout: the world's axes for
// the default vertical +y).
struct Orbit {
  glm::vec3 target{0.0f};
  render::VerticalFrame frame = render::FrameAbout({0, 1, 0});
  float distance = 1, yaw = 0, pitch = 0;

  static Orbit From(const render::Camera& c, const glm::vec3& vertical) {
    Orbit o;
    o.target = c.target;
    o.frame = render::FrameAbout(vertical);
    const glm::vec3 d = c.eye - c.target;
    o.distance = render::LengthOf(d);
    o.yaw = std::atan2(glm::dot(d, o.frame.side), glm::dot(d, o.frame.front));
    o.pitch = std::asin(std::clamp(glm::dot(d, o.frame.up) / o.distance, -1.0f, 1.0f));
    return o;
  }
  glm::vec3 Eye() const {
    return target +
           distance * (std::cos(pitch) * std::sin(yaw) * frame.side + std::sin(pitch) * frame.up +
                       std::cos(pitch) * std::cos(yaw) * frame.front);
  }
};

struct Input {
  Orbit orbit;
  bool dragging = false;
  double last_x = 0, last_y = 0;
  bool changed = true;
  float min_distance = 0, max_distance = 0;  // of the zoom, from the volume's size
  int eps_steps = 0;                         // +1: eps / 2
  int iso_steps = 0;                         // +1: isovalues + 1% of the range
  bool reset = false;
};

// Chunks from the receiving thread to the GL thread (GL calls must stay on the window's).
struct Inbox {
  std::mutex mu;
  std::deque<::isostream::v1::FrameChunk> chunks;
  std::atomic<bool> ended{false};
};

// One Session stream and the thread that reads it. The daemon closes a session that sent no
// view for a while (DEADLINE_EXCEEDED); the window then keeps its picture and opens a new
// session when the user next moves.
class Connection {
 public:
  explicit Connection(net::Client* client) : client_(client) {}
  ~Connection() { Close(); }

  bool open() const { return session_ != nullptr; }
  Inbox& inbox() { return *inbox_; }

  absl::Status Open() {
    auto session = client_->OpenSession();
    if (!session.ok()) return session.status();
    session_ = std::move(*session);
    inbox_ = std::make_unique<Inbox>();
    receiver_ = std::thread([session = session_.get(), inbox = inbox_.get()] {
      ::isostream::v1::FrameChunk chunk;
      while (session->Read(&chunk)) {
        std::lock_guard<std::mutex> lock(inbox->mu);
        inbox->chunks.push_back(std::move(chunk));
      }
      inbox->ended = true;
    });
    return absl::OkStatus();
  }

  absl::Status Send(const ::isostream::v1::ViewRequest& request) { return session_->Send(request); }

  // The stream ended from the server's side: its final status.
  absl::Status Finished() {
    receiver_.join();
    absl::Status status = session_->Finish();
    session_.reset();
    return status;
  }

  void Close() {
    if (!session_) return;
    // The receiver may be blocked in Read: cancel, let it return, then finish the call here.
    session_->TryCancel();
    receiver_.join();
    session_->Finish().IgnoreError();
    session_.reset();
  }

 private:
  net::Client* client_;
  std::unique_ptr<net::Session> session_;
  std::unique_ptr<Inbox> inbox_ = std::make_unique<Inbox>();
  std::thread receiver_;
};

absl::Status Screenshot(int width, int height, const std::string& path) {
  render::Image image;
  image.width = width;
  image.height = height;
  image.rgba.resize(size_t(width) * height * 4);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, width, height, GL_RGBA, GL_UNSIGNED_BYTE, image.rgba.data());
  // GL rows run bottom to top; PNG rows top to bottom.
  for (int y = 0; y < height / 2; ++y)
    std::swap_ranges(image.rgba.begin() + size_t(y) * width * 4,
                     image.rgba.begin() + size_t(y + 1) * width * 4,
                     image.rgba.begin() + size_t(height - 1 - y) * width * 4);
  return render::WritePng(image, path);
}

}  // namespace

absl::Status RunWindow(net::Client& client, const WindowOptions& options) {
  glfwSetErrorCallback([](int, const char* message) { g_glfw_error = message; });
  if (!glfwInit())
    return absl::UnavailableError("cannot open a window (GLFW: " + g_glfw_error + ")");
  struct Terminate {
    ~Terminate() { glfwTerminate(); }
  } terminate;
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  // EGL, like the headless path: GLVND's libOpenGL then dispatches the renderer's calls.
  glfwWindowHint(GLFW_CONTEXT_CREATION_API, GLFW_EGL_CONTEXT_API);
  glfwWindowHint(GLFW_SAMPLES, options.samples > 1 ? options.samples : 0);
  GLFWwindow* window =
      glfwCreateWindow(options.width, options.height, "isostream-view", nullptr, nullptr);
  if (!window && options.samples > 1) {  // a display without multisampled configs: without
    glfwWindowHint(GLFW_SAMPLES, 0);
    window = glfwCreateWindow(options.width, options.height, "isostream-view", nullptr, nullptr);
  }
  if (!window)
    return absl::UnavailableError("cannot open a GL 3.3 core window (GLFW: " + g_glfw_error + ")");
  glfwMakeContextCurrent(window);
  glfwSwapInterval(1);

  auto renderer = render::MeshRenderer::Create();
  if (!renderer.ok()) return renderer.status();
  const render::Palette palette = render::DefaultPalette();
  (*renderer)->SetPalette(palette);

  Input input;
  input.orbit = Orbit::From(options.camera, options.world_up);
  input.min_distance = 1e-3f * options.scene_radius;
  input.max_distance = std::max(1e3f * options.scene_radius, input.orbit.distance);
  glfwSetWindowUserPointer(window, &input);
  glfwSetMouseButtonCallback(window, [](GLFWwindow* w, int button, int action, int) {
    auto* in = static_cast<Input*>(glfwGetWindowUserPointer(w));
    if (button != GLFW_MOUSE_BUTTON_LEFT) return;
    in->dragging = action == GLFW_PRESS;
    glfwGetCursorPos(w, &in->last_x, &in->last_y);
  });
  glfwSetCursorPosCallback(window, [](GLFWwindow* w, double x, double y) {
    auto* in = static_cast<Input*>(glfwGetWindowUserPointer(w));
    if (!in->dragging) return;
    in->orbit.yaw -= float(x - in->last_x) * 0.01f;
    in->orbit.pitch = std::clamp(in->orbit.pitch + float(y - in->last_y) * 0.01f, -1.5f, 1.5f);
    in->last_x = x, in->last_y = y;
    in->changed = true;
  });
  glfwSetScrollCallback(window, [](GLFWwindow* w, double, double dy) {
    auto* in = static_cast<Input*>(glfwGetWindowUserPointer(w));
    in->orbit.distance = std::clamp(in->orbit.distance * std::pow(0.9f, float(dy)),
                                    in->min_distance, in->max_distance);
    in->changed = true;
  });
  glfwSetKeyCallback(window, [](GLFWwindow* w, int key, int, int action, int) {
    if (action == GLFW_RELEASE) return;
    auto* in = static_cast<Input*>(glfwGetWindowUserPointer(w));
    switch (key) {
      case GLFW_KEY_EQUAL:
      case GLFW_KEY_KP_ADD:
        ++in->eps_steps;
        break;
      case GLFW_KEY_MINUS:
      case GLFW_KEY_KP_SUBTRACT:
        --in->eps_steps;
        break;
      case GLFW_KEY_RIGHT_BRACKET:
        ++in->iso_steps;
        break;
      case GLFW_KEY_LEFT_BRACKET:
        --in->iso_steps;
        break;
      case GLFW_KEY_R:
        in->reset = true;
        break;
      case GLFW_KEY_Q:
      case GLFW_KEY_ESCAPE:
        glfwSetWindowShouldClose(w, GLFW_TRUE);
        return;
      default:
        return;
    }
    in->changed = true;
  });

  Connection connection(&client);
  if (absl::Status opened = connection.Open(); !opened.ok()) return opened;

  ViewState state = options.state;
  uint64_t request_id = 0;
  net::FrameAssembler assembler(client.options().max_frame_triangles);
  bool frame_open = false;
  bool awaiting_frame = false;  // a view was sent and its refined frame is not complete
  using Clock = std::chrono::steady_clock;
  Clock::time_point last_data = Clock::now();  // a chunk arrived, or a view was sent
  int refined_frames = 0;
  absl::Status result;
  render::Camera camera = options.camera;
  char title[256];
  while (!glfwWindowShouldClose(window)) {
    glfwPollEvents();
    if (input.changed) {
      if (input.reset) {
        input.orbit = Orbit::From(options.camera, options.world_up);
        state = options.state;
        input.reset = false;
      }
      // Finer (+) or coarser (-): a budget doubles or halves, an eps halves or doubles, and an
      // eps of 0 (the finest) starts coarsening from a thousandth of the values' range (the
      // keys did nothing to a budget, and 0 stayed 0).
      for (; input.eps_steps > 0; --input.eps_steps) {
        constexpr int64_t kMostBudget = int64_t{1} << 40;  // far past any daemon's frame limit
        if (state.budget > 0)
          state.budget = state.budget >= kMostBudget / 2 ? std::max(state.budget, kMostBudget)
                                                         : 2 * state.budget;
        else
          state.eps *= 0.5;
      }
      for (; input.eps_steps < 0; ++input.eps_steps) {
        if (state.budget > 0)
          state.budget = std::max<int64_t>(state.budget / 2, 1);
        else
          state.eps = state.eps > 0 ? state.eps * 2.0 : options.value_range / 1024;
      }
      for (double& v : state.isovalues) v += 0.01 * options.value_range * input.iso_steps;
      input.iso_steps = 0;
      camera.eye = input.orbit.Eye();
      camera.target = input.orbit.target;
      camera.up = render::UsableUp(camera.target - camera.eye, options.world_up);
      // The planes the initial camera had belong to its distance: zoomed in, near cut the
      // volume's front away, and past it the whole picture.
      render::EncloseSphere(input.orbit.distance, options.scene_radius, &camera);
      if (!connection.open()) result = connection.Open();
      if (result.ok())
        result = connection.Send(MakeViewRequest(state, camera, palette, ++request_id));
      if (!result.ok()) break;
      awaiting_frame = true;
      last_data = Clock::now();
      input.changed = false;
    }
    Inbox& inbox = connection.inbox();
    {
      std::lock_guard<std::mutex> lock(inbox.mu);
      while (!inbox.chunks.empty() && result.ok()) {
        ::isostream::v1::FrameChunk chunk = std::move(inbox.chunks.front());
        inbox.chunks.pop_front();
        if (chunk.frame_id() != request_id) continue;  // superseded by a newer view
        last_data = Clock::now();                      // only this view's chunks are progress
        result = AddAndUpload(assembler, chunk, **renderer, &frame_open);
        if (!result.ok()) break;
        const net::Frame& f = assembler.frame();
        if (assembler.complete()) {
          result = (*renderer)->EndFrame();
          frame_open = false;
          if (!f.coarse) {
            ++refined_frames, awaiting_frame = false;
            // The next view of the turn; a script's --exit-after past the orbit goes on turning.
            const int views = std::max(options.orbit, options.exit_after_frames);
            if (options.orbit > 0 && refined_frames < views) {
              input.orbit.yaw += 2.0f * glm::pi<float>() / float(options.orbit);
              input.changed = true;
            }
          }
          std::snprintf(title, sizeof(title), "isostream-view  %s  eps %s  %lld triangles  %s",
                        state.volume.c_str(), ShortestText(f.stats.eps_used()).c_str(),
                        (long long)f.mesh.triangle_count(), f.coarse ? "(coarse)" : "");
          glfwSetWindowTitle(window, title);
        }
      }
    }
    if (!result.ok()) break;
    // A script's window (--exit-after) waits at most --timeout-s for data, and as long for a
    // move once its frames are in: frames after the first come only from moves or --orbit, and
    // without either it waited for ever.
    if (options.exit_after_frames > 0 && options.timeout_s > 0 &&
        Clock::now() - last_data > std::chrono::seconds(options.timeout_s)) {
      const std::string waited = std::to_string(options.timeout_s) + " s";
      result = awaiting_frame
                   ? absl::DeadlineExceededError("no data from the server for " + waited)
                   : absl::DeadlineExceededError(
                         "--exit-after " + std::to_string(options.exit_after_frames) + ": " +
                         std::to_string(refined_frames) + " refined frame(s), then no move for " +
                         waited + " (frames after the first come from moves, keys or --orbit)");
      break;
    }
    if (connection.open() && inbox.ended && inbox.chunks.empty()) {
      result = connection.Finished();
      // The daemon ends an idle session (no view, no frame in flight) with DEADLINE_EXCEEDED,
      // and a frame past its deadline too: only the first is reopened on the next move.
      if (absl::IsDeadlineExceeded(result) && !awaiting_frame) {
        result = absl::OkStatus();
      } else {
        if (result.ok()) result = absl::UnavailableError("the server closed the session");
        break;
      }
    }
    int fb_width, fb_height;
    glfwGetFramebufferSize(window, &fb_width, &fb_height);
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    glViewport(0, 0, fb_width, fb_height);
    camera.aspect = float(fb_width) / float(std::max(fb_height, 1));
    result = (*renderer)->Render(camera);
    if (!result.ok()) break;
    if (options.exit_after_frames > 0 && refined_frames >= options.exit_after_frames) {
      if (!options.screenshot.empty()) result = Screenshot(fb_width, fb_height, options.screenshot);
      break;
    }
    glfwSwapBuffers(window);
  }
  connection.Close();
  renderer->reset();
  glfwDestroyWindow(window);
  return result;
}

}  // namespace isostream::view
