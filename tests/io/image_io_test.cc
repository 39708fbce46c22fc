#include "mgsr/io/image_io.h"

#include <gtest/gtest.h>

#include <cmath>

#include "mgsr/io/file_util.h"
#include "test_util.h"

namespace mgsr {
namespace {

TEST(ImageIoTest, Png8BitRoundTripIsExact) {
  const std::string dir = testing::ScratchDir();
  for (int channels : {1, 3, 4}) {
    Image im(7, 5, channels);
    for (size_t i = 0; i < im.size(); ++i)
      im.data()[i] = static_cast<float>((i * 37) % 256) / 255.0f;
    const std::string path = dir + "/im" + std::to_string(channels) + ".png";
    ASSERT_TRUE(WriteImage(path, im).ok());
    Image back;
    ASSERT_TRUE(ReadImage(path, &back).ok());
    ASSERT_TRUE(back.SameShape(im)) << channels;
    for (size_t i = 0; i < im.size(); ++i) ASSERT_NEAR(back.data()[i], im.data()[i], 1e-7) << i;
  }
}

TEST(ImageIoTest, ChannelOrderIsRgb) {
  const std::string dir = testing::ScratchDir();
  Image im(2, 2, 3);
  im.Fill(0);
  for (int y = 0; y < 2; ++y) {
    for (int x = 0; x < 2; ++x) im.at(0, y, x) = 1.0f;  // pure red
  }
  ASSERT_TRUE(WriteImage(dir + "/red.png", im).ok());
  Image back;
  ASSERT_TRUE(ReadImage(dir + "/red.png", &back).ok());
  EXPECT_FLOAT_EQ(back.at(0, 1, 1), 1.0f);
  EXPECT_FLOAT_EQ(back.at(2, 1, 1), 0.0f);
}

TEST(ImageIoTest, PfmRoundTripIsLossless) {
  const std::string dir = testing::ScratchDir();
  for (int channels : {1, 3}) {
    Image im(9, 4, channels);
    for (size_t i = 0; i < im.size(); ++i) im.data()[i] = std::sin(0.37f * i) * 1e3f;
    const std::string path = dir + "/m.pfm";
    ASSERT_TRUE(WritePfm(path, im).ok());
    Image back;
    ASSERT_TRUE(ReadPfm(path, &back).ok());
    ASSERT_TRUE(back.SameShape(im));
    for (size_t i = 0; i < im.size(); ++i) ASSERT_EQ(back.data()[i], im.data()[i]);
  }
}

TEST(ImageIoTest, BadFilesGiveClearErrors) {
  const std::string dir = testing::ScratchDir();
  Image im;
  Status s = ReadImage(dir + "/missing.png", &im);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message(), dir + "/missing.png: image file is missing");
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/junk.png", "not a png at all").ok());
  s = ReadImage(dir + "/junk.png", &im);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("cannot decode"), std::string::npos);
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/short.pfm", "Pf\n10 10\n-1.0\n1234").ok());
  s = ReadPfm(dir + "/short.pfm", &im);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("truncated"), std::string::npos);
}

TEST(ImageIoTest, DownscaleAveragesBlocks) {
  Image im(4, 2, 1);
  const float v[8] = {0, 1, 2, 3, 4, 5, 6, 7};
  std::copy(v, v + 8, im.data());
  const Image half = ResizeImage(im, 2, 1);
  EXPECT_NEAR(half.at(0, 0, 0), (0 + 1 + 4 + 5) / 4.0f, 1e-6);
  EXPECT_NEAR(half.at(0, 0, 1), (2 + 3 + 6 + 7) / 4.0f, 1e-6);
}

}  // namespace
}  // namespace mgsr
