// The LEB128 varint under the Draco header reader and the rANS symbol stream: edge values
// round-trip in the fewest bytes, and truncated, over-long or overflowing encodings are refused
// without reading past the buffer or moving the cursor.
#include "shared/internal/varint.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace isostream {
namespace {

using internal::GetVarint32;
using internal::PutVarint32;

// A heap copy of exactly `bytes`, so that AddressSanitizer would catch a read one past it.
std::unique_ptr<uint8_t[]> Exact(const std::vector<uint8_t>& bytes) {
  auto out = std::make_unique<uint8_t[]>(bytes.size());
  std::copy(bytes.begin(), bytes.end(), out.get());
  return out;
}

TEST(Varint, EdgeValuesRoundTripInTheFewestBytes) {
  const struct {
    uint32_t value;
    std::vector<uint8_t> bytes;
  } cases[] = {
      {0, {0x00}},
      {127, {0x7f}},
      {128, {0x80, 0x01}},
      {16383, {0xff, 0x7f}},
      {16384, {0x80, 0x80, 0x01}},
      {0xffffffffu, {0xff, 0xff, 0xff, 0xff, 0x0f}},
  };
  for (const auto& c : cases) {
    std::string out = "ab";
    PutVarint32(c.value, &out);
    EXPECT_EQ(out, "ab" + std::string(c.bytes.begin(), c.bytes.end())) << c.value;
    const auto* data = reinterpret_cast<const uint8_t*>(out.data());
    size_t at = 2;
    uint32_t v = 12345;
    ASSERT_TRUE(GetVarint32(data, out.size(), &at, &v)) << c.value;
    EXPECT_EQ(v, c.value);
    EXPECT_EQ(at, out.size());
  }
}

TEST(Varint, ConsecutiveValuesReadInOrder) {
  std::string out;
  const uint32_t values[] = {0, 127, 128, 300, 0xffffffffu, 1};
  for (uint32_t v : values) PutVarint32(v, &out);
  const auto* data = reinterpret_cast<const uint8_t*>(out.data());
  size_t at = 0;
  for (uint32_t expected : values) {
    uint32_t v = 0;
    ASSERT_TRUE(GetVarint32(data, out.size(), &at, &v));
    EXPECT_EQ(v, expected);
  }
  EXPECT_EQ(at, out.size());
}

// A refused varint leaves the cursor and the value alone.
void ExpectRefused(const std::vector<uint8_t>& bytes, size_t size, const char* what) {
  const auto data = Exact(bytes);
  size_t at = 0;
  uint32_t v = 12345;
  EXPECT_FALSE(GetVarint32(data.get(), size, &at, &v)) << what;
  EXPECT_EQ(at, 0u) << what;
  EXPECT_EQ(v, 12345u) << what;
}

TEST(Varint, TruncatedInputIsRefused) {
  ExpectRefused({}, 0, "empty");
  ExpectRefused({0x80}, 1, "one continuation byte");
  ExpectRefused({0xff, 0xff, 0xff, 0xff}, 4, "2^32-1 without its last byte");
  // The size bounds the read, not the bytes behind it: a terminating byte past `size` is not
  // looked at.
  ExpectRefused({0x80, 0x01}, 1, "end before the terminating byte");
  // A cursor at or past the end reads nothing.
  const auto data = Exact({0x05});
  for (size_t start : {size_t{1}, size_t{7}}) {
    size_t at = start;
    uint32_t v = 0;
    EXPECT_FALSE(GetVarint32(data.get(), 1, &at, &v));
    EXPECT_EQ(at, start);
  }
}

TEST(Varint, MoreThanFiveBytesAreRefused) {
  // Six bytes even though the value (0) would fit: a sixth byte is never read as part of it.
  ExpectRefused({0x80, 0x80, 0x80, 0x80, 0x80, 0x00}, 6, "6 bytes for 0");
  ExpectRefused({0xff, 0xff, 0xff, 0xff, 0x8f, 0x00}, 6, "6 bytes for 2^32-1");
}

TEST(Varint, ValuesOverflowing32BitsInTheFifthByteAreRefused) {
  // The 5th byte carries bits 28..34: only its low four fit in a uint32.
  ExpectRefused({0xff, 0xff, 0xff, 0xff, 0x10}, 5, "2^32 + 2^28 - 1");
  ExpectRefused({0x80, 0x80, 0x80, 0x80, 0x7f}, 5, "bits 32..34 set");
  ExpectRefused({0x80, 0x80, 0x80, 0x80, 0x10}, 5, "2^32");
  // The largest 5th byte that fits still reads.
  const auto data = Exact({0x80, 0x80, 0x80, 0x80, 0x0f});
  size_t at = 0;
  uint32_t v = 0;
  ASSERT_TRUE(GetVarint32(data.get(), 5, &at, &v));
  EXPECT_EQ(v, 0xf0000000u);
  EXPECT_EQ(at, 5u);
}

// Not the shortest form, but within 5 bytes: accepted, as Draco's own reader accepts it.
TEST(Varint, ZeroPaddedEncodingsWithinFiveBytesRead) {
  const auto data = Exact({0x81, 0x80, 0x00});
  size_t at = 0;
  uint32_t v = 0;
  ASSERT_TRUE(GetVarint32(data.get(), 3, &at, &v));
  EXPECT_EQ(v, 1u);
  EXPECT_EQ(at, 3u);
}

}  // namespace
}  // namespace isostream
