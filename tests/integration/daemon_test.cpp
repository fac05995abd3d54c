// Integration tests: a real isostreamd process on 127.0.0.1, driven through the client library
// and the `isostream fetch` CLI. Volumes are small generators (buckyball:65/129) so the suite
// runs in well under a minute on two cores; every wait is bounded.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>
#include <thread>

#include "client/net/session_client.h"
#include "server/extract/extractor.h"
#include "server/hierarchy/prepared_volume.h"
#include "shared/frame_codec.h"
#include "shared/ply_io.h"
#include "tests/integration/daemon_process.h"

namespace isostream {
namespace {

namespace pb = ::isostream::v1;
using testing::DaemonProcess;
using testing::ScratchDir;

const std::vector<float> kIso = {0.05f, 0.15f, 0.25f};

pb::ViewRequest MakeView(const std::string& volume, uint64_t id, double eps, glm::dvec3 eye,
                         pb::Codec codec = pb::DRACO) {
  pb::ViewRequest v;
  v.set_volume(volume);
  v.set_request_id(id);
  for (float iso : kIso) v.add_surfaces()->set_isovalue(iso);
  v.set_eps(eps);
  v.mutable_camera()->mutable_eye()->set_x(eye.x);
  v.mutable_camera()->mutable_eye()->set_y(eye.y);
  v.mutable_camera()->mutable_eye()->set_z(eye.z);
  v.set_codec(codec);
  return v;
}

ExtractRequest DirectRequest(double eps, glm::dvec3 eye) {
  ExtractRequest r;
  r.isovalues = kIso;
  r.eps = eps;
  r.view.eye = eye;
  return r;
}

// Per-triangle comparison: the codec renumbers (and may duplicate) vertices, so triangles are
// compared corner by corner, in order, with their surface index.
void ExpectSameFrame(const OrderedMesh& direct, const OrderedMesh& got, float position_error) {
  ASSERT_EQ(direct.triangle_count(), got.triangle_count());
  size_t surface_mismatch = 0, position_mismatch = 0;
  float worst = 0;
  for (size_t t = 0; t < direct.triangle_count(); ++t) {
    surface_mismatch += direct.surface[t] != got.surface[t];
    for (int c = 0; c < 3; ++c) {
      const uint32_t a = direct.triangles[3 * t + c], b = got.triangles[3 * t + c];
      for (int k = 0; k < 3; ++k) {
        const float d = std::abs(direct.positions[3 * a + k] - got.positions[3 * b + k]);
        worst = std::max(worst, d);
        position_mismatch += d > position_error;
      }
    }
  }
  EXPECT_EQ(surface_mismatch, 0u);
  EXPECT_EQ(position_mismatch, 0u) << "worst " << worst << " allowed " << position_error;
}

class Daemon : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scratch_ = new ScratchDir();
    daemon_ = new DaemonProcess();
    ASSERT_TRUE(daemon_->Start(
        {"--cache-dir", scratch_->path() + "/cache", "--threads", "2", "--max-sessions", "3",
         "--max-isovalues", "4", "--max-triangles", "1000000", "--max-dim", "129"},
        scratch_->path() + "/isostreamd.log"));
  }
  static void TearDownTestSuite() {
    delete daemon_;
    delete scratch_;
  }

  std::unique_ptr<net::Client> Connect(const std::string& token = "") {
    net::ClientOptions o;
    o.address = daemon_->address();
    o.token = token;
    auto c = net::Client::Connect(o);
    EXPECT_TRUE(c.ok());
    return std::move(*c);
  }

  // The server's own preparation of the volume, repeated here (same cache) for comparison.
  static PreparedVolume Local(const std::string& spec) {
    HierarchyCacheOptions cache;
    cache.dir = scratch_->path() + "/cache";
    auto p = PrepareVolume(spec, VolumeLimits{}, cache, HierarchyBuildOptions{});
    EXPECT_TRUE(p.ok()) << p.status();
    return std::move(*p);
  }

