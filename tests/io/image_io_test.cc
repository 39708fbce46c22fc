#include "mgsr/io/image_io.h"

#include <gtest/gtest.h>
#include <zlib.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <vector>

#include "mgsr/eval/image_metrics.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/scene.h"
#include "mgsr/synth/synthetic_scene.h"
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

namespace mgsr {
namespace {

// Every EXIF orientation is read from the file and undone as the tag defines it: each corner of
// a 6 x 4 photo lands where a viewer shows it.
TEST(ImageIoTest, ExifOrientationIsReadAndUndone) {
  const std::string dir = testing::ScratchDir();
  Image image(6, 4, 3);
  // Blocky quadrants so JPEG keeps them apart: top-left dark, top-right bright red, bottom-left
  // bright green, bottom-right white.
  for (int y = 0; y < 4; ++y) {
    for (int x = 0; x < 6; ++x) {
      const bool right = x >= 3, bottom = y >= 2;
      image.at(0, y, x) = right ? 1.0f : (bottom ? 0.0f : 0.1f);
      image.at(1, y, x) = bottom ? 1.0f : 0.1f;
      image.at(2, y, x) = right && bottom ? 1.0f : 0.1f;
    }
  }
  // Where the stored top-left corner appears (row, column as shown) for each orientation.
  const int shown_w[9] = {0, 6, 6, 6, 6, 4, 4, 4, 4};
  for (int o = 1; o <= 8; ++o) {
    const std::string path = testing::WriteJpegWithOrientation(dir, image, o);
    EXPECT_EQ(ExifOrientation(path), o);
    Image stored;
    ASSERT_TRUE(ReadImage(path, &stored).ok());
    EXPECT_EQ(stored.width(), 6);  // the stored grid, as COLMAP reads it
    const Image shown = ApplyExifOrientation(stored, o);
    EXPECT_EQ(shown.width(), shown_w[o]) << o;
    // The stored top-left (dark) pixel: corner per the tag (2: top-right, 3: bottom-right,
    // 4: bottom-left, 5: top-left, 6: top-right, 7: bottom-right, 8: bottom-left).
    const int w = shown.width(), h = shown.height();
    const int row[9] = {0, 0, 0, h - 1, h - 1, 0, 0, h - 1, h - 1};
    const int col[9] = {0, 0, w - 1, w - 1, 0, 0, w - 1, w - 1, 0};
    EXPECT_LT(shown.at(0, row[o], col[o]), 0.3f) << "orientation " << o;
    EXPECT_LT(shown.at(1, row[o], col[o]), 0.3f) << "orientation " << o;
  }
  const std::string png = dir + "/x.png";
  ASSERT_TRUE(WriteImage(png, image).ok());
  EXPECT_EQ(ExifOrientation(png), 1);
  EXPECT_EQ(ExifOrientation(dir + "/missing.jpg"), 1);
}

}  // namespace
}  // namespace mgsr

namespace mgsr {
namespace {

// A photo stored turned, whose camera was made from its upright view (its EXIF orientation
// honoured by the tool that posed it), loads upright; the mask stored like the photo turns too.
TEST(ImageIoTest, APhotoStoredTurnedLoadsUprightWhenItsCameraIsUpright) {
  const std::string dir = testing::ScratchDir();
  SynthOptions o = testing::SmallSynthOptions();
  o.width = 40;
  o.height = 24;
  ASSERT_TRUE(WriteSyntheticScene(o, dir).ok());
  Scene original;
  ASSERT_TRUE(LoadScene(dir, SceneOptions(), &original).ok());
  Image upright;
  ASSERT_TRUE(ReadImage(dir + "/images/v001.png", &upright).ok());
  // Stored turned a quarter (orientation 6 is undone by a clockwise turn; 8 turns the other way).
  const Image stored = ApplyExifOrientation(ExtractChannels(upright, 0, 3), 8);
  ASSERT_EQ(stored.width(), 24);
  const std::string jpeg = testing::WriteJpegWithOrientation(dir, stored, 6);
  std::filesystem::rename(jpeg, dir + "/images/v001.png");
  Image mask;
  ASSERT_TRUE(ReadImage(dir + "/masks/v001.png", &mask).ok());
  ASSERT_TRUE(WriteImage(dir + "/masks/v001.png", ApplyExifOrientation(mask, 8)).ok());
  Scene turned;
  const Status s = LoadScene(dir, SceneOptions(), &turned);
  ASSERT_TRUE(s.ok()) << s.message();
  const View& v = turned.views[1];
  EXPECT_EQ(v.image.width(), 40);
  EXPECT_GT(Psnr(v.image, original.views[1].image), 25.0);  // JPEG, not bit-exact
  EXPECT_EQ(v.mask.width(), 40);
  EXPECT_EQ(Psnr(v.mask, original.views[1].mask), std::numeric_limits<double>::infinity());
}

}  // namespace
}  // namespace mgsr

