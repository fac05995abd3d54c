// isostream-render-mesh end to end: the real binary draws a real PLY into real PNGs, and its
// bad inputs (flags, files) end in a clear message and a non-zero exit status, never a crash.
#include <gtest/gtest.h>

#include <cstdio>
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
  return ::isostream::testing::RunCommand(
      ::isostream::testing::ShellQuote(ISOSTREAM_RENDER_MESH_PATH) + " " + args);
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

// A mesh far from the origin and huge is drawn as its copy near the origin at unit scale, from
// the same eye: framing is found in double and the mesh drawn relative to its centre. In float
// the squared lengths of a mesh 1e20 across overflowed, and it was refused as degenerate.
TEST_F(RenderMeshTool, AMeshFarOutAndHugeLooksLikeItsCopyAtUnitScale) {
  const OrderedMesh unit = testing::MakeSpheres(testing::ThreeNestedSpheres(), 3);
  struct Move {
    double scale, offset;
  };
  const auto moved_ply = [&](const Move& m, const std::string& name) {
    OrderedMesh copy = unit;
    for (float& c : copy.positions) c = float(double(c) * m.scale + m.offset);
    const std::string path = Temp(name);
    EXPECT_TRUE(WritePly(copy, path).ok());
    return path;
  };
  const auto eye_flag = [](const Move& m) {
    char text[128];
    std::snprintf(text, sizeof(text), " --eye %.17g,%.17g,%.17g", 0.5 * m.scale + m.offset,
                  1.0 * m.scale + m.offset, 4.0 * m.scale + m.offset);
    return std::string(text);
  };
  const auto render = [&](const std::string& ply, const std::string& flags,
                          const std::string& name) -> Image {
    const std::string png = Temp(name);
    const auto r = RenderMesh(ply + " -o " + png + " --size 96x72" + flags);
    EXPECT_EQ(r.code, 0) << flags << "\n" << r.output;
    absl::StatusOr<Image> image = ReadPng(png);
    EXPECT_TRUE(image.ok()) << name << ": " << image.status();
    return image.ok() ? *image : Image{};
  };
  const Move moves[] = {{1e18, 1e20}, {1e20, 0.0}, {1e20, 1e20}};
  for (const std::string view : {"", " --view-dir 1,-2,-3", "eye"}) {
    const Image expected = render(ply_, view == "eye" ? eye_flag({1.0, 0.0}) : view, "unit.png");
    ASSERT_EQ(expected.width, 96) << view;
    EXPECT_GT(testing::Coverage(expected, glm::vec3(1.0f)), 0.2) << view;
    for (const Move& m : moves) {
      const std::string name = "moved_" + std::to_string(&m - moves);
      const Image image =
          render(moved_ply(m, name + ".ply"), view == "eye" ? eye_flag(m) : view, name + ".png");
      // Positions differ from the unit copy's by a float rounding at most.
      const double difference = MeanAbsoluteDifference(image, expected);
      EXPECT_GE(difference, 0.0) << "sizes differ";
      EXPECT_LT(difference, 1e-4) << view << ", scale " << m.scale << ", offset " << m.offset;
    }
  }
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
      {ply_ + " -o " + png + " --eye 0,0,0 --target 0,0,0", "--eye equals --target"},
      // Far eyes were blamed on --eye equal to --target too.
      {ply_ + " -o " + png + " --eye 1e300,0,0", "the eye is too far from the mesh"},
      {ply_ + " -o " + png + " --eye 1e30,0,0", "the eye is too far from the mesh"},
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