  // Polls the server's counters until `done` holds (at most 10 s).
  static bool WaitForStats(net::Client* c, const std::function<bool(const pb::ServerStats&)>& done,
                           pb::ServerStats* last = nullptr) {
    for (int i = 0; i < 500; ++i) {
      auto s = c->GetServerStats();
      if (s.ok() && done(*s)) {
        if (last) *last = *s;
        return true;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return false;
  }

  static ScratchDir* scratch_;
  static DaemonProcess* daemon_;
};
ScratchDir* Daemon::scratch_ = nullptr;
DaemonProcess* Daemon::daemon_ = nullptr;

TEST_F(Daemon, HealthServingAndCatalogue) {
  auto c = Connect();
  auto health = c->CheckHealth();
  ASSERT_TRUE(health.ok()) << health.status();
  EXPECT_TRUE(*health);
  auto list = c->ListVolumes();
  ASSERT_TRUE(list.ok()) << list.status();
  EXPECT_TRUE(list->generators_allowed());
  EXPECT_EQ(list->max_generator_dim(), 129);
  auto info = c->GetVolumeInfo("buckyball:65", 16);
  ASSERT_TRUE(info.ok()) << info.status();
  ASSERT_EQ(info->dims_size(), 3);
  EXPECT_EQ(info->dims(0), 65);
  ASSERT_EQ(info->histogram_size(), 16);
  uint64_t total = 0;
  for (uint64_t h : info->histogram()) total += h;
  EXPECT_EQ(total, 65u * 65u * 65u);
  EXPECT_LT(info->min_value(), info->max_value());
  // Documented quantization: at most 1/64 of a voxel.
  EXPECT_GT(info->position_error(), 0);
  EXPECT_LE(info->position_error(), info->spacing().x() / 64 * 1.01);
}

TEST_F(Daemon, DecodedFrameEqualsDirectExtraction) {
  const glm::dvec3 eye(2.5, 1.8, 3.1);
  PreparedVolume local = Local("buckyball:65");
  auto direct = Extract(*local.hierarchy, local.grid_to_world, DirectRequest(0.002, eye));
  ASSERT_TRUE(direct.ok()) << direct.status();
  auto c = Connect();
  auto info = c->GetVolumeInfo("buckyball:65");
  ASSERT_TRUE(info.ok());

  for (pb::Codec codec : {pb::DRACO, pb::RAW}) {
    SCOPED_TRACE(pb::Codec_Name(codec));
    std::vector<pb::FrameChunk> chunks;
    auto frame =
        c->Fetch(MakeView("buckyball:65", 7, 0.002, eye, codec), [&](const pb::FrameChunk& ch) {
          pb::FrameChunk header = ch;
          header.clear_data();
          chunks.push_back(header);
        });
    ASSERT_TRUE(frame.ok()) << frame.status();
    EXPECT_EQ(frame->id, 7u);
    EXPECT_EQ(frame->stats.triangles(), int64_t(direct->mesh.triangle_count()));
    ExpectSameFrame(direct->mesh, frame->mesh,
                    codec == pb::RAW ? 0.0f : float(info->position_error()));
    // Chunks in draw order, the first small so it leaves early, none over 64k triangles.
    ASSERT_GT(chunks.size(), 2u);
    for (size_t i = 0; i < chunks.size(); ++i) {
      EXPECT_EQ(chunks[i].chunk_index(), i);
      EXPECT_LE(chunks[i].triangle_count(), 65536u);
      EXPECT_EQ(chunks[i].last(), i + 1 == chunks.size());
    }
    EXPECT_EQ(chunks[0].triangle_count(), 8192u);
    EXPECT_EQ(chunks.back().chunk_count(), chunks.size());
    EXPECT_EQ(frame->stats.chunk_count(), int(chunks.size()));
  }
}

// The budget -> eps search runs for the first view only: the count does not depend on the
// view, so later views of the same volume, isovalues and budget reuse the eps it found.
TEST_F(Daemon, BudgetSearchRunsOnceAndLaterViewsReuseItsEps) {
  constexpr int64_t kBudget = 12345;  // used by no other test of this daemon
  auto c = Connect();
  const glm::dvec3 eyes[3] = {{2.5, 1.8, 3.1}, {-3.0, 0.5, 1.0}, {0.2, -2.8, -1.5}};
  PreparedVolume local = Local("buckyball:65");
  double first_eps = -1;
  for (int i = 0; i < 3; ++i) {
    SCOPED_TRACE(i);
    pb::ViewRequest v = MakeView("buckyball:65", 60 + i, 0.0, eyes[i], pb::RAW);
    v.set_triangle_budget(kBudget);
    auto frame = c->Fetch(v, nullptr);
    ASSERT_TRUE(frame.ok()) << frame.status();
    EXPECT_LE(frame->stats.triangles(), kBudget);
    if (i == 0) {
      EXPECT_GT(frame->stats.budget_passes(), 2);
      first_eps = frame->stats.eps_used();
    } else {
      EXPECT_EQ(frame->stats.budget_passes(), 0);
      EXPECT_EQ(frame->stats.eps_used(), first_eps);
    }
    // The remembered eps gives exactly the frame a direct extraction at that eps gives.
    auto direct = Extract(*local.hierarchy, local.grid_to_world,
                          DirectRequest(frame->stats.eps_used(), eyes[i]));
    ASSERT_TRUE(direct.ok());
    ExpectSameFrame(direct->mesh, frame->mesh, 0.0f);
  }
}

TEST_F(Daemon, FetchCommandWritesTheFrame) {
  const std::string out = scratch_->path() + "/fetched.ply";
  const std::string cmd = std::string(ISOSTREAM_CLI_PATH) + " fetch --server " +
                          daemon_->address() +
                          " --volume buckyball:65 --iso 0.05,0.15,0.25 --eps 0.002 --eye "
                          "2.5,1.8,3.1 --codec raw -o " +
                          out + " 2>/dev/null";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  auto mesh = ReadPly(out);
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  PreparedVolume local = Local("buckyball:65");
  auto direct = Extract(*local.hierarchy, local.grid_to_world,
                        DirectRequest(0.002, glm::dvec3(2.5, 1.8, 3.1)));
  ASSERT_TRUE(direct.ok());
  ExpectSameFrame(direct->mesh, *mesh, 0.0f);

  const std::string bad = std::string(ISOSTREAM_CLI_PATH) + " fetch --server " +
                          daemon_->address() + " --volume /etc/passwd --iso 0.1 --eps 0.01 -o " +
                          out + " 2>/dev/null";
  EXPECT_NE(std::system(bad.c_str()), 0);
}

TEST_F(Daemon, StatusCodes) {
  auto c = Connect();
  const glm::dvec3 eye(2, 2, 2);
  auto code = [&](const pb::ViewRequest& v) { return c->Fetch(v).status(); };
  absl::Status s;

  // Unknown names, paths and oversized generators are all just "not in the catalogue".
  for (const char* name : {"nope", "/etc/passwd", "../x.vdb", "buckyball:4097", "raw:/x:2x2x2:f32"})
    EXPECT_EQ(code(MakeView(name, 1, 0.01, eye)).code(), absl::StatusCode::kNotFound) << name;
  EXPECT_EQ(c->GetVolumeInfo("nope").status().code(), absl::StatusCode::kNotFound);
  // A name too long to quote whole in the status is shortened there (whole, it overflowed the
  // status metadata and the client saw RESOURCE_EXHAUSTED).
  const std::string long_name(20000, 'a');
  s = code(MakeView(long_name, 1, 0.01, eye));
  EXPECT_EQ(s.code(), absl::StatusCode::kNotFound) << s;
  EXPECT_NE(s.message().find("(20000 bytes)"), std::string::npos) << s;
  EXPECT_EQ(c->GetVolumeInfo(long_name).status().code(), absl::StatusCode::kNotFound);

  pb::ViewRequest no_surfaces = MakeView("buckyball:65", 1, 0.01, eye);
  no_surfaces.clear_surfaces();
  s = code(no_surfaces);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_FALSE(s.message().empty());

  s = code(MakeView("buckyball:65", 1, -1.0, eye));
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("eps"), std::string::npos) << s;

  pb::ViewRequest ortho = MakeView("buckyball:65", 1, 0.01, eye);
  ortho.mutable_camera()->set_projection(pb::ORTHOGRAPHIC);
  ortho.mutable_camera()->mutable_target()->set_x(2);
  ortho.mutable_camera()->mutable_target()->set_y(2);
  ortho.mutable_camera()->mutable_target()->set_z(2);
  s = code(ortho);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("direction"), std::string::npos) << s;

