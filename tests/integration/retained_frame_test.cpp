// A stream's retained frame (server/service/retained_frame.h): recorded, kept within the
// daemon's budget, freed.
#include "server/service/retained_frame.h"

#include <gtest/gtest.h>

#include <chrono>
#include <string>
#include <vector>

#include "server/service/catalogue.h"
#include "server/service/frame_producer.h"
#include "tests/integration/daemon_process.h"

namespace isostream::service {
namespace {

using testing::ScratchDir;

// A stream's retained frame: recorded unless the stream slides through meshes, charged to the
// daemon's budget for what it holds, freed when the stream draws another mesh or the budget
// has no room, and never kept from a frame that did not finish.
// buckyball:65 served as the daemon serves it, and one request for two of its shells.
class RetainedFrameTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto volume = catalogue_.Get("buckyball:65");
    ASSERT_TRUE(volume.ok()) << volume.status();
    volume_ = *volume;
    r.isovalues = {0.05f, 0.15f};
    r.eps = 0.004;
    r.view.eye = {3, 2, 1};
  }
  // Extracts r, recording into `cut` if given; returns the triangle count. The frame stays in
  // `frame_`, for RetainedFrame::EndRecording.
  int64_t extract(RetainedCut* cut = nullptr) {
    auto res = Extract(*v().prepared.hierarchy, v().prepared.grid_to_world, r, nullptr, cut);
    EXPECT_TRUE(res.ok());
    if (!res.ok()) return 0;
    frame_ = std::move(res->mesh);
    return res->stats.triangles;
  }
  const ServedVolume& v() const { return *volume_; }

  VolumeCatalogue catalogue_{CatalogueOptions{}};
  ServedVolumePtr volume_;
  ExtractRequest r;
  OrderedMesh frame_;  // the last extraction's
};

TEST_F(RetainedFrameTest, RecordsKeepsAndFreesWithinTheBudget) {
  const ServedVolume& v = this->v();

  RetainBudget budget(int64_t{256} << 20);
  {
    RetainedFrame frame(&budget);
    RetainedCut* cut = frame.StartRecording(v, r);  // a session's first frame is recorded
    ASSERT_NE(cut, nullptr);
    const int64_t triangles = extract(cut);
    frame.EndRecording(v, &frame_);
    frame.Drew(v, r, triangles);
    ASSERT_NE(frame.Find(v, r), nullptr);
    EXPECT_EQ(budget.used(), int64_t(frame.Find(v, r)->memory_bytes()));
    EXPECT_GT(budget.used(), 32 * triangles);
    // The next frame of this size is estimated at what this one held, not less.
    EXPECT_GE(budget.Estimate(triangles), budget.used());

    // A frame that did not finish is not kept, and what was held stays charged until freed.
    ASSERT_NE(frame.StartRecording(v, r), nullptr);
    frame.EndRecording(v, nullptr);
    EXPECT_EQ(frame.Find(v, r), nullptr);
    EXPECT_GT(budget.used(), 0);

    // Another mesh drawn: the old one is freed.
    ExtractRequest other = r;
    other.eps = 0.008;
    frame.Drew(v, other, 1000);
    EXPECT_EQ(budget.used(), 0);
    EXPECT_EQ(frame.Find(v, r), nullptr);
    frame.Drew(v, r, triangles);
    cut = frame.StartRecording(v, r);
    ASSERT_NE(cut, nullptr);
    extract(cut);
    frame.EndRecording(v, &frame_);
    EXPECT_NE(frame.Find(v, r), nullptr);
  }
  EXPECT_EQ(budget.used(), 0);  // the stream's end gives everything back

  // No room in the budget: nothing is recorded, nothing stays charged.
  RetainBudget small(4096);
  RetainedFrame frame(&small);
  frame.Drew(v, r, 50000);
  EXPECT_EQ(frame.StartRecording(v, r), nullptr);
  EXPECT_EQ(small.used(), 0);
  // An estimate that fits but a frame that does not: the recording stops once its records
  // outgrow the budget, never holding much past it, and nothing is kept.
  int64_t tree = 0;
  {
    RetainBudget roomy(int64_t{1} << 40);
    RetainedFrame sizing(&roomy);
    RetainedCut* full = sizing.StartRecording(v, r);
    ASSERT_NE(full, nullptr);
    extract(full);
    tree = int64_t(full->tree_bytes());
  }
  RetainBudget tight(tree / 2);
  RetainedFrame tight_frame(&tight);
  tight_frame.Drew(v, r, 100);
  RetainedCut* cut = tight_frame.StartRecording(v, r);
  ASSERT_NE(cut, nullptr);
  extract(cut);
  EXPECT_LE(tight.used(), tight.limit());
  EXPECT_EQ(cut->tree_bytes(), 0u);  // released when refused room
  tight_frame.EndRecording(v, &frame_);
  EXPECT_EQ(tight_frame.Find(v, r), nullptr);
  EXPECT_EQ(tight.used(), 0);
}

