// The `isostream` command line end to end: a real process, real files, exit codes and messages.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "server/extract/extractor.h"
#include "server/hierarchy/prepared_volume.h"
#include "shared/file_io.h"
#include "shared/glb_writer.h"
#include "shared/ply_io.h"
#include "tests/common/run_command.h"
#include "volume_files.h"

namespace isostream {
namespace {

using CliRun = testing::CommandResult;

CliRun Cli(const std::string& args) {
  return testing::RunCommand(::isostream::testing::ShellQuote(ISOSTREAM_CLI) + " " + args);
}

std::string TempPath(const std::string& name) {
  return (std::filesystem::path(::testing::TempDir()) / name).string();
}

TEST(Cli, ExtractWritesThePlyOfTheDirectExtractionInOrder) {
  const std::string out = TempPath("cli-bucky.ply");
  const CliRun r =
      Cli("extract --volume buckyball:33 --iso 0.05,0.15,0.25 --eps 0.002 --eye 2,1.5,2.5 "
          "--no-cache -o " +
          out + " --stats");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("tets visited"), std::string::npos) << r.output;
  auto ply = ReadPly(out);
  ASSERT_TRUE(ply.ok()) << ply.status();
  auto prepared = PrepareVolume("buckyball:33", {}, {}, {});
  ASSERT_TRUE(prepared.ok());
  ExtractRequest req;
  req.isovalues = {0.05f, 0.15f, 0.25f};
  req.eps = 0.002;
  req.view.eye = {2, 1.5, 2.5};
  auto direct = Extract(*prepared->hierarchy, prepared->grid_to_world, req);
  ASSERT_TRUE(direct.ok());
  EXPECT_GT(direct->mesh.triangle_count(), 1000u);
  EXPECT_EQ(ply->triangles, direct->mesh.triangles);
  EXPECT_EQ(ply->surface, direct->mesh.surface);
  EXPECT_EQ(ply->positions, direct->mesh.positions);
}

// A uint8 NIfTI file of the test samples (volume_files::Samples) in the test's scratch folder.
std::string WriteUint8Nifti(const std::string& name, const std::array<int, 3>& dims,
                            const std::array<float, 3>& pixdim, unsigned char xyzt_units = 0) {
  volume_files::NiftiFile nf;
  nf.dims = dims;
  nf.datatype = 2;
  nf.bitpix = 8;
  nf.pixdim = pixdim;
  nf.xyzt_units = xyzt_units;
  const std::string path = TempPath(name);
  volume_files::WriteBytes(
      path, volume_files::Concat(
                nf.Header(), volume_files::Samples(volume_files::Type::kUint8, nf.dims, false)));
  return path;
}

// A .glb keeps positions as finely as the daemon's frames, 1/64 of the smallest voxel side: the
// writer's default, 14 bits over the mesh's bounding cube, put two corners of 1.2% of
// cayley:257's eps 0 triangles in one place (found by a reviewing helper), and is coarser still
// where one axis is long in world units. Here a NIfTI volume with 64-unit slices.
TEST(Cli, GlbPositionsAreWithinAVoxelSixtyFourth) {
  const std::string nii = WriteUint8Nifti("cli-slices.nii", {33, 33, 17}, {1, 1, 64});
  const std::string glb = TempPath("cli-slices.glb"), ply = TempPath("cli-slices.ply");
  const std::string args = "extract --volume " + nii + " --iso 127.5 --eps 0 --no-cache -o ";
  ASSERT_EQ(Cli(args + glb).code, 0);
  ASSERT_EQ(Cli(args + ply).code, 0);
  auto bytes = ReadFileBytes(glb);
  ASSERT_TRUE(bytes.ok()) << bytes.status();
  auto decoded = ParseGlb(*bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  auto exact = ReadPly(ply);
  ASSERT_TRUE(exact.ok()) << exact.status();
  ASSERT_GT(exact->triangles.size(), 0u);
  ASSERT_EQ(decoded->triangles.size(), exact->triangles.size());  // same order, own numbering
  float worst = 0;
  for (size_t i = 0; i < exact->triangles.size(); ++i)
    for (int a = 0; a < 3; ++a)
      worst = std::max(worst, std::abs(decoded->positions[3 * size_t(decoded->triangles[i]) + a] -
                                       exact->positions[3 * size_t(exact->triangles[i]) + a]));
  EXPECT_LE(worst, 1.01f / 64);  // the smallest voxel side is 1
  // Surfaces carry the viewer's colours (COLOR_0), so a viewer elsewhere tells them apart: the
  // file had one white material for all.
  const size_t json_length = size_t(uint8_t((*bytes)[12])) | size_t(uint8_t((*bytes)[13])) << 8 |
                             size_t(uint8_t((*bytes)[14])) << 16;
  EXPECT_NE(bytes->substr(20, json_length).find("\"COLOR_0\""), std::string::npos);
}

// A volume in millimetres (NIfTI's xyzt_units) gives a .glb whose node scales to glTF's meters,
// its vertices as in the PLY; `info` names the unit.
TEST(Cli, GlbOfAVolumeInMillimetresIsInMeters) {
  const std::string nii =
      WriteUint8Nifti("cli-mm.nii", {17, 17, 17}, {0.5, 0.5, 0.5}, 2 | 8);  // mm, s
  const CliRun info = Cli("info --volume " + nii + " --no-cache");
  ASSERT_EQ(info.code, 0) << info.output;
  EXPECT_NE(info.output.find("unit          mm (0.001 m)\n"), std::string::npos) << info.output;
  const std::string glb = TempPath("cli-mm.glb");
  ASSERT_EQ(Cli("extract --volume " + nii + " --iso 127.5 --eps 0 --no-cache -o " + glb).code, 0);
  auto bytes = ReadFileBytes(glb);
  ASSERT_TRUE(bytes.ok()) << bytes.status();
  auto chunks = ParseGlbChunks(*bytes);
  ASSERT_TRUE(chunks.ok()) << chunks.status();
  const auto doc = nlohmann::json::parse(chunks->json);
  EXPECT_EQ(doc["nodes"][0]["scale"], nlohmann::json::array({1e-3, 1e-3, 1e-3})) << doc.dump();
  auto decoded = ParseGlb(*bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  float widest = 0;  // half-voxel samples of 17 points: the data span 8 mm
  for (size_t i = 0; i < decoded->positions.size(); ++i)
    widest = std::max(widest, decoded->positions[i]);
  EXPECT_GT(widest, 2.0f);
  EXPECT_LE(widest, 8.01f);
}

TEST(Cli, BadInputsExitNonZeroWithAClearMessage) {
  const std::string out = TempPath("cli-bad.ply");
  struct Case {
    std::string args, message;
  };
  const Case cases[] = {
      {"info --volume /no/such/file.nii", "/no/such/file.nii"},
      {"info --volume nosuch:33", "unknown generator"},
      {"extarct --volume sphere:17",
       "unknown command 'extarct' (info, tets, extract, fetch, volumes or stats)"},
      {"extract --volume sphere:17 --iso 0.5 --budget 0 -o " + out, "--budget"},
      {"extract --volume sphere:17 --iso 0.5 --eps -1 -o " + out, "--eps must be a finite"},
      {"extract --volume sphere:17 --iso 0.5 --eps inf -o " + out, "--eps must be a finite"},
      {"extract --volume sphere:17 --iso 0.5 -o " + out, "--eps"},
      {"extract --volume sphere:17 --iso 1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16,17 --eps 0 -o " +
           out,
       "16"},
      {"extract --volume sphere:17 --iso abc --eps 0 -o " + out, "abc"},
      {"extract --volume sphere:17 --iso 0.5 --eps 0 --view-dir 0,0,0 -o " + out, "direction"},
      {"extract --volume sphere:17 --iso 0.5 --eps 0 -o " + TempPath("x.obj"), ".ply or .glb"},
      {"extract --volume sphere:17 --iso 0.5 --eps 0 -o /no/such/dir/x.ply", "/no/such/dir"},
      // Given but empty or negative: an error, not "absent".
      {"extract --volume sphere:17 --iso 0.5 --budget -1 -o " + out, "positive triangle count"},
      {"extract --volume sphere:17 --iso 0.5 --eps 0 --eye '' -o " + out, "--eye"},
      {"extract --volume sphere:17 --iso 0.5 --eps 0 --view-dir '' -o " + out, "--view-dir"},
      {"extract --volume sphere:17 --iso 0.5 --eps '' -o " + out, "--eps: a number is needed"},
      {"extract --volume sphere:17 --iso 0.5 --budget '' -o " + out, "--budget: a number"},
      {"extract --volume sphere:17 --iso 1e300 --eps 0 -o " + out, "single-precision range"},
      {"info --volume raw:/dev/null:4x4x4:float32:xx", "byte order 'xx'"},
      {"info --volume sphere:17 --iso 0.5,1e300", "single-precision range"},
      {"info --volume sphere:17 --iso ''", "--iso: a number is needed"},  // not "no table"
      {"fetch --server 127.0.0.1:1 --volume sphere:17 --iso 0.5 --eps 0 "
       "--max-frame-triangles 0 -o " +
           out,
       "--max-frame-triangles"},

  };
  for (const auto& c : cases) {
    const CliRun r = Cli(c.args + " --no-cache");
    EXPECT_NE(r.code, 0) << c.args;
    EXPECT_LT(r.code, 100) << c.args;  // usage errors exit 2 too, not CLI11's 100+
    EXPECT_NE(r.output.find(c.message), std::string::npos) << c.args << "\n" << r.output;
  }
  // An empty CA file would have meant plaintext: refused before connecting, as is a device.
  const std::string empty_ca = TempPath("cli-empty-ca.pem");
  ASSERT_TRUE(WriteFileBytes(empty_ca, "").ok());
  for (const auto& [ca, message] :
       {std::pair<std::string, std::string>{empty_ca, "holds no certificates"},
        {"/dev/null", "not a regular file"}}) {
    const CliRun r =
        Cli("fetch --server 127.0.0.1:1 --volume sphere:17 --iso 0.5 --eps 0 "
            "--tls-ca " +
            ca + " -o " + out);
    EXPECT_EQ(r.code, 2) << ca;
    EXPECT_NE(r.output.find(message), std::string::npos) << r.output;
  }
  // A server address without a numeric port had gRPC try port 0 or 443.
  for (const std::string server : {"127.0.0.1:abc", "localhost"}) {
    const CliRun r =
        Cli("fetch --server " + server + " --volume sphere:17 --iso 0.5 --eps 0 -o " + out);
    EXPECT_EQ(r.code, 2) << server;
    EXPECT_NE(r.output.find("'" + server + "' is not HOST:PORT"), std::string::npos) << r.output;
  }
  // The view's flags are checked before any call, as extract checks them (a zero --view-dir came
  // back as the server's refusal, exit 1); an output named .PLY is taken, as extract takes it.
  const CliRun zero_dir =
      Cli("fetch --server 127.0.0.1:1 --volume sphere:17 --iso 0.5 --eps 0 "
          "--view-dir 0,0,0 -o " +
          out);
  EXPECT_EQ(zero_dir.code, 2) << zero_dir.output;
  EXPECT_NE(zero_dir.output.find("view direction"), std::string::npos) << zero_dir.output;
  const CliRun upper = Cli("fetch --server 127.0.0.1:1 --volume sphere:17 --iso 0.5 --eps 0 -o " +
                           TempPath("cli-upper.PLY"));
  EXPECT_EQ(upper.code, 1) << upper.output;  // past the name: nothing listens there
  EXPECT_NE(upper.output.find("cannot reach"), std::string::npos) << upper.output;
  // Outputs that cannot be written are refused before the volume is prepared (cayley:4097
  // would take minutes and 270 GB), not after the frame was extracted.
  const std::string folder_named_ply = TempPath("cli-folder.ply");
  std::filesystem::create_directories(folder_named_ply);
  for (const auto& [o, message] :
       {std::pair<std::string, std::string>{"/no/such/dir/x.ply", "no folder /no/such/dir/"},
        {folder_named_ply, "is a directory"}}) {
    const CliRun r = Cli("extract --volume cayley:4097 --iso 0.5 --eps 0 --no-cache -o " + o);
    EXPECT_EQ(r.code, 2) << o << "\n" << r.output;
    EXPECT_NE(r.output.find(message), std::string::npos) << r.output;
  }
}

// A --volume spec that is wrong as written is a usage error, exit 2, as the other flags' are; a
// file it names that is missing or damaged is not (exit 1). Both exited 1.
TEST(Cli, VolumeSpecsWrongAsWrittenAreUsageErrors) {
  const std::string raw = TempPath("cli-spec.raw");
  ASSERT_TRUE(WriteFileBytes(raw, std::string(8, '\0')).ok());
  const std::string notes = TempPath("cli-spec-notes.txt");
  ASSERT_TRUE(WriteFileBytes(notes, "notes").ok());
  const std::string damaged = TempPath("cli-spec-damaged.nii");
  ASSERT_TRUE(WriteFileBytes(damaged, "not a NIfTI header").ok());
  struct Case {
    std::string spec, message;
    int code;
  };
  const Case cases[] = {
      {"nosuch:33", "unknown generator 'nosuch'", 2},
      {"sphere:x", "N 'x' is not an integer", 2},
      {"sphere:9:3", "expected sphere:N", 2},
      {"noise:9:-1", "SEED '-1'", 2},
      {"sphere:1", "need at least 2 samples per axis", 2},
      {"sphere:5000", "exceed the limit of 4097 samples per axis", 2},  // --max-dim's default
      {"sphere:2000", "exceed the limit of 1076890625 samples", 2},     // past 1025^3 in all
      {"sphere:300 --max-dim 299", "exceed the limit of 299 samples per axis", 2},
      // No larger side can be held (its cube's k would pass 12).
      {"sphere:1026 --max-dim 4098", "--max-dim: Value 4098 not in range 2 to 4097", 2},
      {"raw:" + raw + ":2x2:uint8", "dims '2x2' are not NXxNYxNZ", 2},
      {"raw:" + raw + ":2x2x2:float", "unsupported type 'float'", 2},
      {"raw:" + raw + ":2x2x2:uint8:middle", "byte order 'middle'", 2},
      {notes, "unrecognised volume type", 2},
      {"buckyball", "unrecognised volume type", 2},
      {TempPath("cli-spec-missing.nii"), "no such file", 1},
      {"raw:" + TempPath("cli-spec-missing.raw") + ":2x2x2:uint8", "no such file", 1},
      {"raw:" + raw + ":2x2x3:uint8", "cli-spec.raw", 1},  // 8 bytes of the 12 it needs
      {damaged, "cli-spec-damaged.nii", 1},
  };
  const std::string out = TempPath("cli-spec.ply");
  for (const Case& c : cases) {
    for (const std::string& command :
         {"info --volume " + c.spec,
          "extract --volume " + c.spec + " --iso 0.5 --eps 0 -o " + out}) {
      const CliRun r = Cli(command + " --no-cache");
      EXPECT_EQ(r.code, c.code) << command << "\n" << r.output;
      EXPECT_NE(r.output.find(c.message), std::string::npos) << command << "\n" << r.output;
    }
  }
  EXPECT_EQ(Cli("info --volume raw:" + raw + ":2x2x2:uint8 --no-cache").code, 0);
}

// An isovalue the volume never reaches draws nothing; the user is told so (a typo such as
// "--iso 0,5" for 0.5 read as two isovalues, 0 and 5, gave a silently empty mesh).
TEST(Cli, IsovaluesOutsideTheDataAreNamed) {
  const CliRun r = Cli("extract --volume sphere:17 --iso 0,5 --eps 0 --no-cache -o " +
                       TempPath("cli-outside.ply"));
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("isovalue 5 lies outside sphere:17's values [0, 1.7320508]"),
            std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("isovalue 0 lies"), std::string::npos) << r.output;
  // Single-precision values in their shortest form (4.9 printed as 4.900000095367432).
  const CliRun tenths = Cli("extract --volume sphere:17 --iso 4.9 --eps 0 --no-cache -o " +
                            TempPath("cli-outside.ply"));
  EXPECT_NE(tenths.output.find("isovalue 4.9 lies outside"), std::string::npos) << tenths.output;
  const CliRun info = Cli("info --volume sphere:17 --iso 0,5 --no-cache");
  EXPECT_EQ(info.code, 0) << info.output;
  EXPECT_NE(info.output.find("isovalue 5 lies outside sphere:17's values"), std::string::npos)
      << info.output;
}

// Results that look wrong but are what was asked for are explained: a budget under the coarsest
// mesh (written, silently over budget, as "found for the budget"), and an eps so large that the
// coarse tetrahedra miss every surface (an empty mesh, silently).
TEST(Cli, SurprisingFramesAreExplained) {
  // What `extract --volume VOLUME ARGS` prints, after it succeeded.
  auto extract = [](const std::string& volume, const std::string& args) {
    const CliRun r = Cli("extract --volume " + volume + " --no-cache " + args + " -o " +
                         TempPath("cli-noted.ply"));
    EXPECT_EQ(r.code, 0) << args << "\n" << r.output;
    return r.output;
  };
  const std::string over = extract("cayley:33", "--iso 0 --budget 1 --stats");
  EXPECT_NE(over.find("has 12 triangles, over the budget of 1"), std::string::npos) << over;
  EXPECT_NE(over.find("(the coarsest mesh, over the budget)"), std::string::npos) << over;
  EXPECT_EQ(over.find("found for the budget"), std::string::npos) << over;
  const std::string empty = extract("sphere:17", "--iso 0.5 --eps 100");
  EXPECT_NE(empty.find("the mesh is empty at eps 100"), std::string::npos) << empty;
  // A budget under the first mesh that has triangles: the budget is what to change, not an eps
  // the user never gave.
  const std::string empty_budget = extract("sphere:17", "--iso 0.5 --budget 1");
  EXPECT_NE(empty_budget.find("the next finer mesh is over the budget of 1 triangles"),
            std::string::npos)
      << empty_budget;
  EXPECT_EQ(empty_budget.find("a smaller eps"), std::string::npos) << empty_budget;
  const std::string fine = extract("sphere:17", "--iso 0.5 --eps 0");
  EXPECT_EQ(fine.find("note:"), std::string::npos) << fine;
  // No advice to lower an eps of 0, nor for isovalues the volume never reaches (their own note
  // says why), nor for a budget's search (it never stops at an empty mesh above eps 0).
  for (const char* args : {"--iso 0.5 --eps 0", "--iso 5 --eps 9", "--iso 5 --budget 1000"}) {
    const std::string out = extract("sphere:17", args);
    EXPECT_EQ(out.find("the mesh is empty"), std::string::npos) << args << "\n" << out;
  }
}

// `args` ended by one value of its last flag, then another: the second succeeds and prints
// what the first did. Returns the second run.
CliRun ExpectSameOutput(const std::string& args, const std::string& first,
                        const std::string& second) {
  const CliRun a = Cli(args + first);
  const CliRun b = Cli(args + second);
  EXPECT_EQ(b.code, 0) << b.output;
  EXPECT_EQ(b.output, a.output) << first << " vs " << second;
  return b;
}

// A count may be written with an exponent ("--budget 1e3"): it was refused as "Could not
// convert". A fraction is still refused.
TEST(Cli, BudgetsWithAnExponent) {
  const std::string args = "extract --volume sphere:17 --iso 0.5 --no-cache -o " +
                           TempPath("cli-exponent.ply") + " --budget ";
  ExpectSameOutput(args, "1000", "1e3");
  // Counts that are not whole or pass int64's end are refused by name (CLI11 said "Could not
  // convert", and took 99999999999999999999 as the largest count silently).
  for (const auto& [given, says] :
       {std::pair<std::string, std::string>{"1.5", "1.5 is not a whole number"},
        {"1e19", "1e19 is past the largest count"},
        {"99999999999999999999", "99999999999999999999 is past the largest count"}}) {
    const CliRun bad = Cli(args + given);
    EXPECT_EQ(bad.code, 2) << bad.output;
    EXPECT_NE(bad.output.find(says), std::string::npos) << bad.output;
  }
  // Up to int64's end: 9e18 (below 2^63) was refused as "Could not convert".
  ExpectSameOutput(args, "9200000000000000000", "9.2e18");
}

// More threads than cores: the same output, and nothing from TBB on stderr (it warned that it
// ignored the extra ones).
TEST(Cli, ThreadsPastTheCoresAreQuiet) {
  const std::string args = "extract --volume sphere:17 --iso 0.5 --eps 0 --no-cache -o " +
                           TempPath("cli-threads.ply") + " --threads ";
  const CliRun many = ExpectSameOutput(args, "1", "1024");
  EXPECT_EQ(many.output.find("TBB"), std::string::npos) << many.output;
}

// What a command prints is its result: one that cannot be written is a failure (exit 1), help
// included.
TEST(Cli, AnUnwritableStandardOutputFails) {
  for (const std::string cmd :
       {"tets", "tets --json", "info --volume sphere:9 --no-cache", "--help", "extract --help"}) {
    EXPECT_EQ(Cli(cmd + " >/dev/null").code, 0) << cmd;
    EXPECT_EQ(Cli(cmd + " >/dev/full").code, 1) << cmd;
  }
}

// The reference tetrahedra's plane normals read 0 where a component is zero, never -0.0 (a
// negated zero printed as such; a helper's walkthrough found it).
TEST(Cli, TetsPrintsNoNegativeZero) {
  for (const std::string cmd : {"tets", "tets --json"}) {
    const CliRun r = Cli(cmd);
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_NE(r.output.find("0.7071067811865475"), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find("-0.0,"), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find("-0.0]"), std::string::npos) << r.output;
  }
}

TEST(Cli, InfoPrintsTheTriangleCountByEps) {
  const CliRun r = Cli("info --volume buckyball:33 --iso 0.05,0.15 --no-cache");
  ASSERT_EQ(r.code, 0) << r.output;
  const size_t table = r.output.find("triangles by eps");
  ASSERT_NE(table, std::string::npos) << r.output;
  std::istringstream rows(r.output.substr(r.output.find('\n', r.output.find("  eps", table)) + 1));
  std::vector<std::pair<std::string, long long>> counts;
  std::string eps;
  long long n;
  while (rows >> eps >> n) counts.push_back({eps, n});
  ASSERT_GE(counts.size(), 4u) << r.output;
  for (size_t i = 1; i < counts.size(); ++i)
    EXPECT_GE(counts[i].second, counts[i - 1].second) << counts[i].first;
  EXPECT_EQ(counts.back().first, "0");
  const std::string out = TempPath("cli-info-full.ply");
  ASSERT_EQ(Cli("extract --volume buckyball:33 --iso 0.05,0.15 --eps 0 --no-cache -o " + out).code,
            0);
  auto ply = ReadPly(out);
  ASSERT_TRUE(ply.ok()) << ply.status();
  EXPECT_EQ(counts.back().second, (long long)ply->triangle_count());
  // Every eps printed gives back its count: printed short (6 digits), 1.73438 stood for the
  // code at 1.734375 and gave 5712 triangles where the table said 5760.
  for (const auto& [printed, count] : counts) {
    const CliRun again = Cli("extract --volume buckyball:33 --iso 0.05,0.15 --eps " + printed +
                             " --no-cache -o " + out);
    ASSERT_EQ(again.code, 0) << again.output;
    auto redone = ReadPly(out);
    ASSERT_TRUE(redone.ok()) << redone.status();
    EXPECT_EQ((long long)redone->triangle_count(), count) << "eps " << printed;
  }
  // No triangle at any eps: one row (a closing "0  0" repeated it).
  const CliRun none = Cli("info --volume buckyball:33 --iso 5 --no-cache");
  ASSERT_EQ(none.code, 0) << none.output;
  const std::string none_rows = none.output.substr(none.output.find("  eps"));
  EXPECT_EQ(std::count(none_rows.begin(), none_rows.end(), '\n'), 2) << none.output;
  EXPECT_NE(none_rows.find("\n  any               0\n"), std::string::npos) << none.output;
  const CliRun bad = Cli("info --volume buckyball:33 --iso 0.05,x --no-cache");
  EXPECT_EQ(bad.code, 2);
  EXPECT_NE(bad.output.find("'x' is not a number"), std::string::npos) << bad.output;
  // Checked before the volume is prepared: this one could not be (4097^3 floats).
  const CliRun early = Cli("info --volume cayley:4097 --iso 0.1,nan --no-cache");
  EXPECT_EQ(early.code, 2);
  EXPECT_NE(early.output.find("'nan' is not a number"), std::string::npos) << early.output;
  // A number past the double range is one, only not finite (it was called not a number).
  const CliRun huge = Cli("info --volume cayley:4097 --iso 0.1,1e309 --no-cache");
  EXPECT_EQ(huge.code, 2);
  EXPECT_NE(huge.output.find("'1e309' is not a finite number"), std::string::npos) << huge.output;
  const CliRun twice = Cli("info --volume cayley:4097 --iso 0.1,0.1 --no-cache");
  EXPECT_EQ(twice.code, 2);
  EXPECT_NE(twice.output.find("isovalue 0.1 is given twice"), std::string::npos) << twice.output;
  // extract likewise: its view flags are checked before the volume is prepared (they were after).
  const std::string early_ply = ::testing::TempDir() + "/early.ply";
  const std::pair<std::string, std::string> refused[] = {
      {"--iso 0.1,0.1 --eps 0", "isovalue 0.1 is given twice"},
      {"--iso 0.1 --eps 0 --eye 1,2", "--eye needs x,y,z"},
      {"--iso 0.1", "give --eps E"},
      {"--iso 0.1 --budget 0", "--budget must be a positive"},
      {"--iso 1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16,17 --eps 0", "at most 16 isovalues"}};
  for (const auto& [flags, reason] : refused) {
    const CliRun refusal =
        Cli("extract --volume cayley:4097 --no-cache " + flags + " -o " + early_ply);
    EXPECT_EQ(refusal.code, 2) << flags << "\n" << refusal.output;
    EXPECT_NE(refusal.output.find(reason), std::string::npos) << flags << "\n" << refusal.output;
    EXPECT_EQ(refusal.output.find("lies outside"), std::string::npos) << flags << "\n"
                                                                      << refusal.output;
  }
}

// A thin volume stores its data's planes and stand-ins for the rest of its cube's padding, and
// says so: 600x9x5 pads to the 1025^3 cube (1.08 G points), of which it stores 0.7 M.
TEST(Cli, InfoSaysWhichPlanesAThinVolumeStores) {
  const std::string raw = TempPath("cli-thin.f32");
  {
    std::vector<float> values;
    for (int z = 0; z < 5; ++z)
      for (int y = 0; y < 9; ++y)
        for (int x = 0; x < 600; ++x)
          values.push_back(float(std::sin(0.02 * x) + 0.1 * y - 0.2 * z));
    ASSERT_TRUE(WriteFileBytes(raw, std::string_view(reinterpret_cast<const char*>(values.data()),
                                                     values.size() * sizeof(float)))
                    .ok());
  }
  const CliRun r = Cli("info --volume raw:" + raw + ":600x9x5:float32 --no-cache");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("cube 1025^3 (k = 10)"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("stored        624 x 36 x 32 planes of the cube's"), std::string::npos)
      << r.output;
}

// Spaces around the numbers of a list are allowed on either side; an empty item is not.
TEST(Cli, NumberListsAllowSpacesAroundItems) {
  EXPECT_EQ(Cli("info --volume sphere:9 --iso ' 0.5 , 0.7 ' --no-cache").code, 0);
  const CliRun empty = Cli("info --volume sphere:9 --iso '0.5, ,0.7' --no-cache");
  EXPECT_EQ(empty.code, 2);
  EXPECT_NE(empty.output.find("'' is not a number"), std::string::npos) << empty.output;
}

// Two samples per axis is a valid volume: it pads to the smallest hierarchy, 3^3.
TEST(Cli, TwoSamplesPerAxisExtract) {
  const std::string out = TempPath("cli-two.ply");
  const CliRun r = Cli("extract --volume cayley:2 --iso 0 --eps 0 --no-cache -o " + out);
  ASSERT_EQ(r.code, 0) << r.output;
  auto ply = ReadPly(out);
  ASSERT_TRUE(ply.ok()) << ply.status();
  EXPECT_GT(ply->surface.size(), 0u);
}

TEST(Cli, TetsJsonListsTheSeventyTwoClasses) {
  const CliRun r = Cli("tets --json");
  ASSERT_EQ(r.code, 0);
  size_t count = 0;
  for (size_t at = r.output.find("\"level_mod3\""); at != std::string::npos;
       at = r.output.find("\"level_mod3\"", at + 1))
    ++count;
  EXPECT_EQ(count, 72u);
}

}  // namespace
}  // namespace isostream