  pb::ViewRequest no_accuracy = MakeView("buckyball:65", 1, 0.01, eye);
  no_accuracy.clear_eps();
  EXPECT_EQ(code(no_accuracy).code(), absl::StatusCode::kInvalidArgument);

  pb::ViewRequest nan_eye = MakeView("buckyball:65", 1, 0.01, glm::dvec3(NAN, 0, 0));
  EXPECT_EQ(code(nan_eye).code(), absl::StatusCode::kInvalidArgument);

  pb::ViewRequest many = MakeView("buckyball:65", 1, 0.01, eye);
  for (int i = 0; i < 2; ++i) many.add_surfaces()->set_isovalue(0.3f + 0.01f * i);
  EXPECT_EQ(code(many).code(), absl::StatusCode::kResourceExhausted);  // 5 > --max-isovalues 4

  pb::ViewRequest big_budget = MakeView("buckyball:65", 1, 0.01, eye);
  big_budget.set_triangle_budget(2'000'000);
  EXPECT_EQ(code(big_budget).code(), absl::StatusCode::kResourceExhausted);

  // A bad request on a session ends that session with the status.
  auto session = c->OpenSession();
  ASSERT_TRUE(session.ok());
  ASSERT_TRUE((*session)->Send(no_surfaces).ok());
  EXPECT_EQ((*session)->Finish().code(), absl::StatusCode::kInvalidArgument);
}

