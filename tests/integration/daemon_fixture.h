// The daemon the integration tests drive: a real isostreamd on 127.0.0.1 started once per test
// suite (a suite with other flags derives and starts its own), a client for it, and the view
// requests the tests send. Shared by daemon_test.cpp (the default daemon) and
// daemon_options_test.cpp (daemons started with a token, a catalogue, limits, TLS).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <functional>
#include <iterator>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "client/net/session_client.h"
#include "server/extract/extractor.h"
#include "server/hierarchy/prepared_volume.h"
#include "tests/integration/daemon_process.h"

namespace isostream::testing {

namespace pb = ::isostream::v1;

// The buckyball shells every test view asks for.
inline const std::vector<float> kIso = {0.05f, 0.15f, 0.25f};

inline pb::ViewRequest MakeView(const std::string& volume, uint64_t id, double eps, glm::dvec3 eye,
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

// The extraction a test compares a served frame with: the test views' isovalues at eps.
inline ExtractRequest DirectRequest(double eps, glm::dvec3 eye) {
  ExtractRequest r;
  r.isovalues = kIso;
  r.eps = eps;
  r.view.eye = eye;
  return r;
}

// Per-triangle comparison: the codec renumbers (and may duplicate) vertices, so triangles are
// compared corner by corner, in order, with their surface index.
inline void ExpectSameFrame(const OrderedMesh& direct, const OrderedMesh& got, float position_error) {
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

// Reads chunks until a frame is complete; false if the stream ends first.
inline bool ReadFrame(net::Session& s, net::Frame* out) {
  net::FrameAssembler assembler;
  pb::FrameChunk chunk;
  while (s.Read(&chunk)) {
    if (!assembler.Add(chunk).ok()) return false;
    if (assembler.complete()) {
      *out = assembler.Take();
      return true;
    }
  }
  return false;
}

// The default daemon (small limits so the limit tests stay quick), shared by a suite.
// The daemon log written in a scratch directory (the suites and DaemonProcess starts here
// write it to DIR/isostreamd.log).
inline std::string DaemonLog(const ScratchDir& scratch) {
  std::ifstream log(scratch.path() + "/isostreamd.log");
  return std::string((std::istreambuf_iterator<char>(log)), std::istreambuf_iterator<char>());
}

// Polls the daemon's open sessions until `open` (true) or `until` has passed (false).
inline bool WaitForOpenSessions(net::Client& c, int64_t open,
                                std::chrono::steady_clock::time_point until) {
  for (;;) {
    const auto stats = c.GetServerStats();
    if (stats.ok() && stats->sessions_open() == open) return true;
    if (std::chrono::steady_clock::now() >= until) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

class Daemon : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    StartSuiteDaemon([](const std::string& dir) {
      return std::vector<std::string>{"--cache-dir", dir + "/cache", "--threads", "2",
                                      "--max-sessions", "3", "--max-isovalues", "4",
                                      "--max-triangles", "1000000", "--max-dim", "129"};
    });
  }
  // Makes the suite's scratch directory and starts its daemon with flags(that directory); a
  // suite with other flags calls it from its own SetUpTestSuite.
  static void StartSuiteDaemon(
      const std::function<std::vector<std::string>(const std::string& dir)>& flags) {
    scratch_ = new ScratchDir();
    daemon_ = new DaemonProcess();
    ASSERT_TRUE(daemon_->Start(flags(scratch_->path()), scratch_->path() + "/isostreamd.log"));
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

  inline static ScratchDir* scratch_ = nullptr;
  inline static DaemonProcess* daemon_ = nullptr;
};

}  // namespace isostream::testing
