// isostream-view end to end: a real daemon on 127.0.0.1, the real viewer binary, real PNGs;
// and the failures a thin client meets (server gone, wrong address, unknown volume, corrupt
// chunk bytes) give a clear error and a non-zero exit.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <utility>
#include <vector>

#include "client/net/session_client.h"
#include "client/render/image.h"
#include "client/render/mesh_renderer.h"
#include "daemon_process.h"
#include "misbehaving_server.h"
#include "tests/common/image_coverage.h"
#include "tests/common/run_command.h"

namespace isostream {
namespace {

using ViewRun = testing::CommandResult;

// `whole_command`: args is the command line itself (to wrap the viewer in timeout, say).
ViewRun View(const std::string& args, bool no_display = false, bool whole_command = false) {
  return testing::RunCommand(
      std::string(no_display ? "env -u DISPLAY -u WAYLAND_DISPLAY " : "") +
      (whole_command ? "" : ::isostream::testing::ShellQuote(ISOSTREAM_VIEW_PATH) + " ") + args);
}

// The viewer draws on the renderer's default background.
double Coverage(const render::Image& image) {
  return testing::Coverage(image, glm::vec3(render::kDefaultBackground));
}

// --help is the viewer's output: written, exit 0; unwritable (a full disk), exit 1, as the CLI's.
TEST(View, HelpThatCannotBeWrittenExitsOne) {
  EXPECT_EQ(View("--help >/dev/null").code, 0);
  // (RunCommand adds 2>&1 after the command: braces keep stderr on the pipe.)
  const ViewRun full =
      View("{ " + ::isostream::testing::ShellQuote(ISOSTREAM_VIEW_PATH) + " --help >/dev/full; }",
           false, true);
  EXPECT_EQ(full.code, 1) << full.output;
  EXPECT_NE(full.output.find("cannot write standard output"), std::string::npos) << full.output;
}

TEST(View, RendersStreamedFramesAndFailsClearly) {
  testing::ScratchDir dir;
  testing::DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start({"--no-cache"}, dir.path() + "/daemon.log"));
  const std::string png = dir.path() + "/bucky.png";
  const ViewRun ok = View("--server " + daemon.address() +
                          " --volume buckyball:65 --iso 0.05,0.15,0.25 --eps 0.01 --eye 2.2,1.6,2.8"
                          " --size 200x160 -o " +
                          png);
  ASSERT_EQ(ok.code, 0) << ok.output;
  auto image = render::ReadPng(png);
  ASSERT_TRUE(image.ok()) << image.status();
  EXPECT_EQ(image->width, 200);
  EXPECT_EQ(image->height, 160);
  EXPECT_GT(Coverage(*image), 0.1) << "the surfaces should fill a good part of the picture";

  // An orbit asks the server for a new, newly ordered frame per view. It writes orbit_NNN.png,
  // never orbit.png itself: a folder of that name is no obstacle (it was refused), and one
  // named like a frame it will write is refused before any frame (it failed after the first).
  std::filesystem::create_directory(dir.path() + "/orbit.png");
  std::filesystem::create_directory(dir.path() + "/blocked_001.png");
  const ViewRun blocked =
      View("--server " + daemon.address() +
           " --volume sphere:33 --iso 0.3 --budget 5000 --orbit 3 --size 64x64 -o " + dir.path() +
           "/blocked.png");
  EXPECT_EQ(blocked.code, 2) << blocked.output;
  EXPECT_NE(blocked.output.find("blocked_001.png is a directory"), std::string::npos)
      << blocked.output;
  EXPECT_FALSE(std::filesystem::exists(dir.path() + "/blocked_000.png"));
  const ViewRun orbit =
      View("--server " + daemon.address() +
           " --volume sphere:33 --iso 0.3,0.6 --budget 5e3 --orbit 3 --size 64x64 -o " +
           dir.path() + "/orbit.png");
  ASSERT_EQ(orbit.code, 0) << orbit.output;
  for (const char* name : {"orbit_000.png", "orbit_001.png", "orbit_002.png"})
    EXPECT_TRUE(render::ReadPng(dir.path() + "/" + name).ok()) << name;

  const ViewRun unknown = View("--server " + daemon.address() + " --volume nosuch:9 -o " + png);
  EXPECT_NE(unknown.code, 0);
  EXPECT_NE(unknown.output.find("nosuch:9"), std::string::npos) << unknown.output;

  const ViewRun bad_eps =
      View("--server " + daemon.address() + " --volume sphere:17 --iso 0.5 --eps -3 -o " + png);
  EXPECT_NE(bad_eps.code, 0);
  EXPECT_NE(bad_eps.output.find("eps"), std::string::npos) << bad_eps.output;

  const std::string address = daemon.address();
  EXPECT_EQ(daemon.Stop(), 0);
  const ViewRun gone = View("--server " + address + " --volume buckyball:65 -o " + png);
  EXPECT_NE(gone.code, 0);
  EXPECT_FALSE(gone.output.empty());

