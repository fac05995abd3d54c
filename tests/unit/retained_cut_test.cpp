// A retained cut re-ordered for another view equals a fresh extraction for that view: the same
// triangles, with the same vertex positions, normals and surfaces, in the same draw order.
#include "server/extract/retained_cut.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "test_volumes.h"

namespace isostream {
namespace {

using testing::BlobsField;
using testing::CayleyField;
using testing::SphereField;

// Grid to world as a served volume has it: not the identity.
const GridToWorld kXf{glm::dvec3(-1.0, -0.75, -1.25), glm::dvec3(2.0 / 64, 2.0 / 64, 2.5 / 64)};

using Case = testing::VolumeCase;

// Extracts r, recording into *cut, and hands the cut a copy of the frame (KeepMesh), as the
// daemon hands it the frame it streamed.
absl::StatusOr<ExtractResult> ExtractRetaining(const Hierarchy& h, const GridToWorld& xf,
                                               const ExtractRequest& r, RetainedCut* cut) {
  auto res = Extract(h, xf, r, nullptr, cut);
  if (res.ok()) {
    EXPECT_TRUE(cut->KeepMesh(OrderedMesh(res->mesh)));
  }
  return res;
}

std::vector<Case> Volumes() {
  std::vector<Case> v;
  v.push_back({testing::MakeHierarchy(5, CayleyField), {-0.3f, 0.05f, 0.4f}, "cayley 33^3"});
  v.push_back({testing::MakeHierarchy(5, BlobsField), {0.2f, 0.5f, 0.8f}, "blobs 33^3"});
  v.push_back({testing::MakeHierarchy(4, SphereField), {0.6f}, "sphere 17^3"});
  v.push_back(testing::ClippedCayley());
  // Vertices on terraces, where the normal cannot come from central differences.
  v.push_back({testing::MakeHierarchy(5, testing::TerracesField), {0.5f}, "terraces 33^3"});
  return v;
}

// Triangle t of m as its corners' positions and normals and its surface, bit for bit.
std::vector<float> Corners(const OrderedMesh& m, size_t t) {
  std::vector<float> out;
  for (int i = 0; i < 3; ++i) {
    const size_t v = m.triangles[3 * t + i];
    out.insert(out.end(), &m.positions[3 * v], &m.positions[3 * v] + 3);
    out.insert(out.end(), &m.normals[3 * v], &m.normals[3 * v] + 3);
  }
  return out;
}

void ExpectSameDrawing(const OrderedMesh& fresh, const OrderedMesh& reordered,
                       const std::string& what) {
  ASSERT_EQ(fresh.triangle_count(), reordered.triangle_count()) << what;
  ASSERT_EQ(fresh.vertex_count(), reordered.vertex_count()) << what;
  for (size_t t = 0; t < fresh.triangle_count(); ++t) {
    ASSERT_EQ(fresh.surface[t], reordered.surface[t]) << what << ", triangle " << t;
    const std::vector<float> a = Corners(fresh, t), b = Corners(reordered, t);
    ASSERT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(float)), 0)
        << what << ", triangle " << t;
  }
}

// Views given in grid units, placed in the world as kXf places the grid.
View Perspective(glm::dvec3 grid_eye) {
  View v;
  v.eye = kXf.origin + kXf.spacing * grid_eye;
  return v;
}
View Orthographic(glm::dvec3 grid_direction) {
  View v;
  v.orthographic = true;
  v.direction = kXf.spacing * grid_direction;
  return v;
}

