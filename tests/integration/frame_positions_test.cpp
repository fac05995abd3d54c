// Positions of compressed frames through a real isostreamd, for volumes placed at the extremes
// the loaders accept: the unit tests (quantization_test.cpp) check QuantizationFor, this the
// path from a file to a client's decoded frame.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cfloat>
#include <cmath>
#include <string>
#include <vector>

#include "tests/integration/daemon_fixture.h"
#include "tests/integration/nifti_writer.h"

namespace isostream::testing {
namespace {

// Draco frames (the default codec) promise positions within VolumeInfo.position_error of the
// exact ones, "fine enough for 1/64 voxel", for any volume the loaders accept (spacing in
// [1e-30, 1e30] per axis). Found by adversarial testing: a volume with spacing 1e-25 got
// position_error 1.5e-12 (10^13 voxels) and every vertex of its Draco frame decoded to one
// point, (1.1e-13, 1.1e-13, 1.1e-13), while its data lie near (5e-21, 0, 0); one with spacing
// (1e20, 1e-20, 1) had every vertex's y and z at -4.4e13. RAW frames of the same views were
// right (QuantizationFor: an absolute margin of 1e-6 around the box, at most 24 bits).
TEST(FramePositions, DracoFramesKeepTheirBoundForTinyAndAnisotropicSpacing) {
  ScratchDir dir;
  struct Entry {
    const char* name;
    std::array<float, 3> spacing, origin;
  };
  const Entry entries[] = {{"tiny", {1e-25f, 1e-25f, 1e-25f}, {5e-21f, 0, 0}},
                           {"aniso", {1e20f, 1e-20f, 1.0f}, {0, 0, 0}}};
  std::vector<std::string> args = {"--no-cache", "--threads", "2"};
  for (const Entry& e : entries) {
    const std::string path = dir.path() + "/" + e.name + ".nii";
    WriteNifti(path, {20, 24, 28}, e.spacing, e.origin);
    args.push_back("--volume");
    args.push_back(std::string(e.name) + "=" + path);
  }
  DaemonProcess daemon;
  ASSERT_TRUE(daemon.Start(args, dir.path() + "/isostreamd.log"));
  net::ClientOptions o;
  o.address = daemon.address();
  auto c = net::Client::Connect(o);
  ASSERT_TRUE(c.ok());
  for (const Entry& e : entries) {
    SCOPED_TRACE(e.name);
    auto info = (*c)->GetVolumeInfo(e.name, 1);
    ASSERT_TRUE(info.ok()) << info.status();
    const double spacing[3] = {info->spacing().x(), info->spacing().y(), info->spacing().z()};
    const double origin[3] = {info->origin().x(), info->origin().y(), info->origin().z()};
    pb::ViewRequest view = MakeView(e.name, 1, 0.0, glm::dvec3(0, 0, 0));
    view.clear_surfaces();
    view.add_surfaces()->set_isovalue(1.0f);
    // An eye well outside the box on every axis, in the volume's own units.
    view.mutable_camera()->mutable_eye()->set_x(origin[0] + 60 * spacing[0]);
    view.mutable_camera()->mutable_eye()->set_y(origin[1] + 50 * spacing[1]);
    view.mutable_camera()->mutable_eye()->set_z(origin[2] + 70 * spacing[2]);
    view.set_codec(pb::RAW);
    auto raw = (*c)->Fetch(view);
    ASSERT_TRUE(raw.ok()) << raw.status();
    view.set_codec(pb::DRACO);
    auto draco = (*c)->Fetch(view);
    ASSERT_TRUE(draco.ok()) << draco.status();
    const OrderedMesh &a = raw->mesh, &b = draco->mesh;
    ASSERT_GT(a.triangle_count(), 0u);
    ASSERT_EQ(a.triangle_count(), b.triangle_count());
    // Per axis: within 1/64 of that axis's voxel of the exact positions, give or take the
    // single-precision rounding of the coordinates themselves.
    for (int k = 0; k < 3; ++k) {
      double worst = 0, allowed = 0;
      for (size_t t = 0; t < 3 * a.triangle_count(); ++t) {
        const float exact = a.positions[3 * a.triangles[t] + k];
        const float got = b.positions[3 * b.triangles[t] + k];
        worst = std::max(worst, std::abs(double(exact) - double(got)));
        allowed = std::max(allowed, spacing[k] / 64 * 1.01 + 4 * FLT_EPSILON * std::abs(exact));
      }
      EXPECT_LE(worst, allowed) << "axis " << k << " (spacing " << spacing[k] << ")";
      EXPECT_LE(worst, info->position_error()) << "axis " << k << ": the bound the daemon reports";
    }
  }
  EXPECT_EQ(daemon.Stop(), 0);
}

}  // namespace
}  // namespace isostream::testing