  const ViewRun wrong = View("--server 127.0.0.1:1 --volume buckyball:65 -o " + png);
  EXPECT_NE(wrong.code, 0);
  EXPECT_NE(wrong.output.find("127.0.0.1:1"), std::string::npos) << wrong.output;

  const ViewRun window = View("--server 127.0.0.1:1 --volume buckyball:65 --window", true);
  EXPECT_NE(window.code, 0);
  EXPECT_NE(window.output.find("display"), std::string::npos) << window.output;

  // Given values that used to pass for "not given" or wrap around; a token gRPC cannot send.
  for (const auto& [args, says] : std::vector<std::pair<std::string, std::string>>{
           {"--eps nan", "--eps"},
           {"--budget -5", "--budget"},
           {"--size 4294967297x1", "--size"},
           {"--token \"$(printf 'a\\tb')\"", "token"},
           // A window that would never close itself, or whose -o would never be written.
           {"--window --exit-after 0", "--exit-after"},
           {"--window --exit-after -1", "--exit-after"},
           {"--window", "--exit-after"},
           {"--samples 0", "--samples"},
           {"--samples 17", "--samples"}}) {
    const ViewRun r =
        View("--server 127.0.0.1:1 --volume buckyball:65 -o " + png + " " + args, true);
    EXPECT_EQ(r.code, 2) << args;
    EXPECT_NE(r.output.find(says), std::string::npos) << args << "\n" << r.output;
  }
}

// Views from straight above and below the volume's centre (along the viewer's up vector) are
// drawn: they were refused as "too far from the volume (or too close to it)".
TEST(View, DrawsFromStraightAboveAndBelow) {
  testing::ScratchDir dir;
  testing::DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start({"--no-cache"}, dir.path() + "/daemon.log"));
  // And from far away: the mesh is framed as from near (an eye 1e6 away framed a sphere of a
  // ten-thousandth of its distance, and drew nothing).
  for (const char* eye : {"0,5,0", "0,-3,0", "1e6,0,0"}) {
    const std::string png = dir.path() + "/top.png";
    const ViewRun run =
        View("--server " + daemon.address() +
             " --volume sphere:33 --iso 0.5 --eps 0.01 --size 64x64 --eye " + eye + " -o " + png);
    ASSERT_EQ(run.code, 0) << eye << "\n" << run.output;
    auto image = render::ReadPng(png);
    ASSERT_TRUE(image.ok()) << image.status();
    EXPECT_GT(Coverage(*image), 0.05) << eye;
  }
  // A budget under the coarsest mesh is said to be exceeded (it was drawn silently).
  const ViewRun over =
      View("--server " + daemon.address() +
           " --volume cayley:33 --iso 0 --budget 1 --size 64x64 -o " + dir.path() + "/over.png");
  EXPECT_EQ(over.code, 0) << over.output;
  EXPECT_NE(over.output.find("over the budget of 1"), std::string::npos) << over.output;
  EXPECT_EQ(daemon.Stop(), 0);
}

// A frame whose vertices all decode to one point (the surface around a single bright voxel)
// is drawn: its fitted camera had near and far equal in single precision, and the viewer
// stopped with "camera has no valid projection" (exit 2) and no picture.
TEST(View, DrawsAFrameWhoseVerticesShareOnePoint) {
  testing::ScratchDir dir;
  const std::string raw = dir.path() + "/voxel.raw";
  {
    std::string bytes(65 * 65 * 65, '\0');
    bytes[(16 * 65 + 16) * 65 + 16] = char(255);
    std::ofstream(raw, std::ios::binary) << bytes;
  }
  testing::DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start({"--no-cache", "--volume", "voxel=raw:" + raw + ":65x65x65:uint8"},
                           dir.path() + "/daemon.log"));
  const std::string png = dir.path() + "/voxel.png";
  const ViewRun r = View("--server " + daemon.address() +
                         " --volume voxel --iso 254 --eps 0 --size 64x64 -o " + png);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(render::ReadPng(png).ok());
}

// The daemon's counters (empty, with a test failure, if it cannot be asked).
::isostream::v1::ServerStats StatsOf(const testing::DaemonProcess& d) {
  net::ClientOptions o;
  o.address = d.address();
  auto c = net::Client::Connect(o);
  EXPECT_TRUE(c.ok()) << c.status();
  if (!c.ok()) return {};
  auto s = (*c)->GetServerStats();
  EXPECT_TRUE(s.ok()) << s.status();
  return s.ok() ? *s : ::isostream::v1::ServerStats();
}

