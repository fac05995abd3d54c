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

}  // namespace
}  // namespace isostream
