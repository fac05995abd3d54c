// isostream-view's default view of volumes at the extremes of the sizes the loaders accept.
#include <gtest/gtest.h>

#include <cstdio>
#include <string>
#include <vector>

#include "client/render/image.h"
#include "client/render/mesh_renderer.h"
#include "daemon_process.h"
#include "nifti_writer.h"
#include "tests/common/image_coverage.h"
#include "tests/common/run_command.h"

namespace isostream {
namespace {

// The loaders accept any spacing in [1e-30, 1e30] and a world box within +-1e30, and the daemon
// serves such volumes. The viewer's default view must draw them too. Found by adversarial
// testing: spacing 1e-16 drew a blank picture and exited 0 (the camera framed a sphere of at
// least 1e-6); spacing 1e19 exited 2 with the daemon's "view is not finite" for a command line
// that gave no view (float squares of the box's lengths overflowed). The camera's lengths and
// matrices are now taken in double, and the shader's vector to the eye is in the view's units.
TEST(ViewScale, DefaultViewDrawsVolumesOfAnyAcceptedSize) {
  testing::ScratchDir dir;
  const float scales[] = {1e-28f, 1e-16f, 1e19f, 1e28f};
  constexpr int kScales = sizeof(scales) / sizeof(scales[0]);
  std::vector<std::string> args = {"--no-cache"};
  for (int i = 0; i < kScales; ++i) {
    const std::string path = dir.path() + "/v" + std::to_string(i) + ".nii";
    testing::WriteNifti(path, {20, 24, 28}, {scales[i], scales[i], scales[i]}, {0, 0, 0});
    args.push_back("--volume");
    args.push_back("v" + std::to_string(i) + "=" + path);
  }
  testing::DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start(args, dir.path() + "/daemon.log"));
  for (int i = 0; i < kScales; ++i) {
    char what[32];
    std::snprintf(what, sizeof what, "spacing %g", double(scales[i]));
    SCOPED_TRACE(what);
    for (const char* codec : {"raw", "draco"}) {
      const std::string png = dir.path() + "/v" + std::to_string(i) + codec + ".png";
      const testing::CommandResult r =
          testing::RunCommand(testing::ShellQuote(ISOSTREAM_VIEW_PATH) + " --server " +
                              daemon.address() + " --volume v" + std::to_string(i) +
                              " --iso 1 --eps 0 --codec " + codec + " --size 100x100 -o " + png);
      ASSERT_EQ(r.code, 0) << codec << ": " << r.output;
      auto image = render::ReadPng(png);
      ASSERT_TRUE(image.ok()) << image.status();
      EXPECT_GT(testing::Coverage(*image, glm::vec3(render::kDefaultBackground)), 0.05)
          << codec << ": the sphere should fill part of the picture; " << r.output;
    }
  }
  EXPECT_EQ(daemon.Stop(), 0);
}

}  // namespace
}  // namespace isostream