// An orbit around one mesh: from its second view the daemon re-orders its last frame instead of
// extracting (FrameStats.reordered); the pictures are pixel for pixel those of a daemon that
// retains nothing and extracts every view.
TEST(View, ReorderedOrbitDrawsWhatExtractionDraws) {
  testing::ScratchDir dir;
  testing::DaemonProcess retaining, extracting;
  ASSERT_TRUE(retaining.Start({"--no-cache"}, dir.path() + "/retaining.log"));
  ASSERT_TRUE(extracting.Start({"--no-cache", "--retain-mb", "0"}, dir.path() + "/extracting.log"));
  const std::string args =
      " --volume buckyball:65 --iso 0.05,0.15,0.25 --eps 0.004 --eye 2.2,1.6,2.8 --orbit 4"
      " --size 160x120 -o ";
  const ViewRun a = View("--server " + retaining.address() + args + dir.path() + "/r.png");
  ASSERT_EQ(a.code, 0) << a.output;
  const ViewRun b = View("--server " + extracting.address() + args + dir.path() + "/e.png");
  ASSERT_EQ(b.code, 0) << b.output;
  for (int i = 0; i < 4; ++i) {
    SCOPED_TRACE(i);
    const std::string n = "_00" + std::to_string(i) + ".png";
    auto r = render::ReadPng(dir.path() + "/r" + n), e = render::ReadPng(dir.path() + "/e" + n);
    ASSERT_TRUE(r.ok() && e.ok());
    EXPECT_GT(Coverage(*r), 0.05);
    ASSERT_EQ(r->rgba.size(), e->rgba.size());
    size_t differing = 0;
    for (size_t p = 0; p < r->rgba.size(); ++p) differing += r->rgba[p] != e->rgba[p];
    EXPECT_EQ(differing, 0u);
  }
  // The retaining daemon did re-order (views 2 to 4); the other never did.
  EXPECT_EQ(StatsOf(retaining).frames_reordered(), 3);
  EXPECT_EQ(StatsOf(extracting).frames_reordered(), 0);
  EXPECT_EQ(retaining.Stop(), 0);
  EXPECT_EQ(extracting.Stop(), 0);
}

// --window under a virtual X server (xvfb-run, installed by scripts/install-deps.sh): the
// window opens, shows the refined frame, and its screenshot has the surfaces in it.
TEST(View, WindowModeShowsTheFrameUnderXvfb) {
  if (std::system("command -v xvfb-run > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "xvfb-run is not installed (scripts/install-deps.sh installs it)";
  testing::ScratchDir dir;
  testing::DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start({"--no-cache"}, dir.path() + "/daemon.log"));
  const std::string png = dir.path() + "/window.png";
  const std::string cmd = "xvfb-run -a -s '-screen 0 640x480x24' " +
                          ::isostream::testing::ShellQuote(ISOSTREAM_VIEW_PATH) + " --server " +
                          daemon.address() +
                          " --volume buckyball:65 --iso 0.05,0.15,0.25 --eps 0.01 --eye 2.2,1.6,2.8"
                          " --size 240x200 --window --exit-after 1 -o " +
                          png;
  const testing::CommandResult run = testing::RunCommand(cmd);
  ASSERT_EQ(run.code, 0) << run.output;
  auto image = render::ReadPng(png);
  ASSERT_TRUE(image.ok()) << image.status();
  EXPECT_EQ(image->width, 240);
  EXPECT_GT(Coverage(*image), 0.05);
}

// The viewer's window under a virtual X server against `daemon`, with `view_args`; 3 s after
// it starts, xdotool focuses it and does `actions` (it must close itself: --exit-after).
testing::CommandResult WindowWithInput(const testing::DaemonProcess& daemon,
                                       const std::string& view_args, const std::string& actions) {
  // The viewer's path goes in by the environment: quoted inside sh -c '...' it would end the
  // script's own quotes.
  const std::string view = "\"$VIEW\" --server " + daemon.address() + " " + view_args;
  return testing::RunCommand(
      "timeout 60 env VIEW=" + ::isostream::testing::ShellQuote(ISOSTREAM_VIEW_PATH) +
      " xvfb-run -a -s '-screen 0 640x480x24' sh -c '" + view +
      " & pid=$!; sleep 3; xdotool search --sync --name isostream-view"
      " windowfocus --sync " +
      actions + "; wait $pid'");
}

// A frame past the daemon's deadline ends the window with that error: it was taken for the
// daemon closing an idle session, and the window waited for a move that would reopen it (with
// --exit-after, until killed, without a screenshot).
TEST(View, WindowReportsAFramePastTheDaemonsDeadline) {
  if (std::system("command -v xvfb-run > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "xvfb-run is not installed (scripts/install-deps.sh installs it)";
  testing::ScratchDir dir;
  testing::DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start({"--no-cache", "--deadline-ms", "1"}, dir.path() + "/daemon.log"));
  const std::string cmd = "timeout 30 xvfb-run -a -s '-screen 0 640x480x24' " +
                          ::isostream::testing::ShellQuote(ISOSTREAM_VIEW_PATH) + " --server " +
                          daemon.address() +
                          " --volume cayley:129 --iso 0 --eps 0 --size 120x100 --window"
                          " --exit-after 1 -o " +
                          dir.path() + "/never.png";
  const testing::CommandResult run = testing::RunCommand(cmd);
  EXPECT_NE(run.code, 0);
  EXPECT_NE(run.code, 124) << "still waiting when timeout killed it";
  EXPECT_NE(run.output.find("deadline"), std::string::npos) << run.output;
}

// Zooming keeps the volume drawn: near and far follow the eye. They kept the initial
// distance's: zoomed in, the near plane cut the front of the volume away; eight notches out,
// the far plane cut everything (a blank window).
TEST(View, WindowZoomedOutStillShowsTheSurfaces) {
  if (std::system("command -v xvfb-run > /dev/null 2>&1 && command -v xdotool > /dev/null 2>&1") !=
      0)
    GTEST_SKIP() << "xvfb-run or xdotool is not installed (scripts/install-deps.sh installs them)";
  testing::ScratchDir dir;
  testing::DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start({"--no-cache"}, dir.path() + "/daemon.log"));
  const std::string png = dir.path() + "/zoomed.png";
  const testing::CommandResult run = WindowWithInput(
      daemon,
      "--volume cayley:65 --iso 0 --eps 0.01 --size 240x200 --window --exit-after 2 -o " + png,
      "mousemove --window %1 120 100 click --repeat 8 --delay 0 5");  // one burst: one view
  ASSERT_EQ(run.code, 0) << run.output;
  auto image = render::ReadPng(png);
  ASSERT_TRUE(image.ok()) << image.status();
  EXPECT_GT(Coverage(*image), 0.01);  // nothing was drawn
}

// Width over height of the covered pixels' bounding box.
double CoveredAspect(const render::Image& image) {
  const glm::vec3 bg(render::kDefaultBackground);
  int x0 = image.width, x1 = -1, y0 = image.height, y1 = -1;
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) {
      const uint8_t* p = image.pixel(x, y);
      bool covered = false;
      for (int c = 0; c < 3; ++c)
        covered |= std::abs(int(p[c]) - int(std::lround(bg[c] * 255))) > 2;
      if (covered)
        x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
    }
  return x1 < x0 ? 0.0 : double(x1 - x0 + 1) / double(y1 - y0 + 1);
}

