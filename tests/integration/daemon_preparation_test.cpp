// Integration tests of isostreamd preparing its volumes: on first use with --no-preload, and
// slowly (the ISOSTREAMD_TEST_PREPARE_DELAY_MS hook), where views wait for a preparation: the
// frame deadline is not charged the wait, and views superseded meanwhile are counted. Each test
// starts its own daemon on 127.0.0.1 (daemon_process.h); every wait is bounded.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "tests/integration/daemon_fixture.h"

namespace isostream::testing {
namespace {

// --no-preload: a catalogue volume is prepared by its first request, not before.
TEST(NoPreloadDaemon, PreparesOnFirstUse) {
  ScratchDir dir;
  DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start({"--volume", "ball=buckyball:65", "--no-preload", "--no-cache"},
                           dir.path() + "/isostreamd.log"));
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  EXPECT_EQ(DaemonLog(dir).find("prepared volume 'ball'"), std::string::npos) << DaemonLog(dir);
  net::ClientOptions o;
  o.address = daemon.address();
  auto c = net::Client::Connect(o);
  ASSERT_TRUE(c.ok());
  auto info = (*c)->GetVolumeInfo("ball");
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_NE(DaemonLog(dir).find("prepared volume 'ball'"), std::string::npos);
  EXPECT_EQ(daemon.Stop(), 0);
}

// A daemon whose every preparation first sleeps 1.5 s (the test hook), with a 0.5 s frame
// deadline and `flags`, and a client of it (nullptr if either failed).
std::unique_ptr<net::Client> StartSlowlyPreparingDaemon(const std::vector<std::string>& flags,
                                                        const ScratchDir& dir,
                                                        DaemonProcess* daemon) {
  std::vector<std::string> args = {"--deadline-ms", "500", "--no-cache"};
  args.insert(args.end(), flags.begin(), flags.end());
  setenv("ISOSTREAMD_TEST_PREPARE_DELAY_MS", "1500", 1);
  const bool started = daemon->Start(args, dir.path() + "/isostreamd.log");
  unsetenv("ISOSTREAMD_TEST_PREPARE_DELAY_MS");
  if (!started) return nullptr;
  net::ClientOptions o;
  o.address = daemon->address();
  auto c = net::Client::Connect(o);
  return c.ok() ? std::move(*c) : nullptr;
}

// A view asked for while its volume is still being prepared (here the preload, slowed to
// 1.5 s by the test hook) gets its frame: the frame deadline (0.5 s) runs from when the
// volume is ready, not from the request (a 1025^3 volume took 36-49 s to prepare, and every
// first view during the preload failed with DEADLINE_EXCEEDED).
TEST(SlowPreparation, IsNotChargedToTheFrameDeadline) {
  ScratchDir dir;
  DaemonProcess daemon;
  auto c = StartSlowlyPreparingDaemon({"--volume", "ball=buckyball:33"}, dir, &daemon);
  ASSERT_NE(c, nullptr) << DaemonLog(dir);
  auto frame = c->Fetch(MakeView("ball", 1, 0.01, glm::dvec3(2, 2, 2)));
  ASSERT_TRUE(frame.ok()) << frame.status() << "\n" << DaemonLog(dir);
  EXPECT_GT(frame->mesh.triangle_count(), 0u);
  // frame_ms still counts from the request, preparation included.
  EXPECT_GE(frame->stats.frame_ms(), 500);
  EXPECT_EQ(daemon.Stop(), 0);
}

// A view that supersedes one waiting for a preparation is not charged the rest of that wait
// either: it was (view 2, read 0.5 s into a 1.5 s preparation, ended the session with
// DEADLINE_EXCEEDED under a 0.5 s deadline), whether it asked for the volume being prepared or
// another one already prepared.
TEST(SlowPreparation, IsNotChargedToAViewThatSupersedesAWaitingOne) {
  ScratchDir dir;
  DaemonProcess daemon;
  auto c = StartSlowlyPreparingDaemon({"--volume", "a=buckyball:33", "--volume",
                                       "b=buckyball:17", "--volume", "c=buckyball:21",
                                       "--no-preload"},
                                      dir, &daemon);
  ASSERT_NE(c, nullptr) << DaemonLog(dir);
  auto warm = c->Fetch(MakeView("b", 1, 0.01, glm::dvec3(2, 2, 2)));  // b: prepared now
  ASSERT_TRUE(warm.ok()) << warm.status() << "\n" << DaemonLog(dir);
  // {volume being prepared for view 1, volume of view 2}.
  for (const auto& [waiting, second] : {std::pair<std::string, std::string>{"a", "a"}, {"c", "b"}}) {
    auto session = c->OpenSession();
    ASSERT_TRUE(session.ok());
    ASSERT_TRUE((*session)->Send(MakeView(waiting, 2, 0.01, glm::dvec3(2, 2, 2))).ok());
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    ASSERT_TRUE((*session)->Send(MakeView(second, 3, 0.01, glm::dvec3(2, 2, 3))).ok());
    net::Frame frame;
    ASSERT_TRUE(ReadFrame(**session, &frame))
        << second << ": " << (*session)->Finish() << "\n" << DaemonLog(dir);
    EXPECT_EQ(frame.id, 3u) << second;
    EXPECT_GT(frame.mesh.triangle_count(), 0u) << second;
    ASSERT_TRUE((*session)->CloseSend().ok());
  }
  EXPECT_EQ(daemon.Stop(), 0);
}

// A view superseded while its volume's preparation ran, and failed, is counted as cancelled:
// it was counted nowhere (stats off by one per such view).
TEST(SlowPreparation, AViewSupersededWhileItsPreparationFailsIsCancelled) {
  ScratchDir dir;
  const std::string damaged = dir.path() + "/damaged.nii";
  std::ofstream(damaged) << "not a NIfTI file";
  DaemonProcess daemon;
  auto c = StartSlowlyPreparingDaemon({"--volume", "bad=" + damaged, "--no-preload"}, dir, &daemon);
  ASSERT_NE(c, nullptr) << DaemonLog(dir);
  const auto before = c->GetServerStats();
  ASSERT_TRUE(before.ok());
  auto session = c->OpenSession();
  ASSERT_TRUE(session.ok());
  ASSERT_TRUE((*session)->Send(MakeView("bad", 1, 0.01, glm::dvec3(2, 2, 2))).ok());
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  ASSERT_TRUE((*session)->Send(MakeView("bad", 2, 0.01, glm::dvec3(2, 2, 3))).ok());
  ASSERT_TRUE((*session)->CloseSend().ok());
  pb::FrameChunk chunk;
  while ((*session)->Read(&chunk)) {
  }
  const absl::Status ended = (*session)->Finish();
  EXPECT_EQ(ended.code(), absl::StatusCode::kFailedPrecondition) << ended;
  const auto after = c->GetServerStats();
  ASSERT_TRUE(after.ok());
  EXPECT_EQ(after->frames_cancelled() - before->frames_cancelled(), 1);
  EXPECT_EQ(daemon.Stop(), 0);
}

}  // namespace
}  // namespace isostream::testing
