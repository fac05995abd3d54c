// Integration tests of isostreamd started with options: a token and tight limits, a catalogue
// from a config file, a short frame deadline, an idle timeout (what it refuses at start, and
// TLS: daemon_start_test.cpp). Each suite starts its own
// daemon on 127.0.0.1 (daemon_fixture.h); every wait is bounded.
#include <gtest/gtest.h>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <thread>
#include <vector>

#include "tests/common/run_command.h"
#include "tests/integration/daemon_fixture.h"

// In the fixture's namespace: Daemon, MakeView, kIso, pb and the process helpers need no
// using-declarations.
namespace isostream::testing {
namespace {

// A daemon with a token and tight limits; it is stopped with SIGTERM at the end.
class GuardedDaemon : public Daemon {
 protected:
  static void SetUpTestSuite() {
    StartSuiteDaemon([](const std::string& dir) {
      // "1e5": counts may be written with an exponent.
      return std::vector<std::string>{"--cache-dir", dir + "/cache", "--threads",       "2",
                                      "--token",     "s3cret",       "--max-triangles", "1e5"};
    });
  }
};

// `isostream stats` prints the daemon's counters by their proto names, with the token the
// daemon requires (without it, the token's message).
TEST_F(GuardedDaemon, TheStatsCommandPrintsTheCounters) {
  const std::string stats =
      ShellQuote(ISOSTREAM_CLI_PATH) + " stats --server " + daemon_->address();
  const CommandResult refused = RunCommand(stats);
  EXPECT_EQ(refused.code, 1);
  EXPECT_NE(refused.output.find("refused the token"), std::string::npos) << refused.output;
  ASSERT_TRUE(Connect("s3cret")->Fetch(MakeView("sphere:17", 1, 0.01, glm::dvec3(2, 2, 2))).ok());
  const CommandResult r = RunCommand(stats + " --token s3cret");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("serving                true\n"), std::string::npos) << r.output;
  const size_t sent = r.output.find("frames_sent ");
  ASSERT_NE(sent, std::string::npos) << r.output;
  EXPECT_GE(std::stoll(r.output.substr(sent + 12)), 1) << r.output;
}

TEST_F(GuardedDaemon, TokenIsRequired) {
  const auto view = MakeView("buckyball:65", 1, 0.05, glm::dvec3(2, 2, 2));
  const absl::Status missing = Connect()->Fetch(view).status();
  EXPECT_EQ(missing.code(), absl::StatusCode::kUnauthenticated);
  net::ClientOptions without, with;
  with.token = "wrong";
  EXPECT_NE(net::ExplainCallError(missing, without).find("pass --token"), std::string::npos);
  // A token given but wrong is not told to be passed (it was: "pass --token").
  const absl::Status wrong = Connect("wrong")->Fetch(view).status();
  EXPECT_EQ(wrong.code(), absl::StatusCode::kUnauthenticated);
  EXPECT_NE(net::ExplainCallError(wrong, with).find("check the value given to --token"),
            std::string::npos);
  EXPECT_EQ(Connect("wrong")->GetServerStats().status().code(), absl::StatusCode::kUnauthenticated);
  auto session = Connect("s3cre")->OpenSession();
  ASSERT_TRUE(session.ok());
  EXPECT_EQ((*session)->Finish().code(), absl::StatusCode::kUnauthenticated);
  // Health needs no token.
  auto health = Connect()->CheckHealth();
  ASSERT_TRUE(health.ok());
  EXPECT_TRUE(*health);
  EXPECT_TRUE(Connect("s3cret")->Fetch(view).ok());
  // The scheme's name is case-insensitive (RFC 7235), and any authorization header may carry
  // the token ("bearer s3cret" was refused, and a second header was never read).
  auto stub = pb::Isostream::NewStub(
      grpc::CreateChannel(daemon_->address(), grpc::InsecureChannelCredentials()));
  auto stats_with = [&](const std::vector<std::string>& headers) {
    grpc::ClientContext context;
    for (const std::string& h : headers) context.AddMetadata("authorization", h);
    pb::GetServerStatsRequest request;
    pb::ServerStats stats;
    return stub->GetServerStats(&context, request, &stats).error_code();
  };
  EXPECT_EQ(stats_with({"bearer s3cret"}), grpc::StatusCode::OK);
  EXPECT_EQ(stats_with({"Bearer   s3cret"}), grpc::StatusCode::OK);  // 1*SP
  EXPECT_EQ(stats_with({"BEARER s3cret"}), grpc::StatusCode::OK);
  EXPECT_EQ(stats_with({"Basic abc", "Bearer s3cret"}), grpc::StatusCode::OK);
  EXPECT_EQ(stats_with({"Bearer S3cret"}), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(stats_with({"Bearers3cret"}), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(stats_with({"s3cret"}), grpc::StatusCode::UNAUTHENTICATED);
  // gRPC aborts on metadata it cannot send: such a token is refused before any call.
  for (const char* bad : {"a\nb", "t\xc3\xb6k", "\x7f"}) {
    net::ClientOptions o;
    o.address = daemon_->address();
    o.token = bad;
    EXPECT_EQ(net::Client::Connect(o).status().code(), absl::StatusCode::kInvalidArgument) << bad;
  }
  for (const char* address : {"127.0.0.1:104903", "127.0.0.1:-1", ""}) {  // 39367, 65535, none
    net::ClientOptions bad_address;
    bad_address.address = address;
    EXPECT_EQ(net::Client::Connect(bad_address).status().code(), absl::StatusCode::kInvalidArgument)
        << address;
  }
}

TEST_F(GuardedDaemon, FrameOverTriangleLimitIsResourceExhausted) {
  // About 138k triangles at this eps, over --max-triangles 100000.
  auto s = Connect("s3cret")->Fetch(MakeView("buckyball:65", 1, 0.002, glm::dvec3(2, 2, 2)));
  EXPECT_EQ(s.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_NE(s.status().message().find("100000"), std::string::npos) << s.status();
  auto stats = Connect("s3cret")->GetServerStats();
  ASSERT_TRUE(stats.ok());
  EXPECT_EQ(stats->frames_failed(), 1);  // the suite's only frame over the limit
}

// A budget over --max-triangles is taken as the limit, not refused: both are ceilings, and the
// mesh may be far smaller than either.
TEST_F(GuardedDaemon, BudgetOverTheTriangleLimitIsTheLimit) {
  pb::ViewRequest view = MakeView("buckyball:65", 1, 0.002, glm::dvec3(2, 2, 2));
  view.set_triangle_budget(1'000'000'000);
  auto frame = Connect("s3cret")->Fetch(view);
  ASSERT_TRUE(frame.ok()) << frame.status();
  EXPECT_GT(frame->mesh.triangle_count(), 50'000u);
  EXPECT_LE(frame->mesh.triangle_count(), 100'000u);
  EXPECT_EQ(frame->stats.triangle_budget(), 100'000);  // what the frame was fitted to
  EXPECT_GT(frame->stats.eps_used(), 0.0);
  // The CLI says why the mesh is coarser than the budget asked for.
  const testing::CommandResult fetched = testing::RunCommand(
      ::isostream::testing::ShellQuote(ISOSTREAM_CLI_PATH) + " fetch --server " +
      daemon_->address() +
      " --token s3cret --volume buckyball:65 --iso 0.05,0.15,0.25 --budget 1e9 --stats -o " +
      scratch_->path() + "/limited.ply");
  EXPECT_EQ(fetched.code, 0) << fetched.output;
  EXPECT_NE(fetched.output.find("budget        100000  (the daemon's frame limit)"),
            std::string::npos)
      << fetched.output;
  EXPECT_NE(fetched.output.find("the frame was fitted to its limit of 100000"), std::string::npos)
      << fetched.output;
}

// SIGHUP (a closing terminal) stops it as SIGTERM does (ConfiguredDaemon's shutdown test): its
// default action ended the process, cutting frames in flight.
TEST_F(GuardedDaemon, SighupFinishesTheFrameInFlightAndExitsZero) {
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
  EXPECT_EQ(daemon_->Stop(SIGHUP), 0);
  fetch.join();
  EXPECT_TRUE(fetched.ok()) << fetched;
}

// A small OpenVDB file whose grid type name claims 2 GB (OpenVDB alone would allocate and fill
// that much before failing); returns its path.
std::string WriteDamagedVdb(const std::string& dir) {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(0.0f);
  grid->setName("density");
  grid->tree().fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(7)), 1.0f, true);
  const std::string path = dir + "/damaged.vdb";
  openvdb::io::File(path).write({grid});
  std::ifstream in(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t type = bytes.find("Tree_float_5_4_3");
  EXPECT_NE(type, std::string::npos);
  const uint32_t claimed = 0x7f000000u;
  std::memcpy(&bytes[type - 4], &claimed, 4);
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
  return path;
}

// An 8^3 raw float32 file at `path`: x + y + z.
void WriteRawRamp(const std::string& path) {
  std::vector<float> v;
  for (int z = 0; z < 8; ++z)
    for (int y = 0; y < 8; ++y)
      for (int x = 0; x < 8; ++x) v.push_back(float(x + y + z));
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(v.data()), std::streamsize(4 * v.size()));
}

// A daemon with a JSON config: a catalogue (so generator specs are refused) with one damaged
// file in it and one named by a path relative to the config's folder (the daemon runs in the
// tests' own), small chunks, and no retained frames.
class ConfiguredDaemon : public Daemon {
 protected:
  static void SetUpTestSuite() {
    StartSuiteDaemon([](const std::string& dir) {
      std::filesystem::create_directories(dir + "/data");
      WriteRawRamp(dir + "/data/ramp.raw");
      const std::string config = dir + "/isostreamd.json";
      std::ofstream(config)
          << R"({"threads": 2, "volumes": {"ball": "buckyball:65", "big": "buckyball:129",
                                           "ramp": "raw:data/ramp.raw:8x8x8:float32",
                                           "damaged": ")"
          << WriteDamagedVdb(dir) << R"("},
          "frames": {"chunk_triangles": 4096, "first_chunk_triangles": 1024,
                     "max_queued_chunks": 4, "retain_mb": 0}})";
      return std::vector<std::string>{"--config", config, "--cache-dir", dir + "/cache"};
    });
  }
};

TEST_F(ConfiguredDaemon, ServesItsCatalogueOnly) {
  auto c = Connect();
  auto list = c->ListVolumes();
  ASSERT_TRUE(list.ok());
  ASSERT_EQ(list->names_size(), 4);
  EXPECT_EQ(list->names(0), "ball");
  EXPECT_EQ(list->names(1), "big");
  EXPECT_EQ(list->names(2), "damaged");
  EXPECT_EQ(list->names(3), "ramp");
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

// A relative path in the config file is the file's, not the daemon's working directory's
// (found by a helper's walkthrough: "data/ct.nii.gz" failed at every preparation for a daemon
// started elsewhere, as systemd starts it in /).
TEST_F(ConfiguredDaemon, ARelativePathIsTheConfigFilesOwn) {
  auto c = Connect();
  auto info = c->GetVolumeInfo("ramp", 1);
  ASSERT_TRUE(info.ok()) << info.status() << "\n" << DaemonLog(*scratch_);
  EXPECT_EQ(info->dims(0), 8);
  EXPECT_EQ(info->min_value(), 0.0f);
  EXPECT_EQ(info->max_value(), 21.0f);
}

// `isostream volumes` lists the catalogue (the daemon's "unknown volume" message points at it)
// and, with --info, each volume's facts, or why one is not served (exit 1 then).
TEST_F(ConfiguredDaemon, TheVolumesCommandListsTheCatalogueAndItsFacts) {
  const CommandResult r = RunCommand(ShellQuote(ISOSTREAM_CLI_PATH) + " volumes --server " +
                                     daemon_->address() + " --info");
  EXPECT_EQ(r.code, 1) << r.output;  // "damaged"
  EXPECT_NE(r.output.find("ball\n  dims            65 x 65 x 65\n"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("ramp\n  dims            8 x 8 x 8\n"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("  value range     [0, 21]\n"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("damaged\n  not served: "), std::string::npos) << r.output;
  const CommandResult names =
      RunCommand(ShellQuote(ISOSTREAM_CLI_PATH) + " volumes --server " + daemon_->address());
  EXPECT_EQ(names.code, 0) << names.output;
  EXPECT_EQ(names.output, "ball\nbig\ndamaged\nramp\n");
  // A --tls-ca holding no certificate is an argument's fault (exit 2), for stats too.
  const std::string empty_ca = scratch_->path() + "/empty.pem";
  std::ofstream(empty_ca).close();
  for (const char* command : {" volumes", " stats"}) {
    const CommandResult bad_ca =
        RunCommand(ShellQuote(ISOSTREAM_CLI_PATH) + command + " --server " + daemon_->address() +
                   " --tls-ca " + empty_ca);
    EXPECT_EQ(bad_ca.code, 2) << command << "\n" << bad_ca.output;
    EXPECT_NE(bad_ca.output.find("holds no certificates"), std::string::npos) << bad_ca.output;
  }
  auto unknown = Connect()->Fetch(MakeView("nope", 1, 0.01, glm::dvec3(2, 2, 2)));
  EXPECT_NE(unknown.status().message().find("`isostream volumes` lists them"), std::string::npos)
      << unknown.status();
}

// The damaged catalogue file is refused to whoever asks for it, every time (clients learn the
// volume's name, the operator's log the byte at fault); the daemon goes on serving the rest.
// The client's request is right: FAILED_PRECONDITION, not the file's DATA_LOSS (the viewer took
// an INVALID_ARGUMENT of a bad spec for its own argument error). The failure is remembered, so
// clients asking again do not re-read the file and log it each time.
TEST_F(ConfiguredDaemon, ADamagedFileIsRefusedAndTheRestServes) {
  auto c = Connect();
  const std::string reason = "grid type claims 2130706432 bytes";
  auto reads = [&] {  // how many times the daemon has logged reading the file
    const std::string log = DaemonLog(*scratch_);
    size_t n = 0;
    for (size_t at = log.find(reason); at != std::string::npos; at = log.find(reason, at + 1)) ++n;
    return n;
  };
  size_t after_first = 0;
  for (int attempt = 0; attempt < 3; ++attempt) {
    const auto damaged = c->Fetch(MakeView("damaged", 1, 0.0, glm::dvec3(2, 2, 2)));
    ASSERT_FALSE(damaged.ok());
    EXPECT_EQ(damaged.status().code(), absl::StatusCode::kFailedPrecondition) << damaged.status();
    EXPECT_NE(damaged.status().message().find("volume 'damaged'"), std::string::npos)
        << damaged.status();
    if (attempt == 0) after_first = reads();
  }
  EXPECT_GE(after_first, 1u) << DaemonLog(*scratch_);
  EXPECT_EQ(reads(), after_first) << DaemonLog(*scratch_);
  const auto ball = c->Fetch(MakeView("ball", 1, 0.01, glm::dvec3(2, 2, 2)));
  ASSERT_TRUE(ball.ok()) << ball.status();
  EXPECT_GT(ball->mesh.triangle_count(), 0u);
  auto health = c->CheckHealth();
  EXPECT_TRUE(health.ok());
}

// With retain_mb 0 every view is extracted, the same mesh or not, and nothing is held.
TEST_F(ConfiguredDaemon, RetainsNothingWhenItsBudgetIsZero) {
  auto c = Connect();
  auto session = c->OpenSession();
  ASSERT_TRUE(session.ok());
  net::Session& s = **session;
  for (int i = 0; i < 3; ++i) {  // with retain_mb > 0, views 2 and 3 are re-ordered (daemon_test)
    ASSERT_TRUE(s.Send(MakeView("ball", 40 + i, 0.003, glm::dvec3(2, 2 - 2 * i, 2))).ok());
    net::FrameAssembler assembler;
    pb::FrameChunk chunk;
    while (!assembler.complete() && s.Read(&chunk)) ASSERT_TRUE(assembler.Add(chunk).ok());
    ASSERT_TRUE(assembler.complete());
    EXPECT_FALSE(assembler.Take().stats.reordered());
  }
  auto stats = c->GetServerStats();
  ASSERT_TRUE(stats.ok());
  EXPECT_EQ(stats->frames_reordered(), 0);
  EXPECT_EQ(stats->retained_bytes(), 0);
  ASSERT_TRUE(s.CloseSend().ok());
  EXPECT_TRUE(s.Finish().ok());
}

// The catalogue is prepared at start (config `preload`, on by default), with no request for it.
TEST_F(ConfiguredDaemon, PreparesItsCatalogueAtStart) {
  bool preloaded = false;
  for (int i = 0; i < 400 && !preloaded; ++i) {
    preloaded =
        DaemonLog(*scratch_).find("preloaded 3 of 4 catalogue volumes") != std::string::npos;
    if (!preloaded) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  EXPECT_TRUE(preloaded) << DaemonLog(*scratch_);
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
    StartSuiteDaemon([](const std::string& dir) {
      return std::vector<std::string>{"--deadline-ms", "1", "--cache-dir", dir + "/cache"};
    });
  }
};

TEST_F(ImpatientDaemon, SlowFrameIsDeadlineExceeded) {
  auto c = Connect();
  for (int i = 0; i < 2; ++i)
    EXPECT_EQ(c->Fetch(MakeView("buckyball:65", 1, 0.002, glm::dvec3(2, 2, 2))).status().code(),
              absl::StatusCode::kDeadlineExceeded);
  auto health = c->CheckHealth();
  EXPECT_TRUE(health.ok() && *health);
  // Counted as failed by the server, not as cancelled (nobody cancelled them) or sent.
  auto stats = c->GetServerStats();
  ASSERT_TRUE(stats.ok());
  EXPECT_EQ(stats->frames_failed(), 2);
  EXPECT_EQ(stats->frames_started(), 2);
  EXPECT_EQ(stats->frames_cancelled(), 0);
  EXPECT_EQ(stats->frames_sent(), 0);
}

// --idle-timeout-s 1: a session with no request and nothing in flight for a second is ended
// by the server; sessions that keep asking are not, and the daemon keeps serving.
class IdleDaemon : public Daemon {
 protected:
  static void SetUpTestSuite() {
    StartSuiteDaemon([](const std::string& dir) {
      return std::vector<std::string>{"--idle-timeout-s", "1",           "--threads", "2",
                                      "--cache-dir",      dir + "/cache"};
    });
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

// --max-sessions 1: a request's slot lasts until its job has ended, not only until its client
// has gone, so clients that leave cannot keep more jobs running than there are slots. A
// volume's preparation is no job's: it runs on the catalogue's threads, once per volume, and a
// job waiting for it ends as soon as its client leaves (every preparation here first sleeps 3 s,
// the ISOSTREAMD_TEST_PREPARE_DELAY_MS hook: a real volume slow enough on one machine can be
// ready within the test's window on another).
class OneSlotDaemon : public Daemon {
 protected:
  static void SetUpTestSuite() {
    setenv("ISOSTREAMD_TEST_PREPARE_DELAY_MS", "3000", 1);
    StartSuiteDaemon([](const std::string&) {
      return std::vector<std::string>{"--max-sessions", "1", "--no-cache"};
    });
    unsetenv("ISOSTREAMD_TEST_PREPARE_DELAY_MS");
  }
  static int PreparedCount(const std::string& name) {
    const std::string log = DaemonLog(*scratch_), line = "prepared volume '" + name + "'";
    int count = 0;
    for (size_t at = log.find(line); at != std::string::npos; at = log.find(line, at + 1)) ++count;
    return count;
  }
};

// The slot of a session cancelled while its view waits for a preparation comes back before the
// preparation ends (it came back only then), and the preparation is not started again for the
// next request of the volume.
TEST_F(OneSlotDaemon, ACancelledJobWaitingForAPreparationGivesItsSlotBack) {
  auto c = Connect();
  {
    auto session = c->OpenSession();
    ASSERT_TRUE(session.ok());
    ASSERT_TRUE((*session)->Send(MakeView("cayley:65", 1, 0.01, glm::dvec3(3, 2, 4))).ok());
    ASSERT_TRUE(
        WaitForOpenSessions(*c, 1, std::chrono::steady_clock::now() + std::chrono::seconds(2)));
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
    (*session)->Cancel();  // the client is gone; the volume is still being prepared
  }
  // The slot comes back within a second, while the preparation has ~2.8 s to go.
  ASSERT_TRUE(
      WaitForOpenSessions(*c, 0, std::chrono::steady_clock::now() + std::chrono::seconds(1)))
      << DaemonLog(*scratch_);
  EXPECT_EQ(PreparedCount("cayley:65"), 0) << "the slot came back only when the preparation ended";
  // The same volume again: it waits for the preparation in progress, not for a second one.
  auto info = c->GetVolumeInfo("cayley:65", 1);
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(PreparedCount("cayley:65"), 1) << DaemonLog(*scratch_);
}

// A client doing one thing at a time never meets its own last session still holding the only
// slot: the slot goes back before the client sees the stream's status (it went back when gRPC
// called OnDone, a few ms later, and a session or call opened at once was refused).
TEST_F(OneSlotDaemon, OneCallAtATimeIsNeverRefused) {
  auto c = Connect();
  for (int i = 0; i < 100; ++i) {
    auto session = c->OpenSession();
    ASSERT_TRUE(session.ok());
    if (i % 2 == 0) {  // half of them draw a frame first
      ASSERT_TRUE((*session)->Send(MakeView("sphere:17", i + 1, 0.01, glm::dvec3(3, 2, 4))).ok());
      net::FrameAssembler frames;
      pb::FrameChunk chunk;
      while (!frames.complete() && (*session)->Read(&chunk)) ASSERT_TRUE(frames.Add(chunk).ok());
      EXPECT_TRUE(frames.complete()) << i;
    }
    ASSERT_TRUE((*session)->CloseSend().ok());
    const absl::Status ended = (*session)->Finish();
    ASSERT_TRUE(ended.ok()) << i << ": " << ended;
    const absl::Status info = c->GetVolumeInfo("sphere:17").status();
    ASSERT_TRUE(info.ok()) << i << ": " << info;
  }
}

// Started with SIGHUP ignored (nohup), it keeps serving through one: a blocked signal is queued
// for sigwait even when ignored, so waiting for SIGHUP too stopped it.
TEST(DaemonStart, KeepsServingThroughAnIgnoredSighup) {
  ScratchDir dir;
  DaemonProcess daemon;
  struct sigaction ignore {
  }, previous{};
  ignore.sa_handler = SIG_IGN;
  sigemptyset(&ignore.sa_mask);
  ASSERT_EQ(sigaction(SIGHUP, &ignore, &previous), 0);  // inherited through fork and exec
  const bool started = daemon.Start({"--no-cache"}, dir.path() + "/daemon.log");
  sigaction(SIGHUP, &previous, nullptr);
  ASSERT_TRUE(started);
  ASSERT_EQ(kill(daemon.pid(), SIGHUP), 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  net::ClientOptions o;
  o.address = daemon.address();
  auto c = net::Client::Connect(o);
  ASSERT_TRUE(c.ok());
  const auto frame = (*c)->Fetch(MakeView("sphere:17", 1, 0.01, glm::dvec3(2, 2, 2)));
  EXPECT_TRUE(frame.ok()) << frame.status();
  EXPECT_EQ(daemon.Stop(SIGTERM), 0);
}

// A budget whose coarsest mesh is over --max-triangles is told that nothing coarser exists,
// not to "give a triangle budget" it gave.
TEST(DaemonStart, CoarsestMeshOverTheLimitIsExplained) {
  ScratchDir dir;
  DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start({"--no-cache", "--max-triangles", "10"}, dir.path() + "/d.log"));
  net::ClientOptions o;
  o.address = daemon.address();
  auto c = net::Client::Connect(o);
  ASSERT_TRUE(c.ok());
  pb::ViewRequest view = MakeView("cayley:33", 1, 0.01, glm::dvec3(2, 2, 2));
  view.mutable_surfaces(0)->set_isovalue(0);
  view.set_triangle_budget(5);  // the coarsest mesh has 12
  const absl::Status s = (*c)->Fetch(view).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted) << s;
  EXPECT_NE(s.message().find("even the coarsest mesh"), std::string::npos) << s;
  EXPECT_EQ(daemon.Stop(), 0);
}

// A progressive view's coarse frame stays within --max-triangles: its budget (20,000 by
// default) was not capped, so a view over a limit of 1,000 was refused as if even the coarsest
// mesh were over it. Now the coarse frame arrives and the view itself is told to raise eps.
TEST(DaemonStart, CoarseFrameKeepsToTheTriangleLimit) {
  ScratchDir dir;
  DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start({"--no-cache", "--max-triangles", "1000"}, dir.path() + "/d.log"));
  net::ClientOptions o;
  o.address = daemon.address();
  auto c = net::Client::Connect(o);
  ASSERT_TRUE(c.ok());
  pb::ViewRequest view = MakeView("buckyball:65", 1, 0.002, glm::dvec3(2, 2, 2));
  view.set_progressive(true);
  int64_t coarse_triangles = 0;
  const absl::Status s = (*c)->Fetch(view,
                                     [&](const pb::FrameChunk& chunk) {
                                       if (chunk.coarse())
                                         coarse_triangles += chunk.triangle_count();
                                     })
                             .status();
  EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted) << s;
  EXPECT_NE(s.message().find("raise eps or give a triangle budget"), std::string::npos) << s;
  EXPECT_GT(coarse_triangles, 0);
  EXPECT_LE(coarse_triangles, 1000);
  EXPECT_EQ(daemon.Stop(), 0);
}

// One slot, a 2 s frame deadline and no idle timeout: a client that stops reading must not keep
// the slot (a write it never takes would otherwise hold the stream open for good).
class StalledClientDaemon : public Daemon {
 protected:
  static void SetUpTestSuite() {
    StartSuiteDaemon([](const std::string& dir) {
      return std::vector<std::string>{"--max-sessions",   "1", "--deadline-ms", "2000",
                                      "--idle-timeout-s", "0", "--cache-dir",   dir + "/cache"};
    });
  }
};

TEST_F(StalledClientDaemon, AClientThatStopsReadingLosesItsSlot) {
  using Clock = std::chrono::steady_clock;
  auto c = Connect();
  auto stalled = c->OpenSession();
  ASSERT_TRUE(stalled.ok());
  // ~1.5 M triangles, raw: ~40 MB, far past what the transport buffers between the two hold.
  ASSERT_TRUE(
      (*stalled)->Send(MakeView("buckyball:257", 1, 0.0005, glm::dvec3(2, 2, 2), pb::RAW)).ok());
  // It never reads. Another client gets the slot once the stalled write has been given up on.
  const Clock::time_point t0 = Clock::now();
  bool served = false;
  int refused = 0;
  while (!served && Clock::now() - t0 < std::chrono::seconds(40)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
    auto other = Connect()->Fetch(MakeView("buckyball:65", 2, 0.05, glm::dvec3(2, 2, 2)));
    served = other.ok();
    if (!served) {
      EXPECT_EQ(other.status().code(), absl::StatusCode::kResourceExhausted) << other.status();
      ++refused;
    }
  }
  EXPECT_TRUE(served) << "the stalled client kept its slot for 40 s";
  EXPECT_GT(refused, 0) << "the stalled frame ended before the first call: nothing tested";
  // Its stream was ended with a reason.
  pb::FrameChunk chunk;
  while ((*stalled)->Read(&chunk)) {
  }
  const absl::Status ended = (*stalled)->Finish();
  EXPECT_FALSE(ended.ok());
  // Its slot goes back when its frame's job has ended, which notices the cancelled call within
  // a poll of its queue: maybe just after the client has seen the end.
  auto stats = c->GetServerStats();
  for (int i = 0; i < 100 && stats.ok() && stats->sessions_open() != 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    stats = c->GetServerStats();
  }
  ASSERT_TRUE(stats.ok());
  EXPECT_EQ(stats->sessions_open(), 0);
  EXPECT_EQ(stats->streams_stalled(), 1);
}

// A client that reads steadily but slowly gets the whole frame, even when its delivery takes
// longer than the frame deadline (2 s here): the deadline bounds the extraction. A
// 3.6 M-triangle frame read at ~200 KB/s was refused as past the deadline.
TEST_F(StalledClientDaemon, ASlowReaderGetsTheWholeFrame) {
  using Clock = std::chrono::steady_clock;
  auto c = Connect();
  auto session = c->OpenSession();
  ASSERT_TRUE(session.ok());
  // ~1.5 M triangles, raw (45,000 per chunk): ~34 chunks of ~1.2 MB, most of them past what
  // the transport buffers hold, read one per 150 ms: over 3 s of reading.
  ASSERT_TRUE(
      (*session)->Send(MakeView("buckyball:257", 1, 0.0005, glm::dvec3(2, 2, 2), pb::RAW)).ok());
  const Clock::time_point t0 = Clock::now();
  pb::FrameChunk chunk;
  int chunks = 0;
  bool last = false;
  while (!last && (*session)->Read(&chunk)) {
    ++chunks;
    last = chunk.last();
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
  }
  EXPECT_TRUE(last) << "the frame ended after " << chunks << " chunks";
  EXPECT_GT(Clock::now() - t0, std::chrono::milliseconds(3000)) << "delivery was not slow: "
                                                                << "nothing tested";
  ASSERT_TRUE((*session)->CloseSend().ok());
  EXPECT_TRUE((*session)->Finish().ok());
}

// Sessions orbiting meshes of their own at once: frames are recorded and re-ordered on several
// streams concurrently (eviction between streams is RetainedFrameTest's), every frame is still
// the one a direct extraction draws, and nothing stays retained after.
class CrowdedDaemon : public Daemon {
 protected:
  static void SetUpTestSuite() {
    StartSuiteDaemon([](const std::string& dir) {
      return std::vector<std::string>{"--cache-dir", dir + "/cache", "--retain-mb",
                                      "64",          "--threads",    "2"};
    });
  }
};

TEST_F(CrowdedDaemon, ConcurrentOrbitsStayExact) {
  PreparedVolume local = Local("buckyball:65");
  net::ClientOptions o;
  o.address = daemon_->address();
  constexpr int kSessions = 3, kViews = 6;
  std::atomic<int> reordered{0}, compared{0};
  std::vector<std::thread> sessions;
  for (int t = 0; t < kSessions; ++t) {
    sessions.emplace_back([&, t] {
      auto c = net::Client::Connect(o);
      ASSERT_TRUE(c.ok());
      auto session = (*c)->OpenSession();
      ASSERT_TRUE(session.ok());
      const double eps = 0.003 + 0.001 * t;  // a mesh of its own, ~9 MB retained
      for (int i = 0; i < kViews; ++i) {
        const double a = 0.9 * i + t;
        const glm::dvec3 eye(3 * std::cos(a), 1.5 - 0.5 * t, 3 * std::sin(a));
        ASSERT_TRUE((*session)->Send(MakeView("buckyball:65", 1 + i, eps, eye, pb::RAW)).ok());
        net::Frame frame;
        ASSERT_TRUE(ReadFrame(**session, &frame));
        reordered += frame.stats.reordered();
        auto direct = Extract(*local.hierarchy, local.grid_to_world, DirectRequest(eps, eye));
        ASSERT_TRUE(direct.ok());
        ExpectSameFrame(direct->mesh, frame.mesh, 0.0f);
        ++compared;
      }
      ASSERT_TRUE((*session)->CloseSend().ok());
      EXPECT_TRUE((*session)->Finish().ok());
    });
  }
  for (std::thread& s : sessions) s.join();
  EXPECT_EQ(compared.load(), kSessions * kViews);
  EXPECT_GT(reordered.load(), 0);
  auto c = Connect();
  pb::ServerStats stats;
  EXPECT_TRUE(WaitForStats(
      c.get(),
      [](const pb::ServerStats& s) { return s.sessions_open() == 0 && s.retained_bytes() == 0; },
      &stats));
  EXPECT_EQ(stats.frames_reordered(), reordered.load());
}

}  // namespace
}  // namespace isostream::testing