// --up is the picture's vertical: an ellipsoid long along z, seen from +x, lies across the
// picture with the default vertical (+y) and stands with --up 0,0,1, in the default view too;
// the window's orbit turns about it, so after a quarter turn it still stands (it turned about y,
// which a medical volume with z up laid on its side; found by a helper's walkthrough).
TEST(View, UpIsThePicturesVertical) {
  testing::ScratchDir dir;
  const std::string raw = dir.path() + "/ellipsoid.raw";
  {
    std::vector<float> f;
    for (int z = 0; z < 32; ++z)
      for (int y = 0; y < 8; ++y)
        for (int x = 0; x < 8; ++x)
          f.push_back(float((x - 3.5) * (x - 3.5) / 9 + (y - 3.5) * (y - 3.5) / 9 +
                            (z - 15.5) * (z - 15.5) / 144));
    std::ofstream(raw, std::ios::binary)
        .write(reinterpret_cast<const char*>(f.data()), std::streamsize(4 * f.size()));
  }
  testing::DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start({"--no-cache", "--volume", "e=raw:" + raw + ":8x8x32:float32"},
                           dir.path() + "/daemon.log"));
  const std::string common = "--server " + daemon.address() +
                             " --volume e --iso 1 --eps 0 "
                             "--size 160x160 -o ";
  auto aspect = [&](const std::string& name, const std::string& flags) {
    const std::string png = dir.path() + "/" + name + ".png";
    const ViewRun r = View(common + png + " " + flags);
    EXPECT_EQ(r.code, 0) << flags << "\n" << r.output;
    auto image = render::ReadPng(png);
    EXPECT_TRUE(image.ok()) << flags << image.status();
    return image.ok() ? CoveredAspect(*image) : 0.0;
  };
  EXPECT_GT(aspect("across", "--eye 60,3.5,15.5"), 2.0);
  EXPECT_LT(aspect("standing", "--eye 60,3.5,15.5 --up 0,0,1"), 0.5);
  EXPECT_LT(aspect("default", "--up 0,0,1"), 0.5);
  EXPECT_EQ(View(common + dir.path() + "/none.png --up 0,0,0").code, 2);
  // From on the vertical itself (the picture's up is then another axis), --orbit still turns
  // about --up: every view looks down the ellipsoid's long axis (it turned about the picture's
  // up, and views 1 and 3 showed it lying across).
  const ViewRun orbit =
      View(common + dir.path() + "/top.png --up 0,0,1 --eye 3.5,3.5,80 --orbit 4");
  ASSERT_EQ(orbit.code, 0) << orbit.output;
  for (int i = 0; i < 4; ++i) {
    auto image = render::ReadPng(dir.path() + "/top_00" + std::to_string(i) + ".png");
    ASSERT_TRUE(image.ok()) << i << image.status();
    EXPECT_NEAR(CoveredAspect(*image), 1.0, 0.25) << "view " << i;
  }
  if (std::system("command -v xvfb-run > /dev/null 2>&1") == 0) {
    const std::string png = dir.path() + "/window.png";
    const ViewRun r = testing::RunCommand(
        "timeout 60 xvfb-run -a -s '-screen 0 640x480x24' " +
        ::isostream::testing::ShellQuote(ISOSTREAM_VIEW_PATH) + " " + common + png +
        " --eye 60,3.5,15.5 --up 0,0,1 --window --orbit 4 --exit-after 2");
    ASSERT_EQ(r.code, 0) << r.output;
    auto image = render::ReadPng(png);
    ASSERT_TRUE(image.ok()) << image.status();
    EXPECT_LT(CoveredAspect(*image), 0.5) << "a quarter turn about z from +x: still standing";
  }
  EXPECT_EQ(daemon.Stop(), 0);
}

