// A cut's records as the traversal writes them (cut_recorder.h): a refined node whose first
// child left nothing is dropped, its second child standing in its place; otherwise its record
// says where the second child's subtree starts. Leaves without triangles leave no record.
#include "server/extract/cut_recorder.h"

#include <gtest/gtest.h>

namespace isostream {
namespace {

using extract_internal::CutPart;
using extract_internal::CutRecord;

TEST(CutRecorder, ARefinementWhoseFirstChildLeftNothingIsDropped) {
  CutPart part;
  const uint32_t outer = part.AddRefine(7, TetClass{3}, true);
  // First child: refined, with nothing in its own first child and one leaf in its second.
  const uint32_t inner = part.AddRefine(-2, TetClass{4}, false);
  part.AddLeaf(0, 0);  // no triangles: no record
  EXPECT_EQ(part.records.size(), size_t(inner) + 1);
  part.SecondChildStarts(inner);
  EXPECT_EQ(part.records.size(), size_t(inner)) << "the inner refinement should be dropped";
  part.AddLeaf(0, 2);
  part.SecondChildStarts(outer);
  part.AddLeaf(2, 1);

  ASSERT_EQ(part.records.size(), 3u);
  const CutRecord& r = part.records[outer];
  EXPECT_EQ(r.kind, CutRecord::kRefine);
  EXPECT_EQ(int64_t(r.a), 7);
  EXPECT_EQ(r.c, 3);
  EXPECT_TRUE(r.child0_drawn_first);
  EXPECT_EQ(r.b, 2u) << "the second child's subtree starts after the first's leaf";
  EXPECT_EQ(part.records[1].kind, CutRecord::kLeaf);
  EXPECT_EQ(part.records[1].a, 0u);
  EXPECT_EQ(part.records[1].b, 2u);
  EXPECT_EQ(part.records[2].a, 2u);
  EXPECT_EQ(part.records[2].b, 1u);
}

// What a part holds counts its multi-surface leaves too (a daemon charges a retained cut by it).
TEST(CutRecorder, CapacityCountsRecordsAndMultiLeaves) {
  CutPart part;
  part.AddMultiLeaf({glm::dvec3(1.0, 0.0, 0.0), 0, 0.5f}, 2);
  part.AddComponent(0, 0, 1);
  part.AddComponent(1, 1, 1);
  ASSERT_GT(part.multi.capacity(), 0u);
  EXPECT_EQ(part.capacity_bytes(), part.records.capacity() * sizeof(CutRecord) +
                                       part.multi.capacity() * sizeof(extract_internal::MultiLeaf));
  EXPECT_EQ(part.records[0].kind, CutRecord::kMultiLeaf);
  EXPECT_EQ(part.records[0].b, 2u);
  EXPECT_EQ(part.records[2].c, 1);
}

}  // namespace
}  // namespace isostream
