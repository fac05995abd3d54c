// PNG encode/decode round trips exactly, and anything that is not a whole valid PNG is refused
// with a status rather than a crash or a partial image.
#include <gtest/gtest.h>

#include <cstdio>
#include <string>

#include "client/render/image.h"

namespace isostream::render {
namespace {

Image Pattern(int width, int height) {
  Image image;
  image.width = width;
  image.height = height;
  image.rgba.resize(4 * size_t(width) * size_t(height));
  // Every byte value appears, and neighbouring rows differ, so a flipped or shifted row shows.
  for (size_t i = 0; i < image.rgba.size(); ++i) image.rgba[i] = uint8_t((i * 37 + i / 97) & 0xFF);
  return image;
}

std::string EncodeOrDie(const Image& image) {
  std::string bytes;
  const absl::Status status = EncodePng(image, &bytes);
  EXPECT_TRUE(status.ok()) << status;
  return bytes;
}

TEST(PngTest, RoundTripInMemoryIsExact) {
  const Image image = Pattern(37, 23);
  const std::string bytes = EncodeOrDie(image);
  ASSERT_GT(bytes.size(), 8u);
  absl::StatusOr<Image> decoded = DecodePng(bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  EXPECT_EQ(decoded->width, 37);
  EXPECT_EQ(decoded->height, 23);
  EXPECT_EQ(decoded->rgba, image.rgba);
}

TEST(PngTest, RoundTripThroughFileIsExact) {
  const Image image = Pattern(64, 3);
  const std::string path = ::testing::TempDir() + "/render_png_round_trip.png";
  ASSERT_TRUE(WritePng(image, path).ok());
  absl::StatusOr<Image> read = ReadPng(path);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(read->rgba, image.rgba);
  std::remove(path.c_str());
}

TEST(PngTest, MissingFileIsNotFoundAndNamed) {
  const std::string path = ::testing::TempDir() + "/render_no_such_file.png";
  absl::StatusOr<Image> read = ReadPng(path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(read.status().message().find("render_no_such_file.png"), std::string::npos);
}

TEST(PngTest, RejectsEmptyAndForeignBytes) {
  EXPECT_EQ(DecodePng("").status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(DecodePng("GIF89a this is not a png at all").status().code(),
            absl::StatusCode::kInvalidArgument);
}

TEST(PngTest, RejectsTruncatedFile) {
  const std::string bytes = EncodeOrDie(Pattern(40, 40));
  for (size_t keep : {size_t(8), size_t(33), bytes.size() / 2, bytes.size() - 13}) {
    absl::StatusOr<Image> decoded = DecodePng(std::string_view(bytes).substr(0, keep));
    EXPECT_EQ(decoded.status().code(), absl::StatusCode::kInvalidArgument) << "kept " << keep;
  }
}

TEST(PngTest, RejectsCorruptedChunk) {
  std::string bytes = EncodeOrDie(Pattern(40, 40));
  // Byte 20 lies inside the IHDR chunk's data (width/height), so its CRC no longer matches.
  bytes[20] = char(bytes[20] ^ 0x5A);
  EXPECT_EQ(DecodePng(bytes).status().code(), absl::StatusCode::kInvalidArgument);
  std::string body = EncodeOrDie(Pattern(40, 40));
  body[body.size() / 2] = char(body[body.size() / 2] ^ 0xFF);  // inside IDAT
  EXPECT_FALSE(DecodePng(body).ok());
}

TEST(PngTest, EncodeRefusesInconsistentImage) {
  Image image = Pattern(4, 4);
  image.rgba.pop_back();
  std::string bytes;
  EXPECT_EQ(EncodePng(image, &bytes).code(), absl::StatusCode::kInvalidArgument);
  Image empty;
  EXPECT_EQ(EncodePng(empty, &bytes).code(), absl::StatusCode::kInvalidArgument);
}

TEST(MeanAbsoluteDifferenceTest, ZeroOneAndMismatch) {
  Image black = Pattern(5, 5), white = Pattern(5, 5);
  for (size_t i = 0; i < black.rgba.size(); ++i) {
    black.rgba[i] = (i % 4 == 3) ? 7 : 0;  // alpha differs and must not count
    white.rgba[i] = 255;
  }
  EXPECT_DOUBLE_EQ(MeanAbsoluteDifference(black, black), 0.0);
  EXPECT_DOUBLE_EQ(MeanAbsoluteDifference(black, white), 1.0);
  Image one_off = black;
  one_off.pixel(2, 3)[1] = 255;  // one channel of one pixel of 25
  EXPECT_NEAR(MeanAbsoluteDifference(black, one_off), 1.0 / 75.0, 1e-12);
  EXPECT_LT(MeanAbsoluteDifference(black, Pattern(5, 6)), 0.0);
}

// An orbit's numbered files sort in view order: as many digits as its last view needs (out_999
// sorted after out_1000 in a listing or a glob).
TEST(NumberedPngPathTest, DigitsFollowTheOrbitsLength) {
  EXPECT_EQ(NumberedPngPath("o.png", 7, 3), "o_007.png");
  EXPECT_EQ(NumberedPngPath("o.png", 999, 1000), "o_999.png");
  EXPECT_EQ(NumberedPngPath("o.png", 7, 1001), "o_0007.png");
  EXPECT_EQ(NumberedPngPath("o.png", 1000, 1001), "o_1000.png");
  EXPECT_EQ(NumberedPngPath("dir.v2/o", 12, 12000), "dir.v2/o_00012.png");
}

}  // namespace
}  // namespace isostream::render