// --window --orbit N turns the view after each frame, so a script's --exit-after closes it by
// itself (only one view was ever sent: it waited for moves until killed), past N too (it goes
// on turning). The views after the first are re-ordered from the retained mesh.
TEST(View, WindowOrbitsToItsExitAfterCount) {
  if (std::system("command -v xvfb-run > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "xvfb-run is not installed (scripts/install-deps.sh installs it)";
  testing::ScratchDir dir;
  testing::DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start({"--no-cache"}, dir.path() + "/daemon.log"));
  const std::string png = dir.path() + "/turned.png";
  const testing::CommandResult run = testing::RunCommand(
      "timeout 60 xvfb-run -a -s '-screen 0 640x480x24' " +
      ::isostream::testing::ShellQuote(ISOSTREAM_VIEW_PATH) + " --server " + daemon.address() +
      " --volume buckyball:65 --iso 0.15 --eps 0.01 --size 160x120 --window --orbit 2"
      " --exit-after 3 -o " +
      png);
  ASSERT_EQ(run.code, 0) << run.output;
  EXPECT_TRUE(render::ReadPng(png).ok());
  EXPECT_EQ(StatsOf(daemon).frames_reordered(), 2);
  EXPECT_EQ(daemon.Stop(), 0);
}

// A script's window that asks for more frames than it will ever get (--exit-after 2, no
// --orbit, nobody at the keys) gives up after --timeout-s without a move, saying so: it waited
// for ever (found by a helper's walkthrough), and --timeout-s was read only while a frame was
// on its way.
TEST(View, WindowWaitingForAMoveGivesUpAfterTheTimeout) {
  if (std::system("command -v xvfb-run > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "xvfb-run is not installed (scripts/install-deps.sh installs it)";
  testing::ScratchDir dir;
  testing::DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start({"--no-cache"}, dir.path() + "/daemon.log"));
  const testing::CommandResult run = testing::RunCommand(
      "timeout 60 xvfb-run -a -s '-screen 0 640x480x24' " +
      ::isostream::testing::ShellQuote(ISOSTREAM_VIEW_PATH) + " --server " + daemon.address() +
      " --volume buckyball:33 --iso 0.15 --eps 0.01 --size 160x120 --window --exit-after 2"
      " --timeout-s 2 -o " +
      dir.path() + "/never.png");
  EXPECT_NE(run.code, 0);
  EXPECT_NE(run.code, 124) << "still waiting when timeout killed it";
  EXPECT_NE(run.output.find("1 refined frame(s), then no move for 2 s"), std::string::npos)
      << run.output;
  EXPECT_EQ(daemon.Stop(), 0);
}

// '+' refines a --budget view: the budget doubles (the keys changed only eps, which a budget
// view never sends, so the same mesh came back, re-ordered).
TEST(View, WindowPlusDoublesABudget) {
  if (std::system("command -v xvfb-run > /dev/null 2>&1 && command -v xdotool > /dev/null 2>&1") !=
      0)
    GTEST_SKIP() << "xvfb-run or xdotool is not installed (scripts/install-deps.sh installs them)";
  testing::ScratchDir dir;
  testing::DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start({"--no-cache"}, dir.path() + "/daemon.log"));
  const testing::CommandResult run = WindowWithInput(
      daemon,
      "--volume buckyball:65 --iso 0.15 --budget 3000 --size 160x120 --window --exit-after 2 -o " +
          dir.path() + "/finer.png",
      "key equal");
  ASSERT_EQ(run.code, 0) << run.output;
  const auto stats = StatsOf(daemon);
  EXPECT_GE(stats.frames_sent(), 2);
  EXPECT_EQ(stats.frames_reordered(), 0) << "the second view drew the first one's mesh";
  EXPECT_EQ(daemon.Stop(), 0);
}

// The daemon closes a session that sent no view for --idle-timeout-s; the window keeps its
// picture and opens a new session at the next key press (xdotool presses R after the close).
TEST(View, WindowReopensASessionTheDaemonClosedAsIdle) {
  if (std::system("command -v xvfb-run > /dev/null 2>&1 && command -v xdotool > /dev/null 2>&1") !=
      0)
    GTEST_SKIP() << "xvfb-run or xdotool is not installed (scripts/install-deps.sh installs them)";
  testing::ScratchDir dir;
  testing::DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start({"--no-cache", "--idle-timeout-s", "1"}, dir.path() + "/daemon.log"));
  const std::string png = dir.path() + "/window.png";
  const testing::CommandResult run =
      WindowWithInput(daemon,
                      "--volume buckyball:65 --iso 0.05,0.15,0.25 --eps 0.01 --eye 2.2,1.6,2.8"
                      " --size 240x200 --window --exit-after 2 -o " +
                          png,
                      "key r");
  ASSERT_EQ(run.code, 0) << run.output;
  auto image = render::ReadPng(png);
  ASSERT_TRUE(image.ok()) << image.status();
  EXPECT_GT(Coverage(*image), 0.05);
  std::ifstream log(dir.path() + "/daemon.log");
  const std::string text((std::istreambuf_iterator<char>(log)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("idle"), std::string::npos) << "the session was never closed as idle";
}

// A daemon serving TLS: the viewer connects with --tls-ca; without it, the failure names TLS;
// an empty CA file is refused before connecting (it would have meant plaintext).
TEST(View, ConnectsOverTlsWithItsCa) {
  testing::ScratchDir dir;
  std::string key, cert;
  if (!testing::MakeTestCertificate(dir.path(), &key, &cert))
    GTEST_SKIP() << "openssl cannot make a test certificate";
  testing::DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start({"--tls-cert", cert, "--tls-key", key, "--no-cache"},
                           dir.path() + "/daemon.log"));
  const std::string png = dir.path() + "/tls.png";
  const std::string common = "--server " + daemon.address() +
                             " --volume sphere:33 --iso 0.5 --eps 0.01 --size 64x64 -o " + png;
  const ViewRun secure = View(common + " --tls-ca " + cert);
  ASSERT_EQ(secure.code, 0) << secure.output;
  auto image = render::ReadPng(png);
  ASSERT_TRUE(image.ok()) << image.status();
  EXPECT_GT(Coverage(*image), 0.05);

  const ViewRun plain = View(common + " --timeout-s 5");
  EXPECT_NE(plain.code, 0);
  EXPECT_NE(plain.output.find("--tls-ca"), std::string::npos) << plain.output;
  // The other mismatch, TLS to a plaintext daemon: explained once, without gRPC's own line
  // ("E1127 ... Handshake failed ..."), which said the same.
  testing::DaemonProcess plaintext;
  ASSERT_TRUE(plaintext.Start({"--no-cache"}, dir.path() + "/plaintext.log"));
  const ViewRun tls_to_plain =
      View("--server " + plaintext.address() + " --volume sphere:33 --iso 0.5 --size 64x64 -o " +
           png + " --timeout-s 5 --tls-ca " + cert);
  EXPECT_EQ(tls_to_plain.code, 1);
  EXPECT_NE(tls_to_plain.output.find("connected with TLS"), std::string::npos)
      << tls_to_plain.output;
  EXPECT_EQ(tls_to_plain.output.find("ssl_transport_security"), std::string::npos)
      << tls_to_plain.output;
  EXPECT_EQ(plaintext.Stop(), 0);

  const std::string empty = dir.path() + "/empty.pem";
  std::ofstream(empty).close();
  const ViewRun no_ca = View(common + " --tls-ca " + empty);
  EXPECT_NE(no_ca.code, 0);
  EXPECT_NE(no_ca.output.find("holds no certificates"), std::string::npos) << no_ca.output;
  const std::string text = dir.path() + "/not-pem.txt";
  std::ofstream(text) << "root:x:0:0:root:/root:/bin/bash\n";
  const ViewRun not_pem = View(common + " --tls-ca " + text);
  EXPECT_EQ(not_pem.code, 2) << not_pem.output;
  EXPECT_NE(not_pem.output.find("'" + text + "' holds no certificates (PEM)"), std::string::npos)
      << not_pem.output;
  EXPECT_EQ(daemon.Stop(), 0);
}