TEST_F(Daemon, NewViewCancelsOldFrameAndCoarseArrivesBeforeRefined) {
  auto c = Connect();
  auto before = c->GetServerStats();
  ASSERT_TRUE(before.ok());
  auto session = c->OpenSession();
  ASSERT_TRUE(session.ok());
  net::Session& s = **session;
  // A heavy first view (about 690k triangles at eps 0), replaced once its first chunk is in.
  ASSERT_TRUE(s.Send(MakeView("buckyball:129", 1, 0.0, glm::dvec3(3, 2, 4))).ok());
  pb::FrameChunk chunk;
  ASSERT_TRUE(s.Read(&chunk));
  ASSERT_EQ(chunk.frame_id(), 1u);
  ASSERT_FALSE(chunk.last());
  pb::ViewRequest second = MakeView("buckyball:129", 2, 0.002, glm::dvec3(-3, 1, 2));
  second.set_progressive(true);
  ASSERT_TRUE(s.Send(second).ok());

  std::vector<std::pair<uint64_t, bool>> order;  // (frame id, coarse) of each chunk
  net::FrameAssembler assembler;
  bool coarse_done = false, refined_done = false;
  int64_t coarse_triangles = 0, refined_triangles = 0;
  order.push_back({chunk.frame_id(), chunk.coarse()});
  ASSERT_TRUE(assembler.Add(chunk).ok());
  while (!refined_done && s.Read(&chunk)) {
    order.push_back({chunk.frame_id(), chunk.coarse()});
    ASSERT_TRUE(assembler.Add(chunk).ok());
    if (chunk.frame_id() != 2 || !assembler.complete()) continue;
    net::Frame f = assembler.Take();
    if (f.coarse) {
      EXPECT_FALSE(refined_done);
      coarse_done = true;
      coarse_triangles = int64_t(f.mesh.triangle_count());
    } else {
      refined_done = true;
      refined_triangles = int64_t(f.mesh.triangle_count());
    }
  }
  EXPECT_TRUE(coarse_done);
  EXPECT_TRUE(refined_done);
  EXPECT_GT(coarse_triangles, 0);
  EXPECT_LE(coarse_triangles, 20000);
  EXPECT_GT(refined_triangles, coarse_triangles);
  // Once frame 2 has started, nothing of frame 1 follows; coarse chunks all precede refined.
  size_t first2 = order.size();
  for (size_t i = 0; i < order.size(); ++i)
    if (order[i].first == 2) {
      first2 = std::min(first2, i);
    }
  ASSERT_LT(first2, order.size());
  bool seen_refined = false;
  for (size_t i = first2; i < order.size(); ++i) {
    EXPECT_EQ(order[i].first, 2u) << "chunk " << i;
    if (!order[i].second) seen_refined = true;
    if (seen_refined) {
      EXPECT_FALSE(order[i].second) << "coarse chunk after refined";
    }
  }
  ASSERT_TRUE(s.CloseSend().ok());
  EXPECT_TRUE(s.Finish().ok());
  pb::ServerStats after;
  ASSERT_TRUE(WaitForStats(
      c.get(), [](const pb::ServerStats& st) { return st.sessions_open() == 0; }, &after));
  EXPECT_GE(after.frames_cancelled(), before->frames_cancelled() + 1);
}

