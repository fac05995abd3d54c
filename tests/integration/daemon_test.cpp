// Integration tests: a real isostreamd process on 127.0.0.1, driven through the client library
// and the `isostream fetch` CLI. Volumes are small generators (buckyball:65/129) so the suite
// runs in well under a minute on two cores; every wait is bounded.
#include <grpcpp/generic/generic_stub.h>
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <fstream>
#include <iterator>
#include <map>
#include <random>
#include <sstream>
#include <thread>
#include <tuple>

#include "server/extract/extractor.h"
#include "shared/frame_codec.h"
#include "shared/ply_io.h"
#include "tests/common/run_command.h"
#include "tests/integration/daemon_fixture.h"

// In the fixture's namespace: Daemon, MakeView, kIso, pb, the frame helpers and the process
// helpers need no using-declarations.
namespace isostream::testing {
namespace {

TEST_F(Daemon, HealthServingAndCatalogue) {
  auto c = Connect();
  auto health = c->CheckHealth();
  ASSERT_TRUE(health.ok()) << health.status();
  EXPECT_TRUE(*health);
  auto by_name = c->CheckHealth("isostream.v1.Isostream");
  ASSERT_TRUE(by_name.ok()) << by_name.status();
  EXPECT_TRUE(*by_name);
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
  // The histogram (computed in parallel, then kept) equals a direct count over the samples,
  // and again when it comes from what the daemon kept; one bin is just the sample count.
  const PreparedVolume local = Local("buckyball:65");
  std::vector<uint64_t> direct(16, 0);
  const double lo = info->min_value(), width = double(info->max_value()) - info->min_value();
  for (int z = 0; z < 65; ++z)
    for (int y = 0; y < 65; ++y)
      for (int x = 0; x < 65; ++x) {
        const double t = (local.hierarchy->sample(x, y, z) - lo) * 16 / width;
        ++direct[std::min<size_t>(15, size_t(std::max(0.0, t)))];
      }
  for (int round = 0; round < 2; ++round) {
    auto again = round == 0 ? info : c->GetVolumeInfo("buckyball:65", 16);
    ASSERT_TRUE(again.ok());
    EXPECT_EQ(std::vector<uint64_t>(again->histogram().begin(), again->histogram().end()), direct);
  }
  auto one = c->GetVolumeInfo("buckyball:65", 1);
  ASSERT_TRUE(one.ok());
  ASSERT_EQ(one->histogram_size(), 1);
  EXPECT_EQ(one->histogram(0), 65u * 65u * 65u);
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

// An Extract call draws one view: it keeps nothing to re-order (recording its cut cost
// instructions and retain_mb memory, and could free Session streams' retained frames). While
// its frame arrives, the daemon holds no retained frame for it.
TEST_F(Daemon, AnExtractCallRetainsNothing) {
  auto c = Connect();
  auto before = c->GetServerStats();
  ASSERT_TRUE(before.ok());
  int64_t during = -1;
  auto frame = c->Fetch(MakeView("buckyball:65", 70, 0.003, glm::dvec3(2, 2, 2)),
                        [&](const pb::FrameChunk& chunk) {
                          if (chunk.chunk_index() != 0) return;
                          auto now = Connect()->GetServerStats();
                          if (now.ok()) during = now->retained_bytes();
                        });
  ASSERT_TRUE(frame.ok()) << frame.status();
  EXPECT_EQ(during, before->retained_bytes());
}

// Within a session, a refined frame is kept and later views of its mesh (same volume,
// isovalues, eps, normals) are re-ordered from it, not extracted again: the frame says so, and
// equals a direct extraction for its view. A progressive request then skips its coarse frame;
// another eps is extracted (and kept in the old mesh's place), and the session's end gives
// the memory back.
TEST_F(Daemon, NewViewOfTheSameMeshIsReorderedFromTheLastFrame) {
  auto c = Connect();
  auto before = c->GetServerStats();
  ASSERT_TRUE(before.ok());
  PreparedVolume local = Local("buckyball:65");
  auto session = c->OpenSession();
  ASSERT_TRUE(session.ok());
  net::Session& s = **session;
  const glm::dvec3 eyes[5] = {
      {2.5, 1.8, 3.1}, {-3.0, 0.5, 1.0}, {0.1, 0.2, -0.1}, {0.2, -2.8, -1.5}, {3, 3, 3}};
  for (int i = 0; i < 5; ++i) {
    SCOPED_TRACE(i);
    const double eps = i < 4 ? 0.003 : 0.004;
    pb::ViewRequest v = MakeView("buckyball:65", 80 + i, eps, eyes[i], pb::RAW);
    v.set_progressive(i == 2);
    ASSERT_TRUE(s.Send(v).ok());
    net::Frame frame;
    ASSERT_TRUE(ReadFrame(s, &frame));
    EXPECT_EQ(frame.id, uint64_t(80 + i));
    EXPECT_FALSE(frame.coarse) << "the re-ordered frame needs no coarse one before it";
    EXPECT_EQ(frame.stats.reordered(), i >= 1 && i <= 3);
    auto direct = Extract(*local.hierarchy, local.grid_to_world, DirectRequest(eps, eyes[i]));
    ASSERT_TRUE(direct.ok());
    ExpectSameFrame(direct->mesh, frame.mesh, 0.0f);
    // The mesh is held while the session draws it.
    auto now = c->GetServerStats();
    ASSERT_TRUE(now.ok());
    EXPECT_GT(now->retained_bytes(), before->retained_bytes());
    if (i == 4) {
      EXPECT_EQ(now->frames_reordered(), before->frames_reordered() + 3);
    }
  }
  ASSERT_TRUE(s.CloseSend().ok());
  EXPECT_TRUE(s.Finish().ok());
  pb::ServerStats after;
  EXPECT_TRUE(WaitForStats(
      c.get(),
      [&](const pb::ServerStats& st) {
        return st.sessions_open() == 0 && st.retained_bytes() == before->retained_bytes();
      },
      &after))
      << after.retained_bytes();
}

// A triangle budget names a mesh as well as eps does: from its second view in a session the
// frame is re-ordered, and it is the frame a direct extraction at the remembered eps draws.
TEST_F(Daemon, BudgetViewsAreReorderedToo) {
  constexpr int64_t kBudget = 23456;  // used by no other test of this daemon
  auto c = Connect();
  PreparedVolume local = Local("buckyball:65");
  auto session = c->OpenSession();
  ASSERT_TRUE(session.ok());
  net::Session& s = **session;
  const glm::dvec3 eyes[3] = {{2.5, 1.8, 3.1}, {-3.0, 0.5, 1.0}, {0.2, -2.8, -1.5}};
  for (int i = 0; i < 3; ++i) {
    SCOPED_TRACE(i);
    pb::ViewRequest v = MakeView("buckyball:65", 90 + i, 0.0, eyes[i], pb::RAW);
    v.set_triangle_budget(kBudget);
    ASSERT_TRUE(s.Send(v).ok());
    net::Frame frame;
    ASSERT_TRUE(ReadFrame(s, &frame));
    EXPECT_EQ(frame.stats.reordered(), i >= 1);
    EXPECT_LE(frame.stats.triangles(), kBudget);
    auto direct = Extract(*local.hierarchy, local.grid_to_world,
                          DirectRequest(frame.stats.eps_used(), eyes[i]));
    ASSERT_TRUE(direct.ok());
    ExpectSameFrame(direct->mesh, frame.mesh, 0.0f);
  }
  ASSERT_TRUE(s.CloseSend().ok());
  EXPECT_TRUE(s.Finish().ok());
}

TEST_F(Daemon, FetchCommandWritesTheFrame) {
  const std::string out = scratch_->path() + "/fetched.ply";
  const std::string cmd = ::isostream::testing::ShellQuote(ISOSTREAM_CLI_PATH) +
                          " fetch --server " + daemon_->address() +
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
  // One vertex per place, as the extractor's mesh has: the chunks' copies of their seams'
  // vertices are one again (the PLY was open along the seams by index).
  EXPECT_EQ(mesh->vertex_count(), direct->mesh.vertex_count());
  // With Draco, vertices of one chunk that quantize alike stay apart (merging them made
  // triangles with a repeated corner), and a later chunk's copy of such a vertex is welded to
  // neither (welding it to the first made edges used 1 to 6 times): three closed spheres at
  // eps 0 (65 k chunks of ~580 k triangles; positions crowd where crossings meet near corners).
  const std::string draco = ::isostream::testing::ShellQuote(ISOSTREAM_CLI_PATH) +
                            " fetch --server " + daemon_->address() +
                            " --volume sphere:129 --iso 0.3,0.6,0.9 --eps 0 --eye 2.5,1.8,3.1 -o " +
                            out + " 2>/dev/null";
  ASSERT_EQ(std::system(draco.c_str()), 0);
  auto drawn = ReadPly(out);
  ASSERT_TRUE(drawn.ok()) << drawn.status();
  size_t repeated = 0;
  std::map<std::tuple<uint8_t, uint32_t, uint32_t>, int> uses;  // (surface, edge) -> triangles
  for (size_t t = 0; t < drawn->triangle_count(); ++t) {
    const uint32_t* c = &drawn->triangles[3 * t];
    repeated += c[0] == c[1] || c[1] == c[2] || c[0] == c[2];
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = c[k], b = c[(k + 1) % 3];
      ++uses[{drawn->surface[t], std::min(a, b), std::max(a, b)}];
    }
  }
  EXPECT_EQ(repeated, 0u);
  size_t open = 0, over = 0;
  for (const auto& [edge, n] : uses) open += n == 1, over += n > 2;
  EXPECT_EQ(over, 0u);
  // Open only at copies of vertices quantized alike (144 edges of 872 k when measured).
  EXPECT_LT(open, uses.size() / 1000) << open;

  const std::string bad = ::isostream::testing::ShellQuote(ISOSTREAM_CLI_PATH) +
                          " fetch --server " + daemon_->address() +
                          " --volume /etc/passwd --iso 0.1 --eps 0.01 -o " + out + " 2>/dev/null";
  EXPECT_NE(std::system(bad.c_str()), 0);

  // What would surprise is explained, as extract does: an isovalue outside the values, a
  // budget under the coarsest mesh.
  const testing::CommandResult noted = testing::RunCommand(
      ::isostream::testing::ShellQuote(ISOSTREAM_CLI_PATH) + " fetch --server " +
      daemon_->address() + " --volume cayley:33 --iso 0,99 --budget 1 -o " + out);
  EXPECT_EQ(noted.code, 0) << noted.output;
  EXPECT_NE(noted.output.find("isovalue 99 lies outside cayley:33's values"), std::string::npos)
      << noted.output;
  EXPECT_NE(noted.output.find("over the budget of 1"), std::string::npos) << noted.output;
  EXPECT_EQ(noted.output.find("frame limit"), std::string::npos) << noted.output;  // under it
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

  // A budget over --max-triangles 1000000 is that limit (GuardedDaemon tests one that binds).
  pb::ViewRequest big_budget = MakeView("buckyball:65", 1, 0.01, eye);
  big_budget.set_triangle_budget(2'000'000);
  EXPECT_TRUE(code(big_budget).ok());

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

// A progressive budget request whose frame is no bigger than the coarse one gets one frame, the
// refined one: the whole mesh within the coarse budget, or a budget at most twice it (a budget
// of 20001 drew the same 20000 triangles twice, as coarse and as refined).
TEST_F(Daemon, ProgressiveBudgetsGetNoCoarseCopyOfTheirFrame) {
  auto c = Connect();
  for (const auto& [volume, budget] : std::vector<std::pair<std::string, int64_t>>{
           {"sphere:33", 200000}, {"buckyball:65", 20001}}) {
    auto session = c->OpenSession();
    ASSERT_TRUE(session.ok());
    pb::ViewRequest v = MakeView(volume, 1, 0.0, glm::dvec3(3, 2, 1));
    v.set_triangle_budget(budget);
    v.set_progressive(true);
    ASSERT_TRUE((*session)->Send(v).ok());
    ASSERT_TRUE((*session)->CloseSend().ok());
    net::FrameAssembler assembler;
    pb::FrameChunk chunk;
    int coarse_chunks = 0, frames = 0;
    while ((*session)->Read(&chunk)) {
      coarse_chunks += chunk.coarse();
      ASSERT_TRUE(assembler.Add(chunk).ok());
      if (assembler.complete()) ++frames, assembler.Take();
    }
    EXPECT_TRUE((*session)->Finish().ok());
    EXPECT_EQ(coarse_chunks, 0) << volume;
    EXPECT_EQ(frames, 1) << volume;
  }
}

// Views replaced while their volume is still being prepared (the frame never starts) count as
// cancelled frames too, as the proto says; they were not counted.
TEST_F(Daemon, ViewsSupersededWhileTheVolumePreparesCountAsCancelled) {
  auto c = Connect();
  auto before = c->GetServerStats();
  ASSERT_TRUE(before.ok());
  auto session = c->OpenSession();
  ASSERT_TRUE(session.ok());
  net::Session& s = **session;
  // A volume no other test uses, so the first view's job waits for its preparation (~0.1-1 s):
  // the next views arrive meanwhile. (Whether they do or not, every view must be counted.)
  const std::string volume = "noise:129:7";
  for (uint64_t id = 1; id <= 3; ++id) {
    ASSERT_TRUE(s.Send(MakeView(volume, id, 0.3, glm::dvec3(3, 2, 1.0 + double(id)))).ok());
    if (id == 1) std::this_thread::sleep_for(std::chrono::milliseconds(30));  // the job starts
  }
  ASSERT_TRUE(s.CloseSend().ok());
  net::FrameAssembler assembler;
  pb::FrameChunk chunk;
  std::vector<uint64_t> frames;
  while (s.Read(&chunk)) {
    ASSERT_TRUE(assembler.Add(chunk).ok());
    if (assembler.complete()) frames.push_back(assembler.Take().id);
  }
  const absl::Status finished = s.Finish();
  EXPECT_TRUE(finished.ok()) << finished;
  ASSERT_FALSE(frames.empty());
  EXPECT_EQ(frames.back(), 3u);
  pb::ServerStats after;
  ASSERT_TRUE(WaitForStats(
      c.get(), [](const pb::ServerStats& st) { return st.sessions_open() == 0; }, &after));
  // Every view is either sent whole or counted as cancelled.
  EXPECT_EQ((after.frames_sent() - before->frames_sent()) +
                (after.frames_cancelled() - before->frames_cancelled()),
            3)
      << "sent " << after.frames_sent() - before->frames_sent() << ", cancelled "
      << after.frames_cancelled() - before->frames_cancelled();
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

// Sends `bytes` as the request of `method` with gRPC's generic stub (a typed client cannot
// send bytes that do not parse), reads whatever comes back, and returns the call's status and
// how many messages arrived.
std::pair<grpc::Status, int> RawCall(const std::string& address, const std::string& method,
                                     const std::string& bytes) {
  auto channel = grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
  grpc::GenericStub stub(channel);
  grpc::CompletionQueue cq;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  auto call = stub.PrepareCall(&context, method, &cq);
  // Each step waits for its own completion (tags are step numbers).
  intptr_t next = 0;
  auto step = [&]() {
    void* got = nullptr;
    bool ok = false;
    EXPECT_TRUE(cq.Next(&got, &ok));
    EXPECT_EQ(got, reinterpret_cast<void*>(next));
    return ok;
  };
  auto tag = [&] { return reinterpret_cast<void*>(++next); };
  call->StartCall(tag());
  step();
  grpc::Slice slice(bytes);
  call->WriteLast(grpc::ByteBuffer(&slice, 1), grpc::WriteOptions(), tag());
  step();  // may fail if the server already finished: the status says why
  int messages = 0;
  for (;;) {
    grpc::ByteBuffer reply;
    call->Read(&reply, tag());
    if (!step()) break;
    ++messages;
  }
  grpc::Status status;
  call->Finish(&status, tag());
  step();
  cq.Shutdown();
  void* ignored;
  bool ok;
  while (cq.Next(&ignored, &ok)) {
  }
  return {status, messages};
}

// Bytes that are not the method's request (a field claiming 16 bytes with 3 behind it):
// INVALID_ARGUMENT naming the type expected, no message back, on every call. gRPC itself would
// end a Session with OK and no frame (it takes the failed parse for the client's half-close)
// and answer the others UNIMPLEMENTED with no message.
TEST_F(Daemon, RequestBytesThatDoNotParseAreInvalidArgument) {
  const std::string garbage(
      "\x0a\x10"
      "abc",
      5);
  for (const auto& [method, type] : std::vector<std::pair<std::string, std::string>>{
           {"/isostream.v1.Isostream/Session", "ViewRequest"},
           {"/isostream.v1.Isostream/Extract", "ViewRequest"},
           {"/isostream.v1.Isostream/GetVolumeInfo", "GetVolumeInfoRequest"},
           {"/isostream.v1.Isostream/ListVolumes", "ListVolumesRequest"},
           {"/isostream.v1.Isostream/GetServerStats", "GetServerStatsRequest"}}) {
    const auto [status, messages] = RawCall(daemon_->address(), method, garbage);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
        << method << ": " << status.error_message();
    EXPECT_NE(status.error_message().find(type), std::string::npos) << status.error_message();
    EXPECT_EQ(messages, 0) << method;
  }
  // The same path with bytes that parse: a frame's chunks come back, and a volume's info.
  pb::ViewRequest view = MakeView("buckyball:65", 5, 0.05, glm::dvec3(2, 2, 2));
  const auto [extracted, chunks] =
      RawCall(daemon_->address(), "/isostream.v1.Isostream/Extract", view.SerializeAsString());
  EXPECT_TRUE(extracted.ok()) << extracted.error_message();
  EXPECT_GT(chunks, 0);
  pb::GetVolumeInfoRequest info;
  info.set_name("buckyball:65");
  const auto [described, answers] = RawCall(
      daemon_->address(), "/isostream.v1.Isostream/GetVolumeInfo", info.SerializeAsString());
  EXPECT_TRUE(described.ok()) << described.error_message();
  EXPECT_EQ(answers, 1);
  // Random bytes (some parse, as messages of unknown fields or odd values): a clear refusal
  // each time, and the daemon still serves.
  std::mt19937 rng(7);
  for (int i = 0; i < 40; ++i) {
    std::string bytes(rng() % 48, '\0');
    for (char& b : bytes) b = char(rng() & 0xff);
    for (const char* method : {"/isostream.v1.Isostream/Session", "/isostream.v1.Isostream/Extract",
                               "/isostream.v1.Isostream/GetVolumeInfo"}) {
      const auto [status, messages] = RawCall(daemon_->address(), method, bytes);
      const auto code = status.error_code();
      EXPECT_TRUE(code == grpc::StatusCode::INVALID_ARGUMENT || code == grpc::StatusCode::NOT_FOUND)
          << method << ": " << code << " " << status.error_message();
      EXPECT_EQ(messages, 0) << method;
    }
  }
  // A volume name that is not UTF-8: refused, and not one unformatted protobuf line in the
  // log per request (any client could flood it that way).
  const std::string not_utf8("\x0a\x02\xff\xfe", 4);
  for (int i = 0; i < 3; ++i) {
    const auto [status, messages] =
        RawCall(daemon_->address(), "/isostream.v1.Isostream/Extract", not_utf8);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << status.error_message();
  }
  const std::string text = DaemonLog(*scratch_);
  EXPECT_EQ(text.find("libprotobuf"), std::string::npos) << text;
  auto health = Connect()->CheckHealth();
  ASSERT_TRUE(health.ok()) << health.status();
  EXPECT_TRUE(*health);
}

// Fetch of a progressive view returns the refined frame, not the coarse one that comes first.
TEST_F(Daemon, FetchOfAProgressiveViewReturnsTheRefinedFrame) {
  auto c = Connect();
  pb::ViewRequest view = MakeView("buckyball:129", 11, 0.002, glm::dvec3(2, -2, 2));
  bool saw_coarse = false;
  auto plain = c->Fetch(view);
  ASSERT_TRUE(plain.ok()) << plain.status();
  view.set_progressive(true);
  auto frame = c->Fetch(view, [&](const pb::FrameChunk& ch) { saw_coarse |= ch.coarse(); });
  ASSERT_TRUE(frame.ok()) << frame.status();
  ASSERT_TRUE(saw_coarse) << "no coarse frame came: nothing tested";
  EXPECT_FALSE(frame->coarse);
  EXPECT_EQ(frame->mesh.triangle_count(), plain->mesh.triangle_count());
}

// A session closed for sending refuses further views with FAILED_PRECONDITION (a gRPC write
// after WritesDone is not allowed).
TEST_F(Daemon, ASessionClosedForSendingRefusesViews) {
  auto session = Connect()->OpenSession();
  ASSERT_TRUE(session.ok());
  ASSERT_TRUE((*session)->CloseSend().ok());
  EXPECT_EQ((*session)->Send(MakeView("buckyball:65", 1, 0.01, glm::dvec3(2, 2, 2))).code(),
            absl::StatusCode::kFailedPrecondition);
  EXPECT_TRUE((*session)->Finish().ok());
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

}  // namespace
}  // namespace isostream::testing