// Servers that break the contract: the viewer ends with a clear error instead of crashing on a
// volume info without 3 dims, waiting forever on a stalled session, or growing an endless frame
// until memory runs out.
TEST(View, MisbehavingServersGiveClearErrors) {
  testing::ScratchDir dir;
  const std::string png = dir.path() + "/never.png";
  const std::string common = " --volume sphere:33 --iso 0.5 --eps 0.01 --size 64x64 -o " + png;
  {
    testing::MisbehavingServer server(testing::Misbehaviour::kTwoDims);
    ASSERT_TRUE(server.ok());
    const ViewRun r = View("--server " + server.address() + common);
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.output.find("2 dims, not 3"), std::string::npos) << r.output;
  }
  {
    testing::MisbehavingServer server(testing::Misbehaviour::kStall);
    ASSERT_TRUE(server.ok());
    const ViewRun r = View("--server " + server.address() + common + " --timeout-s 1");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.output.find("no data from the server for 1 s"), std::string::npos) << r.output;
  }
  {
    testing::MisbehavingServer server(testing::Misbehaviour::kEndlessFrame);
    ASSERT_TRUE(server.ok());
    const ViewRun r = View("--server " + server.address() + common +
                           " --max-frame-triangles 1000 --timeout-s 30");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.output.find("grows past 1000 triangles"), std::string::npos) << r.output;
    // The viewer stopped the stream; the server did not run out of chunks to send.
    EXPECT_LT(server.chunks_sent(), testing::MisbehavingServer::kMaxChunks);
  }
  {
    // --timeout-s bounds the first call too: it waited 30 s (gRPC's call default) whatever
    // was asked. The bound below is loose; what matters is that 1 s is honoured, not 30.
    testing::MisbehavingServer server(testing::Misbehaviour::kSilentInfo);
    ASSERT_TRUE(server.ok());
    const auto t0 = std::chrono::steady_clock::now();
    const ViewRun r = View("--server " + server.address() + common + " --timeout-s 1");
    EXPECT_EQ(r.code, 1);
    // Each in its own words: the viewer's frames are bounded by silence, fetch's as a whole
    // (the viewer said "a whole frame included", which its README contradicts).
    EXPECT_NE(r.output.find("did not complete within 1 s (--timeout-s bounds each wait for the "
                            "server)"),
              std::string::npos)
        << r.output;
    const ViewRun f = testing::RunCommand(::isostream::testing::ShellQuote(ISOSTREAM_CLI_PATH) +
                                          " fetch --server " + server.address() +
                                          " --volume sphere:33 --iso 0.5 --eps 0.01 "
                                          "--timeout-s 1 -o " +
                                          dir.path() + "/never.ply");
    EXPECT_EQ(f.code, 1);
    EXPECT_NE(f.output.find("did not complete within 1 s (--timeout-s bounds each call, a whole "
                            "frame included)"),
              std::string::npos)
        << f.output;
    EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(20));
  }
  EXPECT_FALSE(std::filesystem::exists(png));
  EXPECT_FALSE(std::filesystem::exists(dir.path() + "/never.ply"));
}

