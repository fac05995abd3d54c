// Notes beside a surprising frame (shared/frame_notes.h).
#include "shared/frame_notes.h"

#include <gtest/gtest.h>

#include <cmath>

namespace isostream {
namespace {

// A surface bounds the samples at or above its isovalue: none at the lowest value (nothing lies
// below it), one at the highest (around the samples there), none outside.
TEST(FrameNotes, AnIsovalueWithoutASurfaceIsSaidWhy) {
  EXPECT_EQ(IsovalueOutsideNote(0, 0, 1, "mask"),
            "isovalue 0 is mask's lowest value: no sample lies below it, so no surface bounds it");
  EXPECT_EQ(IsovalueOutsideNote(1, 0, 1, "mask"), "");
  EXPECT_EQ(IsovalueOutsideNote(0.5f, 0, 1, "mask"), "");
  EXPECT_EQ(IsovalueOutsideNote(std::nextafter(0.0f, 1.0f), 0, 1, "mask"), "");
  EXPECT_EQ(IsovalueOutsideNote(-1, 0, 1, "mask"),
            "isovalue -1 lies outside mask's values [0, 1]: no surface for it");
  EXPECT_NE(IsovalueOutsideNote(2, 0, 1, "mask"), "");
  EXPECT_NE(IsovalueOutsideNote(3, 3, 3, "constant"), "");  // one value: no surface at all
}

TEST(FrameNotes, ValuesFewFloatStepsApartAreSaid) {
  // float64 data 1e6 + 0.01 r held as floats: two values, one step apart.
  EXPECT_EQ(CoarseValuesNote(1e6f, 1e6f + 0.0625f, "v"),
            "v's values [1e+06, 1000000.06] are 1 float step apart: far from 0, single precision "
            "keeps few values (surfaces step between them); subtract an offset such as 1e+06 "
            "before storing");
  const float below_zero = -1e6f;
  EXPECT_NE(CoarseValuesNote(below_zero - 0.25f, below_zero, "v").find("are 4 float steps"),
            std::string::npos);
  // Just under the threshold, and at it.
  const float just = std::nextafter(1.0f, 2.0f) - 1.0f;  // one step at 1
  EXPECT_NE(CoarseValuesNote(1.0f, 1.0f + float(kCoarseValueSteps - 1) * just, "v"), "");
  EXPECT_EQ(CoarseValuesNote(1.0f, 1.0f + float(kCoarseValueSteps) * just, "v"), "");
  // Ordinary ranges, ranges across 0, one value: nothing to say.
  EXPECT_EQ(CoarseValuesNote(0.0f, 255.0f, "v"), "");
  EXPECT_EQ(CoarseValuesNote(1000.0f, 1010.0f, "v"), "");
  EXPECT_EQ(CoarseValuesNote(-1e-40f, 1e-40f, "v"), "");
  EXPECT_EQ(CoarseValuesNote(0.5f, 0.5f, "v"), "");
}

// A frame note says why a frame is over its budget, coarser than the user's budget asks, or
// empty; an ordinary frame has none.
TEST(FrameNotes, FramesThatLookWrongAreSaidWhy) {
  // Over the budget: the coarsest mesh. Exactly at it fits.
  EXPECT_EQ(FrameNote(12, 10, 10, 2.5, true),
            "the coarsest mesh (eps 2.5) has 12 triangles, over the budget of 10: no coarser "
            "mesh exists");
  EXPECT_EQ(FrameNote(10, 10, 10, 2.5, true), "");
  EXPECT_EQ(FrameNote(12, 0, 0, 2.5, true), "");  // no budget: nothing to be over
  // The daemon's frame limit fitted the frame to less than the budget: said, where that made
  // the mesh coarser (eps above 0); a frame that fits whole (eps 0) needed no lowering.
  EXPECT_EQ(FrameNote(900, 5000, 1000, 0.01, true),
            "the budget of 5000 triangles is over the daemon's frame limit: the frame was fitted "
            "to its limit of 1000 (isostreamd --max-triangles)");
  EXPECT_EQ(FrameNote(900, 5000, 1000, 0.0, true), "");
  EXPECT_EQ(FrameNote(900, 1000, 1000, 0.01, true), "");  // fitted to the user's own budget
  EXPECT_EQ(FrameNote(900, 5000, 0, 0.01, true), "");     // fitted not known
  // Empty above eps 0 with a surface in the values: the budget, or else the eps, to change.
  EXPECT_EQ(FrameNote(0, 1, 1, 4, true),
            "the mesh is empty at eps 4: the next finer mesh is over the budget of 1 triangles; "
            "a larger budget draws the surfaces");
  EXPECT_EQ(FrameNote(0, 0, 0, 4, true),
            "the mesh is empty at eps 4: a smaller eps (data units) refines the coarse "
            "tetrahedra that miss the surfaces");
  // Empty at eps 0, or with every isovalue outside the values (said by their own notes).
  EXPECT_EQ(FrameNote(0, 0, 0, 0.0, true), "");
  EXPECT_EQ(FrameNote(0, 0, 0, 4, false), "");
  EXPECT_EQ(FrameNote(0, 1, 1, 4, false), "");
  EXPECT_EQ(FrameNote(500, 1000, 1000, 0.5, true), "");
}

}  // namespace
}  // namespace isostream