TEST(RetainedCut, ReorderedForAnotherViewEqualsAFreshExtraction) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(-1, 1);
  int compared = 0, with_several_surfaces = 0;
  for (const Case& vol : Volumes()) {
    ASSERT_NE(vol.h, nullptr) << vol.name;
    const Hierarchy& h = *vol.h;
    const double n = h.n() - 1, half = n / 2;
    const int mid = h.n() / 2;
    for (double eps : {0.0, 0.05 * h.eta(mid, mid, mid)})
      for (NormalMode normals : {NormalMode::kSmooth, NormalMode::kFlat})
        for (bool blocks : {true, false}) {
          ExtractRequest r;
          r.isovalues = vol.iso;
          r.eps = eps;
          r.normals = normals;
          r.blocks = blocks;
          r.threads = 2;
          r.view = Perspective({-0.7 * n, 2.1 * n, 1.3 * n});
          RetainedCut cut;
          auto first = ExtractRetaining(h, kXf, r, &cut);
          ASSERT_TRUE(first.ok()) << first.status();
          ASSERT_GT(first->mesh.triangle_count(), 50u) << vol.name;
          ASSERT_TRUE(cut.Serves(r));
          // Eyes outside and inside the volume, on grid planes (ties of the plane tests),
          // directions, and the unordered traversal.
          std::vector<std::pair<View, DrawOrder>> views = {
              {r.view, DrawOrder::kBackToFront},
              {Perspective({half + 0.3, half - 0.2, 1.7}), DrawOrder::kBackToFront},
              {Perspective({half, half, half}), DrawOrder::kBackToFront},
              {Perspective({3.0 * n, -n, 0.5 * n}), DrawOrder::kBackToFront},
              {Orthographic({0.3, -1.0, 0.2}), DrawOrder::kBackToFront},
              {Orthographic({0, 0, 1}), DrawOrder::kBackToFront},
              {Perspective({2 * n, 2 * n, 2 * n}), DrawOrder::kNone}};
          for (int i = 0; i < 3; ++i)
            views.push_back(
                {Perspective({half + n * unit(rng), half + n * unit(rng), half + n * unit(rng)}),
                 DrawOrder::kBackToFront});
          for (const auto& [view, order] : views) {
            ExtractRequest fresh_request = r;
            fresh_request.view = view;
            fresh_request.order = order;
            auto fresh = Extract(h, kXf, fresh_request);
            ASSERT_TRUE(fresh.ok()) << fresh.status();
            auto reordered = Reorder(cut, view, order);
            ASSERT_TRUE(reordered.ok()) << reordered.status();
            EXPECT_TRUE(reordered->stats.reordered);
            EXPECT_EQ(reordered->stats.eps_used, fresh->stats.eps_used);
            EXPECT_EQ(reordered->stats.triangles_per_surface, fresh->stats.triangles_per_surface);
            // Leaves with triangles are the mesh's, whatever the view; the walk visits records.
            EXPECT_EQ(reordered->stats.leaves, fresh->stats.leaves);
            EXPECT_EQ(reordered->stats.triangles, fresh->stats.triangles);
            EXPECT_EQ(reordered->stats.vertices, fresh->stats.vertices);
            EXPECT_GT(reordered->stats.tets_visited, 0);
            ExpectSameDrawing(fresh->mesh, reordered->mesh,
                              vol.name + " eps " + std::to_string(eps) + " view " +
                                  std::to_string(compared % views.size()));
            ++compared;
          }
          if (vol.iso.size() > 1 && cut.memory_bytes() > 0) ++with_several_surfaces;
        }
  }
  EXPECT_EQ(compared, 5 * 2 * 2 * 2 * 10);
  EXPECT_GT(with_several_surfaces, 0);
}

// Three nested blobs extracted from one view, their cut retained.
ExtractResult RetainBlobs(RetainedCut* cut) {
  static const HierarchyPtr h = testing::MakeHierarchy(5, BlobsField);
  ExtractRequest r;
  r.isovalues = {0.2f, 0.5f, 0.8f};
  r.view = Perspective({-30, 70, 40});
  auto a = ExtractRetaining(*h, kXf, r, cut);
  EXPECT_TRUE(a.ok()) << a.status();
  return a.ok() ? std::move(*a) : ExtractResult{};
}

// A view that orders the triangles differently: the test above compares something.
TEST(RetainedCut, AnotherViewChangesTheOrder) {
  RetainedCut cut;
  const ExtractResult a = RetainBlobs(&cut);
  auto b = Reorder(cut, Perspective({70, -30, -20}));
  ASSERT_TRUE(b.ok());
  ASSERT_EQ(a.mesh.triangle_count(), b->mesh.triangle_count());
  size_t moved = 0;
  for (size_t t = 0; t < a.mesh.triangle_count(); ++t)
    moved += Corners(a.mesh, t) != Corners(b->mesh, t);
  EXPECT_GT(moved, a.mesh.triangle_count() / 2);
}