// A stream sliding through meshes (each refined frame of another mesh than the one before)
// records nothing from its third mesh on; back on one mesh, it records again.
TEST_F(RetainedFrameTest, SlidingThroughMeshesRecordsNothing) {
  const ServedVolume& v = this->v();
  RetainBudget budget(int64_t{256} << 20);
  RetainedFrame frame(&budget);
  // Draws r at `eps` as FrameProducer does; true if the frame was recorded.
  auto draw = [&](double eps) {
    r.eps = eps;
    RetainedCut* cut = frame.StartRecording(v, r);
    const int64_t triangles = extract(cut);
    if (cut) frame.EndRecording(v, &frame_);
    frame.Drew(v, r, triangles);
    return cut != nullptr;
  };
  EXPECT_TRUE(draw(0.004));  // a session's first mesh
  EXPECT_TRUE(draw(0.005));  // one change: a new mesh to look around
  EXPECT_NE(frame.Find(v, r), nullptr);
  EXPECT_FALSE(draw(0.006));    // sliding
  EXPECT_EQ(budget.used(), 0);  // the last recorded mesh was freed
  EXPECT_FALSE(draw(0.007));
  EXPECT_TRUE(draw(0.007));  // the same mesh again: recorded, the next view is re-ordered
  EXPECT_NE(frame.Find(v, r), nullptr);
  EXPECT_TRUE(draw(0.004));  // a new mesh after a settled one
  EXPECT_NE(frame.Find(v, r), nullptr);
}

// When the budget has no room for a stream's frame, the least recently used frames of other
// streams are freed, unless their streams are using them right now.
TEST_F(RetainedFrameTest, FreesOtherStreamsFramesLeastRecentlyUsedFirst) {
  const ServedVolume& v = this->v();
  // Records a frame of r into `frame` (its second view of the mesh); true if it is kept.
  auto retain = [&](RetainedFrame& frame) {
    frame.Drew(v, r, extract());
    RetainedCut* cut = frame.StartRecording(v, r);
    if (cut == nullptr) return false;
    extract(cut);
    frame.EndRecording(v, &frame_);
    return frame.Find(v, r) != nullptr;
  };
  RetainedFrame probe(nullptr);  // no budget: never records
  EXPECT_FALSE(retain(probe));
  // Room for two frames of this mesh, not three.
  RetainBudget sizing(int64_t{1} << 40);
  int64_t one = 0;
  {
    RetainedFrame frame(&sizing);
    ASSERT_TRUE(retain(frame));
    one = sizing.used();
  }
  RetainBudget budget(one * 5 / 2);
  RetainedFrame a(&budget), b(&budget), c(&budget);
  ASSERT_TRUE(retain(a));
  ASSERT_TRUE(retain(b));
  a.Find(v, r);  // a is used again: b is now the least recently used
  ASSERT_TRUE(retain(c));
  EXPECT_NE(a.Find(v, r), nullptr);
  EXPECT_EQ(b.Find(v, r), nullptr);
  EXPECT_LE(budget.used(), budget.limit());
  // A frame no eviction could make room for frees nothing.
  RetainedFrame huge(&budget);
  huge.Drew(v, r, int64_t{1} << 32);  // its next frame is estimated past the whole budget
  EXPECT_EQ(huge.StartRecording(v, r), nullptr);
  EXPECT_NE(a.Find(v, r), nullptr);
  EXPECT_NE(c.Find(v, r), nullptr);
  // When the frames that could be freed are not enough, none is freed: with a in
  // use, a frame estimated at two of these cannot fit even without c, so c must stay.
  {
    std::lock_guard<std::mutex> using_a_only(a.mutex());
    RetainedFrame d(&budget);
    d.Drew(v, r, 2 * extract());
    EXPECT_EQ(d.StartRecording(v, r), nullptr);
    EXPECT_NE(c.Find(v, r), nullptr);
  }
  // A frame whose stream is using it is not freed: with a and c in use, b finds no room.
  std::lock_guard<std::mutex> using_a(a.mutex());
  std::lock_guard<std::mutex> using_c(c.mutex());
  EXPECT_FALSE(retain(b));
  EXPECT_NE(a.Find(v, r), nullptr);
  EXPECT_NE(c.Find(v, r), nullptr);
  // The same volume prepared again (another catalogue: another hierarchy, the
  // first still alive) is another mesh: a's frame must not serve it.
  {
    VolumeCatalogue other{CatalogueOptions{}};
    auto again = other.Get("buckyball:65");
    ASSERT_TRUE(again.ok());
    ASSERT_NE((*again)->prepared.hierarchy, v.prepared.hierarchy);
    EXPECT_EQ(a.Find(**again, r), nullptr);
  }
}

}  // namespace
}  // namespace isostream::service