namespace mgsr {
namespace {

// A PNG written byte by byte (zlib for the data): `channels` 1 (grey) or 3 (RGB), 16 bits.
std::string Png16(const std::vector<uint16_t>& samples, int width, int height, int channels) {
  const auto u32 = [](uint32_t v) {
    return std::string{static_cast<char>(v >> 24), static_cast<char>(v >> 16),
                       static_cast<char>(v >> 8), static_cast<char>(v)};
  };
  const auto chunk = [&](const std::string& type, const std::string& data) {
    const std::string body = type + data;
    const uint32_t crc = static_cast<uint32_t>(
        crc32(0, reinterpret_cast<const Bytef*>(body.data()), static_cast<uInt>(body.size())));
    return u32(static_cast<uint32_t>(data.size())) + body + u32(crc);
  };
  std::string raw;
  for (int y = 0; y < height; ++y) {
    raw += '\0';  // filter: none
    for (int i = 0; i < width * channels; ++i) {
      const uint16_t v = samples[static_cast<size_t>(y) * width * channels + i];
      raw += static_cast<char>(v >> 8);
      raw += static_cast<char>(v & 0xFF);
    }
  }
  uLongf size = compressBound(static_cast<uLong>(raw.size()));
  std::string packed(size, '\0');
  compress(reinterpret_cast<Bytef*>(&packed[0]), &size, reinterpret_cast<const Bytef*>(raw.data()),
           static_cast<uLong>(raw.size()));
  packed.resize(size);
  const std::string ihdr =
      u32(width) + u32(height) + std::string{16, static_cast<char>(channels == 1 ? 0 : 2), 0, 0, 0};
  return std::string("\x89PNG\r\n\x1a\n", 8) + chunk("IHDR", ihdr) + chunk("IDAT", packed) +
         chunk("IEND", "");
}

// 16-bit photos keep their precision, and grey ones become three equal channels in a scene.
TEST(ImageIoTest, SixteenBitAndGreyPhotosAreRead) {
  const std::string dir = testing::ScratchDir();
  std::vector<uint16_t> rgb = {0, 1, 65535, 32768, 257, 12345};  // 2 x 1 pixels, RGB
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/rgb16.png", Png16(rgb, 2, 1, 3)).ok());
  Image im;
  ASSERT_TRUE(ReadImage(dir + "/rgb16.png", &im).ok());
  ASSERT_EQ(im.channels(), 3);
  EXPECT_FLOAT_EQ(im.at(0, 0, 0), 0.0f);
  EXPECT_NEAR(im.at(1, 0, 0), 1.0 / 65535, 1e-9);  // finer than any 8-bit step
  EXPECT_FLOAT_EQ(im.at(2, 0, 0), 1.0f);
  EXPECT_NEAR(im.at(2, 0, 1), 12345.0 / 65535, 1e-7);
  std::vector<uint16_t> grey = {100, 60000};
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/grey16.png", Png16(grey, 2, 1, 1)).ok());
  ASSERT_TRUE(ReadImage(dir + "/grey16.png", &im).ok());
  ASSERT_EQ(im.channels(), 1);
  EXPECT_NEAR(im.at(0, 0, 1), 60000.0 / 65535, 1e-7);
  // In a scene: a grey photo is replicated into RGB.
  View v;
  v.camera.width = 2;
  v.camera.height = 1;
  v.camera.fx = v.camera.fy = 2;
  v.camera.cx = 1;
  v.camera.cy = 0.5;
  ASSERT_TRUE(LoadViewImages(dir + "/grey16.png", "", SceneOptions(), &v).ok());
  ASSERT_EQ(v.image.channels(), 3);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(v.image.at(c, 0, 1), 60000.0 / 65535, 1e-7);
}

}  // namespace
}  // namespace mgsr