TEST_F(Daemon, SessionLimitIsResourceExhausted) {
  auto c = Connect();
  std::vector<std::unique_ptr<net::Session>> open;
  for (int i = 0; i < 3; ++i) {
    auto s = c->OpenSession();
    ASSERT_TRUE(s.ok());
    // A complete small frame proves the server admitted the session.
    ASSERT_TRUE((*s)->Send(MakeView("buckyball:65", 1, 0.05, glm::dvec3(2, 2, 2))).ok());
    net::FrameAssembler a;
    pb::FrameChunk chunk;
    while (!a.complete() && (*s)->Read(&chunk)) ASSERT_TRUE(a.Add(chunk).ok());
    ASSERT_TRUE(a.complete());
    open.push_back(std::move(*s));
  }
  auto extra = c->OpenSession();
  ASSERT_TRUE(extra.ok());
  (*extra)->Send(MakeView("buckyball:65", 1, 0.05, glm::dvec3(2, 2, 2))).IgnoreError();
  EXPECT_EQ((*extra)->Finish().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(c->Fetch(MakeView("buckyball:65", 1, 0.05, glm::dvec3(2, 2, 2))).status().code(),
            absl::StatusCode::kResourceExhausted);
  // Volume info (which may build a hierarchy and reads every sample) takes a slot too: a
  // flood of it is refused rather than queued ahead of frames.
  EXPECT_EQ(c->GetVolumeInfo("buckyball:65").status().code(), absl::StatusCode::kResourceExhausted);
  for (auto& s : open) {
    ASSERT_TRUE(s->CloseSend().ok());
    EXPECT_TRUE(s->Finish().ok());
  }
  EXPECT_TRUE(
      WaitForStats(c.get(), [](const pb::ServerStats& st) { return st.sessions_open() == 0; }));
  EXPECT_TRUE(c->GetVolumeInfo("buckyball:65").ok());
  EXPECT_TRUE(
      WaitForStats(c.get(), [](const pb::ServerStats& st) { return st.sessions_open() == 0; }));
}

TEST_F(Daemon, ClientLeavingMidFrameFreesItsSession) {
  auto c = Connect();
  for (int round = 0; round < 2; ++round) {
    auto session = c->OpenSession();
    ASSERT_TRUE(session.ok());
    ASSERT_TRUE((*session)->Send(MakeView("buckyball:129", 1, 0.0, glm::dvec3(3, 2, 4))).ok());
    pb::FrameChunk chunk;
    ASSERT_TRUE((*session)->Read(&chunk));  // the frame is under way
    EXPECT_FALSE(chunk.last());
    if (round == 0)
      (*session)->Cancel();
    else
      session->reset();  // destroyed without closing
    EXPECT_TRUE(
        WaitForStats(c.get(), [](const pb::ServerStats& st) { return st.sessions_open() == 0; }))
        << "round " << round;
  }
}

TEST_F(Daemon, ConcurrentFirstRequestsBuildOneHierarchy) {
  auto c = Connect();
  std::vector<std::thread> threads;
  std::atomic<int> ok{0};
  for (int i = 0; i < 3; ++i)  // the daemon's --max-sessions
    threads.emplace_back([&, i] {
      if (c->Fetch(MakeView("sphere:65", uint64_t(i), 0.05, glm::dvec3(2, 1, 3))).ok()) ++ok;
    });
  for (auto& t : threads) t.join();
  EXPECT_EQ(ok.load(), 3);
  std::ifstream log(scratch_->path() + "/isostreamd.log");
  std::string line;
  int builds = 0;
  while (std::getline(log, line)) builds += line.find("prepared volume 'sphere:65'") != line.npos;
  EXPECT_EQ(builds, 1);
}

TEST_F(Daemon, MalformedRequestsNeverTakeItDown) {
  auto c = Connect();
  std::mt19937 rng(12345);
  std::uniform_real_distribution<double> any(-1e3, 1e3);
  const char* names[] = {
      "buckyball:65",   "",         "x",         "buckyball:",          "buckyball:-3", "noise:9:x",
      "buckyball:65:1", "sphere:0", "/dev/zero", "noise:17:99999999999"};
  for (int i = 0; i < 120; ++i) {
    pb::ViewRequest v;
    v.set_volume(names[rng() % 10]);
    v.set_request_id(rng());
    const int surfaces = int(rng() % 6);
    for (int k = 0; k < surfaces; ++k)
      v.add_surfaces()->set_isovalue(rng() % 7 == 0 ? NAN : float(any(rng) * 1e-3));
    switch (rng() % 4) {
      case 0:
        v.set_eps(any(rng));
        break;
      case 1:
        v.set_eps(rng() % 2 ? INFINITY : NAN);
        break;
      case 2:
        v.set_triangle_budget(int64_t(rng() % 20000) - 100);
        break;
      default:
        break;
    }
    // Keep accepted requests cheap: a small mesh at most.
    if (v.accuracy_case() == pb::ViewRequest::kEps && v.eps() >= 0 && v.eps() < 0.05)
      v.set_eps(0.05);
    auto* cam = v.mutable_camera();
    cam->set_projection(pb::Projection(rng() % 3));
    cam->mutable_eye()->set_x(rng() % 9 == 0 ? NAN : any(rng));
    cam->mutable_target()->set_y(any(rng));
    v.set_codec(pb::Codec(rng() % 3));
    v.set_normals(pb::Normals(rng() % 3));
    v.set_progressive(rng() % 2);
    auto frame = c->Fetch(v);
    if (!frame.ok()) {
      const auto code = frame.status().code();
      EXPECT_TRUE(code == absl::StatusCode::kInvalidArgument ||
                  code == absl::StatusCode::kNotFound ||
                  code == absl::StatusCode::kResourceExhausted)
          << frame.status();
    }
  }
  auto health = c->CheckHealth();
  ASSERT_TRUE(health.ok()) << health.status();
  EXPECT_TRUE(*health);
}

TEST_F(Daemon, StillServesAfterEverything) {
  auto c = Connect();
  auto frame = c->Fetch(MakeView("buckyball:65", 99, 0.01, glm::dvec3(-2, 3, 1)));
  ASSERT_TRUE(frame.ok()) << frame.status();
  EXPECT_GT(frame->mesh.triangle_count(), 0u);
  auto stats = c->GetServerStats();
  ASSERT_TRUE(stats.ok());
  EXPECT_TRUE(stats->serving());
  EXPECT_GT(stats->frames_sent(), 0);
  EXPECT_GT(stats->bytes_sent(), 0);
  EXPECT_TRUE(WaitForStats(c.get(), [](const pb::ServerStats& st) {
    return st.sessions_open() == 0 && st.sessions_closed() == st.sessions_total();
  }));
}

// A daemon with a token and tight limits; it is stopped with SIGTERM at the end.
class GuardedDaemon : public Daemon {
 protected:
  static void SetUpTestSuite() {
    scratch_ = new ScratchDir();
    daemon_ = new DaemonProcess();
    ASSERT_TRUE(daemon_->Start({"--cache-dir", scratch_->path() + "/cache", "--threads", "2",
                                "--token", "s3cret", "--max-triangles", "100000"},
                               scratch_->path() + "/isostreamd.log"));
  }
};

TEST_F(GuardedDaemon, TokenIsRequired) {
  const auto view = MakeView("buckyball:65", 1, 0.05, glm::dvec3(2, 2, 2));
  EXPECT_EQ(Connect()->Fetch(view).status().code(), absl::StatusCode::kUnauthenticated);
  EXPECT_EQ(Connect("wrong")->Fetch(view).status().code(), absl::StatusCode::kUnauthenticated);
  EXPECT_EQ(Connect("wrong")->GetServerStats().status().code(), absl::StatusCode::kUnauthenticated);
  auto session = Connect("s3cre")->OpenSession();
  ASSERT_TRUE(session.ok());
  EXPECT_EQ((*session)->Finish().code(), absl::StatusCode::kUnauthenticated);
  // Health needs no token.
  auto health = Connect()->CheckHealth();
  ASSERT_TRUE(health.ok());
  EXPECT_TRUE(*health);
  EXPECT_TRUE(Connect("s3cret")->Fetch(view).ok());
  // gRPC aborts on metadata it cannot send: such a token is refused before any call.
  for (const char* bad : {"a\nb", "t\xc3\xb6k", "\x7f"}) {
    net::ClientOptions o;
    o.address = daemon_->address();
    o.token = bad;
    EXPECT_EQ(net::Client::Connect(o).status().code(), absl::StatusCode::kInvalidArgument) << bad;
  }
  net::ClientOptions far;
  far.address = "127.0.0.1:104903";  // would wrap to port 39367
  EXPECT_EQ(net::Client::Connect(far).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST_F(GuardedDaemon, FrameOverTriangleLimitIsResourceExhausted) {
  // About 138k triangles at this eps, over --max-triangles 100000.
  auto s = Connect("s3cret")->Fetch(MakeView("buckyball:65", 1, 0.002, glm::dvec3(2, 2, 2)));
  EXPECT_EQ(s.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_NE(s.status().message().find("100000"), std::string::npos) << s.status();
}

TEST_F(GuardedDaemon, SigtermFinishesTheFrameInFlightAndExitsZero) {
  auto c = Connect("s3cret");
  std::atomic<bool> first_chunk{false};
  absl::Status fetched;
  std::thread fetch([&] {
    pb::ViewRequest view = MakeView("buckyball:129", 5, 0.0, glm::dvec3(2, 2, 2));
    view.set_triangle_budget(95000);
    auto f = c->Fetch(view, [&](const pb::FrameChunk&) { first_chunk = true; });
    fetched = f.status();
  });
  for (int i = 0; i < 1000 && !first_chunk; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  EXPECT_EQ(daemon_->Stop(SIGTERM), 0);
  fetch.join();
  EXPECT_TRUE(fetched.ok()) << fetched;
}

// A daemon with a JSON config: a catalogue (so generator specs are refused) and small chunks.
class ConfiguredDaemon : public Daemon {
 protected:
  static void SetUpTestSuite() {
    scratch_ = new ScratchDir();
    daemon_ = new DaemonProcess();
    const std::string config = scratch_->path() + "/isostreamd.json";
    std::ofstream(config)
        << R"({"threads": 2, "volumes": {"ball": "buckyball:65", "big": "buckyball:129"},
        "frames": {"chunk_triangles": 4096, "first_chunk_triangles": 1024,
                   "max_queued_chunks": 4}})";
    ASSERT_TRUE(daemon_->Start({"--config", config, "--cache-dir", scratch_->path() + "/cache"},
                               scratch_->path() + "/isostreamd.log"));
  }
};

TEST_F(ConfiguredDaemon, ServesItsCatalogueOnly) {
  auto c = Connect();
  auto list = c->ListVolumes();
  ASSERT_TRUE(list.ok());
  ASSERT_EQ(list->names_size(), 2);
  EXPECT_EQ(list->names(0), "ball");
  EXPECT_EQ(list->names(1), "big");
  EXPECT_FALSE(list->generators_allowed());
  EXPECT_EQ(c->Fetch(MakeView("buckyball:65", 1, 0.01, glm::dvec3(2, 2, 2))).status().code(),
            absl::StatusCode::kNotFound);
  std::vector<uint32_t> sizes;
  auto frame = c->Fetch(MakeView("ball", 3, 0.01, glm::dvec3(2, 2, 2)),
                        [&](const pb::FrameChunk& ch) { sizes.push_back(ch.triangle_count()); });
  ASSERT_TRUE(frame.ok()) << frame.status();
  ASSERT_GT(sizes.size(), 3u);
  EXPECT_EQ(sizes[0], 1024u);
  EXPECT_EQ(sizes[1], 2048u);
  for (size_t i = 2; i + 1 < sizes.size(); ++i) EXPECT_EQ(sizes[i], 4096u);
}

TEST_F(ConfiguredDaemon, ShutdownTurnsHealthOffAndFinishesTheFrameInFlight) {
  // A frame too big for the transport's buffers (raw, flat normals: ~85 bytes per triangle,
  // ~690k triangles), read by a client that stops after the first chunk until the checks
  // below are done: the frame is still in flight on the server while they run.
  auto c = Connect();
  std::atomic<bool> started{false}, resume{false};
  absl::StatusOr<net::Frame> slow = absl::UnknownError("not run");
  std::thread reader([&] {
    pb::ViewRequest v = MakeView("big", 5, 0.0, glm::dvec3(3, 2, 4), pb::RAW);
    v.set_normals(pb::FLAT);
    slow = c->Fetch(v, [&](const pb::FrameChunk&) {
      started = true;
      for (int i = 0; i < 1000 && !resume; ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    });
  });
  for (int i = 0; i < 2000 && !started; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_TRUE(started);
  // An idle session, open when the signal comes: it ends with UNAVAILABLE.
  auto idle = c->OpenSession();
  ASSERT_TRUE(idle.ok());
  ASSERT_TRUE((*idle)->Send(MakeView("ball", 9, 0.05, glm::dvec3(2, 2, 2))).ok());
  pb::FrameChunk chunk;
  while ((*idle)->Read(&chunk) && !chunk.last()) {
  }
  ASSERT_EQ(kill(daemon_->pid(), SIGTERM), 0);
  // While the frame drains: health NOT_SERVING and new streams refused.
  bool not_serving = false;
  for (int i = 0; i < 200 && !not_serving; ++i) {
    auto h = Connect()->CheckHealth();
    not_serving = h.ok() && !*h;
    if (!not_serving) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  EXPECT_TRUE(not_serving);
  EXPECT_EQ(Connect()->Fetch(MakeView("ball", 6, 0.05, glm::dvec3(2, 2, 2))).status().code(),
            absl::StatusCode::kUnavailable);
  EXPECT_EQ((*idle)->Finish().code(), absl::StatusCode::kUnavailable);
  resume = true;
  reader.join();
  ASSERT_TRUE(slow.ok()) << slow.status();
  EXPECT_EQ(slow->stats.triangles(), int64_t(slow->mesh.triangle_count()));
  EXPECT_EQ(daemon_->Stop(SIGTERM), 0);
}

// --deadline-ms 1: every frame that takes longer than a millisecond from request to last
// chunk (all of them) ends with DEADLINE_EXCEEDED, and the daemon carries on.
class ImpatientDaemon : public Daemon {
 protected:
  static void SetUpTestSuite() {
    scratch_ = new ScratchDir();
    daemon_ = new DaemonProcess();
    ASSERT_TRUE(daemon_->Start({"--deadline-ms", "1", "--cache-dir", scratch_->path() + "/cache"},
                               scratch_->path() + "/isostreamd.log"));
  }
};

TEST_F(ImpatientDaemon, SlowFrameIsDeadlineExceeded) {
  auto c = Connect();
  for (int i = 0; i < 2; ++i)
    EXPECT_EQ(c->Fetch(MakeView("buckyball:65", 1, 0.002, glm::dvec3(2, 2, 2))).status().code(),
              absl::StatusCode::kDeadlineExceeded);
  auto health = c->CheckHealth();
  EXPECT_TRUE(health.ok() && *health);
}

// --idle-timeout-s 1: a session with no request and nothing in flight for a second is ended
// by the server; sessions that keep asking are not, and the daemon keeps serving.
class IdleDaemon : public Daemon {
 protected:
  static void SetUpTestSuite() {
    scratch_ = new ScratchDir();
    daemon_ = new DaemonProcess();
    ASSERT_TRUE(daemon_->Start(
        {"--idle-timeout-s", "1", "--threads", "2", "--cache-dir", scratch_->path() + "/cache"},
        scratch_->path() + "/isostreamd.log"));
  }

  // Sends a small view and reads its frame to the end.
  static bool SmallFrame(net::Session* s, uint64_t id) {
    if (!s->Send(MakeView("buckyball:65", id, 0.05, glm::dvec3(2, 2, 2))).ok()) return false;
    net::FrameAssembler a;
    pb::FrameChunk chunk;
    while (!a.complete() && s->Read(&chunk)) {
      if (!a.Add(chunk).ok()) return false;
    }
    return a.complete();
  }
};

TEST_F(IdleDaemon, IdleSessionsAreClosedBusyOnesAreNot) {
  using Clock = std::chrono::steady_clock;
  auto c = Connect();
  const auto before = c->GetServerStats();
  ASSERT_TRUE(before.ok());
  auto idle = c->OpenSession();
  auto busy = c->OpenSession();
  auto silent = c->OpenSession();  // never sends a view
  ASSERT_TRUE(idle.ok() && busy.ok() && silent.ok());
  ASSERT_TRUE(SmallFrame(idle->get(), 1));
  const auto idle_since = Clock::now();
  ASSERT_TRUE(SmallFrame(busy->get(), 1));
  // Not closed early (checked only if this machine got here well within the timeout).
  const auto early = c->GetServerStats();
  ASSERT_TRUE(early.ok());
  if (Clock::now() - idle_since < std::chrono::milliseconds(800)) {
    EXPECT_EQ(early->sessions_idle_closed(), before->sessions_idle_closed());
  }
  // `busy` asks every 0.3 s for 2.4 s; `idle` and `silent` say nothing.
  for (uint64_t id = 2; id < 10; ++id) {
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    ASSERT_TRUE(SmallFrame(busy->get(), id)) << "view " << id;
  }
  const auto after_busy = Clock::now();
  pb::ServerStats stats;
  ASSERT_TRUE(WaitForStats(
      c.get(),
      [&](const pb::ServerStats& st) {
        return st.sessions_idle_closed() == before->sessions_idle_closed() + 2 &&
               st.sessions_open() == before->sessions_open() + 1;  // busy
      },
      &stats));
  // Both ended a second after going idle (checked every 0.1 s), so already, 2.4 s in.
  EXPECT_LT(Clock::now() - after_busy, std::chrono::milliseconds(500));
  for (auto* session : {idle->get(), silent->get()}) {
    pb::FrameChunk chunk;
    EXPECT_FALSE(session->Read(&chunk));
    const absl::Status status = session->Finish();
    EXPECT_EQ(status.code(), absl::StatusCode::kDeadlineExceeded) << status;
    EXPECT_NE(status.message().find("session idle for 1 s"), absl::string_view::npos) << status;
  }
  // The busy session still works, then ends normally; a new session is served.
  ASSERT_TRUE(SmallFrame(busy->get(), 10));
  ASSERT_TRUE((*busy)->CloseSend().ok());
  EXPECT_TRUE((*busy)->Finish().ok());
  auto fresh = c->OpenSession();
  ASSERT_TRUE(fresh.ok());
  ASSERT_TRUE(SmallFrame(fresh->get(), 1));
  ASSERT_TRUE((*fresh)->CloseSend().ok());
  EXPECT_TRUE((*fresh)->Finish().ok());
  ASSERT_TRUE(WaitForStats(
      c.get(), [](const pb::ServerStats& st) { return st.sessions_open() == 0; }, &stats));
  EXPECT_EQ(stats.sessions_idle_closed(), before->sessions_idle_closed() + 2);
  EXPECT_EQ(stats.sessions_closed(), before->sessions_closed() + 4);
}

TEST_F(IdleDaemon, AFrameInFlightIsNotIdle) {
  // A frame too big for the transport's buffers (raw, flat normals: ~60 MB in ~16 chunks), read
  // at 0.2 s per chunk: the server waits on the client for well over the 1 s timeout, and the
  // session must not count as idle meanwhile. The idle clock starts after the last chunk.
  auto c = Connect();
  const auto before = c->GetServerStats();
  ASSERT_TRUE(before.ok());
  auto session = c->OpenSession();
  ASSERT_TRUE(session.ok());
  pb::ViewRequest view = MakeView("buckyball:129", 1, 0.0, glm::dvec3(3, 2, 4), pb::RAW);
  view.set_normals(pb::FLAT);
  ASSERT_TRUE((*session)->Send(view).ok());
  const auto start = std::chrono::steady_clock::now();
  net::FrameAssembler a;
  pb::FrameChunk chunk;
  bool checked = false;
  while (!a.complete() && (*session)->Read(&chunk)) {
    ASSERT_TRUE(a.Add(chunk).ok());
    if (!checked && std::chrono::steady_clock::now() - start > std::chrono::milliseconds(2200)) {
      // Twice the timeout into the frame, with chunks still to come: not closed.
      auto stats = c->GetServerStats();
      ASSERT_TRUE(stats.ok());
      EXPECT_EQ(stats->sessions_idle_closed(), before->sessions_idle_closed());
      EXPECT_FALSE(chunk.last());
      checked = true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  ASSERT_TRUE(a.complete());
  EXPECT_TRUE(checked) << "the frame streamed in under 2.2 s; it no longer tests anything";
  // Then it is idle: ended within bounded time.
  const absl::Status status = (*session)->Finish();
  EXPECT_EQ(status.code(), absl::StatusCode::kDeadlineExceeded) << status;
}

class TlsDaemon : public Daemon {};

TEST_F(TlsDaemon, ServesOverTls) {
  ScratchDir dir;
  const std::string key = dir.path() + "/key.pem", cert = dir.path() + "/cert.pem";
  const std::string make =
      "openssl req -x509 -newkey rsa:2048 -nodes -keyout " + key + " -out " + cert +
      " -days 1 -subj /CN=localhost -addext subjectAltName=IP:127.0.0.1,DNS:localhost "
      ">/dev/null 2>&1";
  if (std::system(make.c_str()) != 0) GTEST_SKIP() << "openssl cannot make a test certificate";
  DaemonProcess tls;
  ASSERT_TRUE(tls.Start({"--tls-cert", cert, "--tls-key", key, "--no-cache"},
                        dir.path() + "/isostreamd.log"));
  std::ifstream in(cert);
  std::stringstream pem;
  pem << in.rdbuf();
  net::ClientOptions o;
  o.address = tls.address();
  o.tls_ca_pem = pem.str();
  auto secure = net::Client::Connect(o);
  ASSERT_TRUE(secure.ok());
  auto frame = (*secure)->Fetch(MakeView("buckyball:65", 1, 0.05, glm::dvec3(2, 2, 2)));
  EXPECT_TRUE(frame.ok()) << frame.status();
  o.tls_ca_pem.clear();
  o.call_timeout = std::chrono::milliseconds(2000);
  auto plain = net::Client::Connect(o);
  ASSERT_TRUE(plain.ok());
  EXPECT_FALSE((*plain)->ListVolumes().ok());
  EXPECT_EQ(tls.Stop(SIGTERM), 0);
}

}  // namespace
}  // namespace isostream