// A cut recorded by an unordered frame of several surfaces keeps what orders a leaf's
// components (its gradient), which that frame had no use for: a later sorted view re-ordered
// from it draws as a fresh extraction does.
TEST(RetainedCut, RecordedUnorderedThenSortedForAView) {
  static const HierarchyPtr h = testing::MakeHierarchy(5, BlobsField);
  const int mid = h->n() / 2;
  for (const bool blocks : {true, false}) {
    ExtractRequest r;
    r.isovalues = {0.45f, 0.5f, 0.55f};  // close: many leaves cross two or three
    r.eps = blocks ? 0.0 : 0.05 * h->eta(mid, mid, mid);
    r.view = Perspective({-30, 70, 40});
    r.order = DrawOrder::kNone;
    r.blocks = blocks;
    RetainedCut cut;
    auto unordered = ExtractRetaining(*h, kXf, r, &cut);
    ASSERT_TRUE(unordered.ok()) << unordered.status();
    for (const View& view : {Perspective({70, -30, -20}), Orthographic({0.3, -1.0, 0.2})}) {
      ExtractRequest sorted = r;
      sorted.view = view;
      sorted.order = DrawOrder::kBackToFront;
      auto fresh = Extract(*h, kXf, sorted);
      ASSERT_TRUE(fresh.ok()) << fresh.status();
      auto reordered = Reorder(cut, view, DrawOrder::kBackToFront);
      ASSERT_TRUE(reordered.ok()) << reordered.status();
      ExpectSameDrawing(fresh->mesh, reordered->mesh, blocks ? "blocks" : "node by node");
    }
  }
}

// The observer hears of the re-ordered frame in contiguous prefixes, a few thousand triangles
// at a time, as it does for an extraction: a stream cuts its first chunk from the first ones.
TEST(RetainedCut, ObserverSeesContiguousPrefixes) {
  RetainedCut cut;
  RetainBlobs(&cut);
  ASSERT_GT(cut.triangle_count(), 3 * 4096u);
  std::vector<std::pair<size_t, size_t>> ranges;
  ExtractObserver observer;
  observer.on_ready = [&](const OrderedMesh& m, size_t first, size_t end) {
    EXPECT_LE(end, m.triangle_count());
    ranges.push_back({first, end});
  };
  auto b = Reorder(cut, Perspective({70, -30, -20}), DrawOrder::kBackToFront, &observer);
  ASSERT_TRUE(b.ok());
  ASSERT_GE(ranges.size(), 3u);
  size_t expected_first = 0;
  for (const auto& [first, end] : ranges) {
    EXPECT_EQ(first, expected_first);
    EXPECT_GT(end, first);
    expected_first = end;
  }
  EXPECT_EQ(expected_first, b->mesh.triangle_count());
  EXPECT_LT(ranges[0].second, 4096u + 64);  // the first prefix is small

  // A stop heard part way (a newer view) ends the walk at the next prefix.
  std::atomic<bool> cancel{false};
  size_t reports = 0;
  observer.cancel = &cancel;
  observer.on_ready = [&](const OrderedMesh&, size_t, size_t) {
    ++reports;
    cancel = true;
  };
  auto stopped = Reorder(cut, Perspective({70, -30, -20}), DrawOrder::kBackToFront, &observer);
  EXPECT_EQ(stopped.status().code(), absl::StatusCode::kCancelled);
  EXPECT_EQ(reports, 1u);
}

TEST(RetainedCut, ServesOnlyTheSameMesh) {
  const auto h = testing::MakeHierarchy(4, SphereField);
  ExtractRequest r;
  r.isovalues = {0.5f, 0.7f};
  r.eps = 0.01;
  r.view = Perspective({40, 40, 40});
  RetainedCut cut;
  EXPECT_FALSE(cut.Serves(r));  // nothing retained yet
  ASSERT_TRUE(ExtractRetaining(*h, GridToWorld{}, r, &cut).ok());
  EXPECT_TRUE(cut.Serves(r));
  ExtractRequest other = r;
  other.eps = 0.02;
  EXPECT_FALSE(cut.Serves(other));
  other = r;
  other.isovalues = {0.7f, 0.5f};  // surfaces numbered otherwise
  EXPECT_FALSE(cut.Serves(other));
  other = r;
  other.normals = NormalMode::kFlat;
  EXPECT_FALSE(cut.Serves(other));
  other = r;
  other.budget = 500;
  EXPECT_FALSE(cut.Serves(other));
  EXPECT_TRUE(cut.Serves(other, 0.01));  // a budget whose remembered eps is the cut's
  // ... but a remembered eps says nothing of a request for another eps.
  ExtractRequest other_eps = r;
  other_eps.eps = 0.02;
  EXPECT_FALSE(cut.Serves(other_eps, 0.01));
  // ... for the same surfaces only: a session alternating isovalue sets under a budget the
  // whole mesh fits (eps 0 for both) must not be served the other set's mesh.
  other.isovalues = {0.7f, 0.5f};
  EXPECT_FALSE(cut.Serves(other, 0.01));
  other.isovalues = {0.5f, 0.8f};
  EXPECT_FALSE(cut.Serves(other, 0.01));
  other.isovalues = r.isovalues;
  other.normals = NormalMode::kFlat;
  EXPECT_FALSE(cut.Serves(other, 0.01));

  // A budget request is served by a cut of the same budget.
  ExtractRequest budget = r;
  budget.budget = 300;
  ASSERT_TRUE(ExtractRetaining(*h, GridToWorld{}, budget, &cut).ok());
  EXPECT_TRUE(cut.Serves(budget));
  EXPECT_FALSE(cut.Serves(r));
}