// Without --iso the viewer draws at 20, 40 and 60% of the value range: computed in float, a
// range near +-FLT_MAX overflowed to "isovalue is not a finite number", and a constant volume
// sent one value three times ("given twice"), though the user gave no isovalues at all, as did
// values four float steps apart (1e6 and 1e6 + 0.25: float64 data far from 0, rounded).
TEST(View, DefaultIsovaluesForExtremeAndConstantVolumes) {
  testing::ScratchDir dir;
  auto raw = [&](const std::string& name, float a, float b) {
    const std::string path = dir.path() + "/" + name + ".raw";
    std::ofstream out(path, std::ios::binary);
    for (int i = 0; i < 27; ++i) {
      const float v = i % 2 ? a : b;
      out.write(reinterpret_cast<const char*>(&v), sizeof v);
    }
    return name + "=raw:" + path + ":3x3x3:float32";
  };
  testing::DaemonProcess daemon;
  ASSERT_TRUE(
      daemon.Start({"--no-cache", "--volume", raw("extreme", -3e38f, 3e38f), "--volume",
                    raw("constant", 0.5f, 0.5f), "--volume", raw("narrow", 1e6f, 1e6f + 0.25f)},
                   dir.path() + "/isostreamd.log"));
  for (const std::string name : {"extreme", "constant", "narrow"}) {
    SCOPED_TRACE(name);
    const std::string png = dir.path() + "/" + name + ".png";
    const ViewRun r =
        View("--server " + daemon.address() + " --volume " + name + " --size 64x64 -o " + png);
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_TRUE(std::filesystem::exists(png));
    if (name == "constant") {
      EXPECT_NE(r.output.find("holds the one value 0.5: it has no isosurface"), std::string::npos)
          << r.output;
      EXPECT_NE(r.output.find(": 0 triangles"), std::string::npos) << r.output;
    } else {
      EXPECT_EQ(r.output.find(": 0 triangles"), std::string::npos) << r.output;
    }
    // Values a few float steps apart are said, by the viewer and in the daemon's log.
    const bool narrow = name == "narrow";
    EXPECT_EQ(r.output.find("are 4 float steps apart") != std::string::npos, narrow) << r.output;
  }
  EXPECT_EQ(daemon.Stop(), 0);
  std::ifstream log(dir.path() + "/isostreamd.log");
  const std::string logged((std::istreambuf_iterator<char>(log)), std::istreambuf_iterator<char>());
  EXPECT_NE(logged.find("volume narrow's values [1e+06, 1000000.25] are 4 float steps apart"),
            std::string::npos)
      << logged;
  EXPECT_EQ(logged.find("volume extreme's values"), std::string::npos) << logged;
}

// Once every frame asked for is written, how the stream ends does not matter: a daemon stopping
// right after the frame made the viewer exit 1 with "cannot reach isostreamd".
TEST(View, AFrameWrittenIsASuccessHoweverTheStreamEnds) {
  testing::ScratchDir dir;
  testing::MisbehavingServer server(testing::Misbehaviour::kFrameThenGone);
  ASSERT_TRUE(server.ok());
  const std::string png = dir.path() + "/frame.png";
  const ViewRun r = View("--server " + server.address() +
                         " --volume sphere:33 --iso 0.5 --eps 0.01 --size 64x64 -o " + png);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("100 triangles"), std::string::npos) << r.output;
  EXPECT_TRUE(std::filesystem::exists(png));
}

