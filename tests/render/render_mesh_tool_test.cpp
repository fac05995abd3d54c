// isostream-render-mesh end to end: the real binary draws a real PLY into real PNGs, and its
// bad inputs (flags, files) end in a clear message and a non-zero exit status, never a crash.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "client/render/image.h"
#include "shared/file_io.h"
#include "shared/ply_io.h"
#include "tests/common/run_command.h"
#include "tests/render/render_test_support.h"
#include "tests/render/test_spheres.h"

namespace isostream::render {
namespace {

::isostream::testing::CommandResult RenderMesh(const std::string& args) {
  return ::isostream::testing::RunCommand(std::string(ISOSTREAM_RENDER_MESH_PATH) + " " + args);
}

// Per test: ctest runs the tests of this file in parallel processes.
std::string Temp(const std::string& name) {
  return ::testing::TempDir() + "render_mesh_tool_" +
         ::testing::UnitTest::GetInstance()->current_test_info()->name() + "_" + name;
}

class RenderMeshTool : public ::testing::Test {
 protected:
  void SetUp() override {
    ply_ = Temp("spheres.ply");
    ASSERT_TRUE(WritePly(testing::MakeSpheres(testing::ThreeNestedSpheres(), 3), ply_).ok());
  }
  std::string ply_;
};

TEST_F(RenderMeshTool, DrawsTheMeshAtTheGivenSizeAndBackground) {
  const std::string png = Temp("default.png");
  const auto r = RenderMesh(ply_ + " -o " + png + " --size 120x90");
  ASSERT_EQ(r.code, 0) << r.output;
  auto image = ReadPng(png);
  ASSERT_TRUE(image.ok()) << image.status();
  EXPECT_EQ(image->width, 120);
  EXPECT_EQ(image->height, 90);
  const glm::vec3 white(1.0f);
  // Framed to the bounding sphere: the spheres fill a good part of the picture, not all of it.
  EXPECT_GT(testing::Coverage(*image, white), 0.2);
  EXPECT_LT(testing::Coverage(*image, white), 0.9);

  // A black background, seen orthographically: the corners keep it, the centre does not.
  const std::string black_png = Temp("black.png");
  const auto b =
      RenderMesh(ply_ + " -o " + black_png + " --size 64x64 --view-dir 0,0,-1 --background 0,0,0");
  ASSERT_EQ(b.code, 0) << b.output;
  auto black = ReadPng(black_png);
  ASSERT_TRUE(black.ok()) << black.status();
  for (const auto& [x, y] : std::vector<std::pair<int, int>>{{0, 0}, {63, 0}, {0, 63}, {63, 63}})
    for (int c = 0; c < 3; ++c) EXPECT_LE(black->pixel(x, y)[c], 2) << x << "," << y;
  const uint8_t* centre = black->pixel(32, 32);
  EXPECT_GT(int(centre[0]) + centre[1] + centre[2], 30);
}

TEST_F(RenderMeshTool, OrbitWritesNumberedImagesThatDiffer) {
  const std::string base = Temp("orbit.png");
  const auto r = RenderMesh(ply_ + " -o " + base + " --size 48x48 --orbit 2 --eye 0,0,4");
  ASSERT_EQ(r.code, 0) << r.output;
  auto first = ReadPng(Temp("orbit_000.png"));
  auto second = ReadPng(Temp("orbit_001.png"));
  ASSERT_TRUE(first.ok()) << first.status();
  ASSERT_TRUE(second.ok()) << second.status();
  EXPECT_EQ(first->width, 48);
  EXPECT_EQ(second->width, 48);
  // Half a turn apart, the off-centre inner spheres are seen from the other side.
  EXPECT_NE(first->rgba, second->rgba);
}

TEST_F(RenderMeshTool, BadInputsExitNonZeroWithAClearMessage) {
  const std::string png = Temp("never.png");
  std::filesystem::remove(png);
  const std::string corrupt = Temp("corrupt.ply");
  ASSERT_TRUE(WriteFileBytes(corrupt,
                             "ply\nformat binary_little_endian 1.0\nelement vertex "
                             "99999999999\nend_header\n")
                  .ok());
  struct Case {
    std::string args;
    std::string says;
    bool flag_parser = false;  // refused by CLI11 itself: its own wording and exit code
  };
  const std::vector<Case> cases = {
      {ply_ + " -o " + png + " --view-dir 0,0,0", "--view-dir is zero"},
      {ply_ + " -o " + png + " --view-dir 1,2", "--view-dir"},
      {ply_ + " -o " + png + " --background 0,0,2", "0..1"},
      {ply_ + " -o " + png + " --background -0.5,0,0", "0..1"},
      {ply_ + " -o " + png + " --size 0x10", "--size"},
      {ply_ + " -o " + png + " --size 4294967297x1", "--size"},
      {ply_ + " -o " + png + " --eye 0,0,0 --target 0,0,0", "degenerate"},
      {ply_ + " -o " + png + " --eye 1,1,1 --view-dir 0,0,1", "excludes", true},
      {ply_ + " -o " + png + " --fov 180", "--fov", true},
      {Temp("no_such.ply") + " -o " + png, "no_such.ply"},
      {corrupt + " -o " + png, "declares 99999999999 items"},
      {"/dev/zero -o " + png, "regular file"},
      {ply_ + " -o /no/such/dir/x.png", "/no/such/dir"},
      // Before any rendering: a name that is not .png, and an orbit frame it cannot write.
      {ply_ + " -o " + Temp("x.jpg"), "give a .png path"},
      {ply_ + " -o " + Temp("orbit.png") + " --orbit 3", "orbit_001.png is a directory"},
  };
  std::filesystem::create_directory(Temp("orbit_001.png"));
  for (const Case& c : cases) {
    const auto r = RenderMesh(c.args);
    EXPECT_GT(r.code, 0) << c.args << "\n" << r.output;  // an exit status, not a signal
    EXPECT_NE(r.output.find(c.says), std::string::npos) << c.args << "\n" << r.output;
    if (!c.flag_parser) {
      EXPECT_EQ(r.code, 1) << c.args;
      EXPECT_NE(r.output.find("isostream-render-mesh: "), std::string::npos) << r.output;
    }
  }
  EXPECT_FALSE(std::filesystem::exists(png));
  EXPECT_FALSE(std::filesystem::exists(Temp("x.jpg")));
  EXPECT_FALSE(std::filesystem::exists(Temp("orbit_000.png")));
}

}  // namespace
}  // namespace isostream::render