// One surface of a small sphere, seen from outside.
ExtractRequest SphereRequest() {
  ExtractRequest r;
  r.isovalues = {0.5f};
  r.view = Perspective({40, 40, 40});
  return r;
}

TEST(RetainedCut, BadViewsAndStoppedExtractionsGiveClearErrors) {
  const auto h = testing::MakeHierarchy(4, SphereField);
  const ExtractRequest r = SphereRequest();
  RetainedCut cut;
  auto none = Reorder(cut, r.view);
  EXPECT_EQ(none.status().code(), absl::StatusCode::kFailedPrecondition);
  ASSERT_TRUE(ExtractRetaining(*h, GridToWorld{}, r, &cut).ok());
  auto zero = Reorder(cut, Orthographic({0, 0, 0}));
  EXPECT_EQ(zero.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(zero.status().message().find("view direction is zero"), std::string::npos);
  auto nan = Reorder(cut, Perspective({std::nan(""), 0, 0}));
  EXPECT_EQ(nan.status().code(), absl::StatusCode::kInvalidArgument);

  std::atomic<bool> cancel{true};
  ExtractObserver observer;
  observer.cancel = &cancel;
  // Cancelled before it began: nothing is drawn, so the observer hears of no prefix.
  size_t prefixes = 0;
  observer.on_ready = [&](const OrderedMesh&, size_t, size_t) { ++prefixes; };
  auto cancelled = Reorder(cut, r.view, DrawOrder::kBackToFront, &observer);
  EXPECT_EQ(cancelled.status().code(), absl::StatusCode::kCancelled);
  EXPECT_EQ(prefixes, 0u);
  observer.on_ready = nullptr;
  // An extraction that stops keeps nothing.
  auto stopped = Extract(*h, GridToWorld{}, r, &observer, &cut);
  EXPECT_EQ(stopped.status().code(), absl::StatusCode::kCancelled);
  EXPECT_FALSE(cut.Serves(r));
  EXPECT_EQ(Reorder(cut, r.view).status().code(), absl::StatusCode::kFailedPrecondition);
}

// A cut serves views only once it holds the frame it recorded: until the caller hands that
// frame back, or when it hands another, re-ordering is refused.
TEST(RetainedCut, ServesOnlyOnceItKeepsTheFrameItRecorded) {
  const auto h = testing::MakeHierarchy(4, SphereField);
  const ExtractRequest r = SphereRequest();
  RetainedCut cut;
  auto first = Extract(*h, GridToWorld{}, r, nullptr, &cut);
  ASSERT_TRUE(first.ok());
  ASSERT_GT(first->mesh.triangle_count(), 1u);
  EXPECT_FALSE(cut.Serves(r));
  EXPECT_EQ(Reorder(cut, r.view).status().code(), absl::StatusCode::kFailedPrecondition);
  OrderedMesh shorter = first->mesh;
  shorter.surface.pop_back();
  shorter.triangles.resize(shorter.triangles.size() - 3);
  EXPECT_FALSE(cut.KeepMesh(std::move(shorter)));
  EXPECT_FALSE(cut.Serves(r));
  EXPECT_FALSE(cut.KeepMesh(OrderedMesh(first->mesh)));  // cleared: nothing recorded now

  // Nor one with the recorded triangles on other vertices (one more, unused).
  auto recorded = Extract(*h, GridToWorld{}, r, nullptr, &cut);
  ASSERT_TRUE(recorded.ok());
  OrderedMesh more_vertices = recorded->mesh;
  more_vertices.positions.insert(more_vertices.positions.end(), {0.0f, 0.0f, 0.0f});
  more_vertices.normals.insert(more_vertices.normals.end(), {0.0f, 0.0f, 1.0f});
  EXPECT_FALSE(cut.KeepMesh(std::move(more_vertices)));
  EXPECT_FALSE(cut.Serves(r));

  auto second = Extract(*h, GridToWorld{}, r, nullptr, &cut);
  ASSERT_TRUE(second.ok());
  const OrderedMesh frame = second->mesh;
  EXPECT_TRUE(cut.KeepMesh(std::move(second->mesh)));
  EXPECT_TRUE(cut.Serves(r));
  auto same_view = Reorder(cut, r.view);
  ASSERT_TRUE(same_view.ok());
  EXPECT_EQ(same_view->mesh.triangles, frame.triangles);
  EXPECT_EQ(same_view->mesh.positions, frame.positions);
}

// Three surfaces of the Cayley field, seen from outside, on two threads.
ExtractRequest ThreeCayleySurfaces() {
  ExtractRequest r;
  r.isovalues = {-0.3f, 0.05f, 0.4f};
  r.view = Perspective({-30, 70, 40});
  r.threads = 2;
  return r;
}

// A recording asks for each growth of its buffers as it happens: granted, it asks for what its
// tree holds; refused, it stops and the cut is released, the frame itself drawn all the same.
TEST(RetainedCut, AsksForRoomAsItsRecordsGrow) {
  const auto h = testing::MakeHierarchy(5, CayleyField);
  const ExtractRequest r = ThreeCayleySurfaces();
  RetainedCut cut;
  std::atomic<int64_t> granted{0};
  cut.SetReserve([&](int64_t bytes) {
    granted += bytes;
    return true;
  });
  auto kept = Extract(*h, kXf, r, nullptr, &cut);
  ASSERT_TRUE(kept.ok());
  // The subtrees' records are asked for; the split's few above them are not.
  EXPECT_GT(granted.load(), int64_t(cut.tree_bytes()) / 2);
  EXPECT_LE(granted.load(), int64_t(cut.tree_bytes()));
  EXPECT_TRUE(cut.KeepMesh(OrderedMesh(kept->mesh)));

  RetainedCut refused;
  std::atomic<int> asked{0};
  refused.SetReserve([&](int64_t) {
    ++asked;
    return false;
  });
  auto drawn = Extract(*h, kXf, r, nullptr, &refused);
  ASSERT_TRUE(drawn.ok());
  EXPECT_EQ(drawn->mesh.triangles, kept->mesh.triangles);
  EXPECT_EQ(drawn->mesh.positions, kept->mesh.positions);
  EXPECT_GE(asked.load(), 1);
  EXPECT_LE(asked.load(), 2);  // once per worker at most: they stop recording
  EXPECT_EQ(refused.tree_bytes(), 0u);
  EXPECT_FALSE(refused.KeepMesh(std::move(drawn->mesh)));
  EXPECT_FALSE(refused.Serves(r));
  // Released, the cut still asks: the next frame's recording is refused again, not granted
  // without a word.
  const int asked_before = asked.load();
  auto again = Extract(*h, kXf, r, nullptr, &refused);
  ASSERT_TRUE(again.ok());
  EXPECT_GT(asked.load(), asked_before);
  EXPECT_EQ(refused.tree_bytes(), 0u);
}

// What a cut holds: its tree and the kept frame's mesh, all of it (a daemon charges its
// retained memory by this); cleared, the mesh is freed and the tree's buffers do not grow from
// one frame to the next.
TEST(RetainedCut, MemoryIsTheTreeAndTheWholeMesh) {
  const auto h = testing::MakeHierarchy(5, CayleyField);
  const ExtractRequest r = ThreeCayleySurfaces();
  RetainedCut cut;
  auto res = ExtractRetaining(*h, kXf, r, &cut);
  ASSERT_TRUE(res.ok());
  const OrderedMesh& m = res->mesh;
  ASSERT_GT(m.normals.size(), 0u);
  const size_t mesh_bytes = (m.positions.size() + m.normals.size()) * sizeof(float) +
                            m.triangles.size() * sizeof(uint32_t) + m.surface.size();
  EXPECT_GE(cut.memory_bytes(), cut.tree_bytes() + mesh_bytes);
  cut.Clear();
  EXPECT_EQ(cut.memory_bytes(), cut.tree_bytes());
  // The same frame recorded again and again into the cut: its buffers are reused.
  ASSERT_TRUE(ExtractRetaining(*h, kXf, r, &cut).ok());
  const size_t tree = cut.tree_bytes();
  for (int i = 0; i < 40; ++i) ASSERT_TRUE(ExtractRetaining(*h, kXf, r, &cut).ok());
  EXPECT_EQ(cut.tree_bytes(), tree);
  auto reordered = Reorder(cut, Perspective({70, -30, -20}));
  ASSERT_TRUE(reordered.ok());
  EXPECT_GE(reordered->stats.total_ms, reordered->stats.extract_ms);
  EXPECT_GT(reordered->stats.extract_ms, 0.0);
}

}  // namespace
}  // namespace isostream
