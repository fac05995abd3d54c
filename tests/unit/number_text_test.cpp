// Numbers as tools print them and users type them back (shared/number_list.h).
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "server/extract/extractor.h"
#include "shared/number_list.h"

namespace isostream {
namespace {

TEST(NumberText, ShortestTextParsesBackToTheSameDouble) {
  std::vector<double> values = {0.1, 1.0 / 3, 2.171875, 1e-300, 5e-324, 1.7976931348623157e308,
                                -123.456, 4608.0};
  // Every eps a budget search can answer with.
  for (uint32_t code = 0; code <= kInfiniteEtaCode; code += 3) values.push_back(EtaCodeEps(code));
  for (const double v : values) {
    const std::string text = ShortestText(v);
    const absl::StatusOr<std::vector<double>> back = ParseNumberList(text, "--eps");
    ASSERT_TRUE(back.ok()) << text << ": " << back.status();
    ASSERT_EQ(back->size(), 1u);
    EXPECT_EQ((*back)[0], v) << text;
  }
  EXPECT_EQ(ShortestText(0.1), "0.1");
  EXPECT_EQ(ShortestText(2.171875), "2.171875");  // "%g" printed 2.17188, another mesh's eps
  EXPECT_EQ(ShortestText(-0.0), "0");
}

}  // namespace
}  // namespace isostream