// A server that never ends the call after a whole frame holds neither client: the viewer
// writes its PNG and exits within --timeout-s (it drained the stream for ever), and fetch
// writes the frame (it failed with its own timeout after the frame had arrived).
TEST(View, AServerThatNeverEndsTheCallAfterTheFrameHoldsNoClient) {
  testing::ScratchDir dir;
  testing::MisbehavingServer server(testing::Misbehaviour::kFrameThenSilent);
  ASSERT_TRUE(server.ok());
  const auto t0 = std::chrono::steady_clock::now();
  const ViewRun r = View("--server " + server.address() +
                         " --volume sphere:33 --iso 0.5 --eps 0.01 --size 64x64 --timeout-s 2 -o " +
                         dir.path() + "/frame.png");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(std::filesystem::exists(dir.path() + "/frame.png"));
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(20));
  const testing::CommandResult fetched = testing::RunCommand(
      ::isostream::testing::ShellQuote(ISOSTREAM_CLI_PATH) + " fetch --server " + server.address() +
      " --volume sphere:33 --iso 0.5 --eps 0.01 --eye 2,2,2 --codec raw --timeout-s 2 -o " +
      dir.path() + "/frame.ply");
  EXPECT_EQ(fetched.code, 0) << fetched.output;
  EXPECT_NE(fetched.output.find("100 triangles"), std::string::npos) << fetched.output;
}

// --timeout-s counts only this view's chunks as progress: a server streaming other frames'
// without end kept the viewer waiting as long as it streamed.
TEST(View, OtherFramesChunksDoNotKeepTheTimeoutQuiet) {
  testing::ScratchDir dir;
  testing::MisbehavingServer server(testing::Misbehaviour::kOtherFrames);
  ASSERT_TRUE(server.ok());
  const auto t0 = std::chrono::steady_clock::now();
  const ViewRun r = View("timeout 60 " + ::isostream::testing::ShellQuote(ISOSTREAM_VIEW_PATH) +
                             " --server " + server.address() +
                             " --volume sphere:33 --iso 0.5 --eps 0.01 --size 64x64 --timeout-s 2"
                             " -o " +
                             dir.path() + "/never.png",
                         false, true);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("no data from the server for 2 s"), std::string::npos) << r.output;
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(20));
  EXPECT_GT(server.chunks_sent(), 10);  // it did stream meanwhile
}

// Arguments it cannot honour are refused before any frame is asked for: an image it would not
// write as named, a window option without a window, an eye too far away to draw from.
TEST(View, ArgumentsItCannotHonourAreRefusedBeforeAnyFrame) {
  testing::ScratchDir dir;
  testing::DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start({"--no-cache"}, dir.path() + "/isostreamd.log"));
  const std::string common = "--server " + daemon.address() +
                             " --volume sphere:33 --iso 0.5 --eps 0.01 --size 64x64 -o " +
                             dir.path();
  const std::pair<std::string, std::string> refused[] = {
      {"/frame.jpg", "give a .png path"},
      {"/frame.png --eps ''", "a number is needed"},
      {"/frame.png --iso ''", "--iso: a number is needed"},  // not the default isovalues
      {"/frame.png --eye ''", "--eye: a number is needed"},  // not the default view
      {"/frame.png --exit-after 2", "--window"},
      {"/frame.png --eye 1e30,0,0", "too far"}};
  for (const auto& [args, reason] : refused) {
    const ViewRun r = View(common + args);
    EXPECT_EQ(r.code, 2) << args;
    EXPECT_NE(r.output.find(reason), std::string::npos) << args << "\n" << r.output;
  }
  EXPECT_FALSE(std::filesystem::exists(dir.path() + "/frame.jpg"));
  EXPECT_FALSE(std::filesystem::exists(dir.path() + "/frame.png"));
  EXPECT_EQ(StatsOf(daemon).frames_started(), 0);
  EXPECT_EQ(daemon.Stop(), 0);
}

TEST(View, CorruptChunkBytesAreAnErrorNotACrash) {
  net::FrameAssembler assembler;
  ::isostream::v1::FrameChunk chunk;
  chunk.set_frame_id(1);
  chunk.set_chunk_index(0);
  chunk.set_last(true);
  chunk.set_chunk_count(1);
  chunk.set_triangle_count(100);
  chunk.set_data(std::string("ISC1 this is not a chunk at all \x01\x02\x03", 36));
  const absl::Status status = assembler.Add(chunk);
  // The server's fault: DATA_LOSS (exit 1), not INVALID_ARGUMENT (the viewer's usage-error 2).
  EXPECT_EQ(status.code(), absl::StatusCode::kDataLoss) << status;
  EXPECT_NE(status.message().find("from the server is malformed"), std::string::npos) << status;
  EXPECT_FALSE(assembler.complete());
}

}  // namespace
}  // namespace isostream
