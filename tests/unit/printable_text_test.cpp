#include "shared/printable_text.h"

#include <gtest/gtest.h>

#include <string>

namespace isostream {
namespace {

TEST(PrintableText, EscapesControlsAndBrokenUtf8AndKeepsTheRest) {
  EXPECT_EQ(PrintableText("density_1 (float)"), "density_1 (float)");
  EXPECT_EQ(PrintableText("Z\n[FAKE] pwned"), "Z\\x0a[FAKE] pwned");
  EXPECT_EQ(PrintableText("\x1b[31mred\x7f"), "\\x1b[31mred\\x7f");
  EXPECT_EQ(PrintableText(std::string("a\0b", 3)), "a\\x00b");
  EXPECT_EQ(PrintableText("C:\\vol"), "C:\\\\vol");  // so an escape in the text is not ambiguous
  EXPECT_EQ(PrintableText("dichte_\xc3\xbc \xe2\x82\xac \xf0\x9f\x99\x82"),
            "dichte_\xc3\xbc \xe2\x82\xac \xf0\x9f\x99\x82");  // ü, €, an emoji
  EXPECT_EQ(PrintableText("\xc2\x9b"
                          "2J"),
            "\\xc2\\x9b2J");  // C1 CSI, as UTF-8
  EXPECT_EQ(PrintableText("\xff\xfe"), "\\xff\\xfe");
  EXPECT_EQ(PrintableText("\xc3"), "\\xc3");                    // cut sequence
  EXPECT_EQ(PrintableText("\xc0\xaf"), "\\xc0\\xaf");           // overlong '/'
  EXPECT_EQ(PrintableText("\xed\xa0\x80"), "\\xed\\xa0\\x80");  // a surrogate
}

TEST(PrintableText, LongTextIsCut) {
  EXPECT_EQ(PrintableText(std::string(2000, 'n'), 10), "nnnnnnnnnn...");
  EXPECT_EQ(PrintableText(std::string(10, 'n'), 10), "nnnnnnnnnn");
  // An escape is not cut in the middle.
  EXPECT_EQ(PrintableText("abcdefgh\n", 10), "abcdefgh...");
  EXPECT_EQ(PrintableText(std::string(5000, 'x')).size(), 1024u + 3u);
}

}  // namespace
}  // namespace isostream
