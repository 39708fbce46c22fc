#include "mgsr/io/colmap_model.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>

#include "mgsr/core/rng.h"
#include "mgsr/io/file_util.h"
#include "test_util.h"

namespace mgsr {
namespace {

// A random model with every feature of the format: several camera models, images with and
// without observations, invalid point ids, tracks.
ColmapModel RandomModel(uint64_t seed) {
  Rng rng(seed);
  ColmapModel m;
  const int models[] = {0, 1, 4, 1};
  for (int i = 0; i < 4; ++i) {
    ColmapCamera c;
    c.camera_id = 10 + i;
    c.model_id = models[i];
    c.width = 640 + i;
    c.height = 480 - i;
    for (int k = 0; k < FindCameraModel(c.model_id)->num_params; ++k)
      c.params.push_back(rng.Uniform(-1, 1000));
    m.cameras.push_back(c);
  }
  for (int i = 0; i < 5; ++i) {
    ColmapImage im;
    im.image_id = 100 - 7 * i;  // ids not in file order
    im.qvec = Eigen::Vector4d(rng.Normal(), rng.Normal(), rng.Normal(), rng.Normal()).normalized();
    im.tvec = {rng.Normal(), rng.Normal(), rng.Normal()};
    im.camera_id = 10 + i % 4;
    im.name = "img_" + std::to_string(i) + ".jpg";
    const int n = i == 2 ? 0 : 3 + i;
    for (int k = 0; k < n; ++k) {
      im.xys.emplace_back(rng.Uniform(0, 640), rng.Uniform(0, 480));
      im.point3D_ids.push_back(k % 3 == 0 ? -1 : static_cast<int64_t>(rng.UniformInt(50)));
    }
    m.images.push_back(im);
  }
  for (int i = 0; i < 7; ++i) {
    ColmapPoint3D p;
    p.point3D_id = 1000 + 3 * i;
    p.xyz = {rng.Normal(), rng.Normal(), rng.Normal()};
    p.rgb = {static_cast<uint8_t>(rng.UniformInt(256)), static_cast<uint8_t>(rng.UniformInt(256)),
             7};
    p.error = rng.Uniform();
    for (int k = 0; k < i; ++k) {
      p.track_image_ids.push_back(100 - 7 * (k % 5));
      p.track_point2D_idxs.push_back(k);
    }
    m.points.push_back(p);
  }
  return m;
}

void ExpectEqual(const ColmapModel& a, const ColmapModel& b) {
  ASSERT_EQ(a.cameras.size(), b.cameras.size());
  for (size_t i = 0; i < a.cameras.size(); ++i) {
    EXPECT_EQ(a.cameras[i].camera_id, b.cameras[i].camera_id);
    EXPECT_EQ(a.cameras[i].model_id, b.cameras[i].model_id);
    EXPECT_EQ(a.cameras[i].width, b.cameras[i].width);
    EXPECT_EQ(a.cameras[i].height, b.cameras[i].height);
    EXPECT_EQ(a.cameras[i].params, b.cameras[i].params);  // exact: precision 17 is lossless
  }
  ASSERT_EQ(a.images.size(), b.images.size());
  for (size_t i = 0; i < a.images.size(); ++i) {
    EXPECT_EQ(a.images[i].image_id, b.images[i].image_id);
    EXPECT_EQ(a.images[i].qvec, b.images[i].qvec);
    EXPECT_EQ(a.images[i].tvec, b.images[i].tvec);
    EXPECT_EQ(a.images[i].camera_id, b.images[i].camera_id);
    EXPECT_EQ(a.images[i].name, b.images[i].name);
    EXPECT_EQ(a.images[i].xys, b.images[i].xys);
    EXPECT_EQ(a.images[i].point3D_ids, b.images[i].point3D_ids);
  }
  ASSERT_EQ(a.points.size(), b.points.size());
  for (size_t i = 0; i < a.points.size(); ++i) {
    EXPECT_EQ(a.points[i].point3D_id, b.points[i].point3D_id);
    EXPECT_EQ(a.points[i].xyz, b.points[i].xyz);
    EXPECT_EQ(a.points[i].rgb, b.points[i].rgb);
    EXPECT_EQ(a.points[i].error, b.points[i].error);
    EXPECT_EQ(a.points[i].track_image_ids, b.points[i].track_image_ids);
    EXPECT_EQ(a.points[i].track_point2D_idxs, b.points[i].track_point2D_idxs);
  }
}

std::string Slurp(const std::string& path) {
  std::string s;
  EXPECT_TRUE(ReadFileToString(path, &s).ok()) << path;
  return s;
}

TEST(ColmapModelTest, BinaryAndTextRoundTrip) {
  const std::string dir = testing::ScratchDir();
  const ColmapModel model = RandomModel(3);
  ASSERT_TRUE(WriteColmapModel(dir + "/bin", model, ColmapFormat::kBinary).ok());
  ASSERT_TRUE(WriteColmapModel(dir + "/txt", model, ColmapFormat::kText).ok());
  ColmapModel from_bin, from_txt;
  ASSERT_TRUE(ReadColmapModel(dir + "/bin", &from_bin).ok());
  ASSERT_TRUE(ReadColmapModel(dir + "/txt", &from_txt).ok());
  ExpectEqual(model, from_bin);
  ExpectEqual(model, from_txt);
}

TEST(ColmapModelTest, BinaryToTextToBinaryIsByteIdentical) {
  const std::string dir = testing::ScratchDir();
  ASSERT_TRUE(WriteColmapModel(dir + "/a", RandomModel(5), ColmapFormat::kBinary).ok());
  ColmapModel m;
  ASSERT_TRUE(ReadColmapModel(dir + "/a", &m).ok());
  ASSERT_TRUE(WriteColmapModel(dir + "/t", m, ColmapFormat::kText).ok());
  ColmapModel t;
  ASSERT_TRUE(ReadColmapModel(dir + "/t", &t).ok());
  ASSERT_TRUE(WriteColmapModel(dir + "/b", t, ColmapFormat::kBinary).ok());
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"}) {
    EXPECT_EQ(Slurp(dir + "/a/" + f), Slurp(dir + "/b/" + f)) << f;
  }
  // And text -> binary -> text reproduces the text files.
  ASSERT_TRUE(WriteColmapModel(dir + "/t2", t, ColmapFormat::kText).ok());
  for (const char* f : {"cameras.txt", "images.txt", "points3D.txt"}) {
    EXPECT_EQ(Slurp(dir + "/t/" + f), Slurp(dir + "/t2/" + f)) << f;
  }
}

TEST(ColmapModelTest, ReadsTheSharedSuzanneTextModel) {
  if (!testing::HaveSharedData()) GTEST_SKIP() << "../shared/data not present";
  ColmapModel m;
  const std::string dir = testing::SharedDataDir() + "/suzanne/sparse/0";
  ASSERT_TRUE(ReadColmapModel(dir, &m).ok());
  EXPECT_TRUE(ValidateColmapModel(m, dir).ok());
  ASSERT_EQ(m.cameras.size(), 1u);
  EXPECT_EQ(m.cameras[0].model_id, 1);
  EXPECT_DOUBLE_EQ(m.cameras[0].params[2], 128.0);
  EXPECT_EQ(m.images.size(), 60u);
  EXPECT_EQ(m.points.size(), 3000u);
  // Exact 2D observations: each track element reprojects onto its recorded 2D point.
  std::map<uint32_t, const ColmapImage*> by_id;
  for (const auto& im : m.images) by_id[im.image_id] = &im;
  const ColmapPoint3D& p = m.points[0];
  for (size_t k = 0; k < p.track_image_ids.size(); ++k) {
    const ColmapImage& im = *by_id.at(p.track_image_ids[k]);
    Camera cam;
    ASSERT_TRUE(MakePinholeCamera(m.cameras[0], im, &cam).ok());
    EXPECT_NEAR((cam.WorldToPixel(p.xyz) - im.xys[p.track_point2D_idxs[k]]).norm(), 0, 1e-3);
  }
}

TEST(ColmapModelTest, TruncatedBinaryIsReportedWithTheFileName) {
  const std::string dir = testing::ScratchDir();
  ASSERT_TRUE(WriteColmapModel(dir, RandomModel(1), ColmapFormat::kBinary).ok());
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"}) {
    const std::string path = dir + "/" + f;
    const std::string full = Slurp(path);
    ASSERT_TRUE(WriteStringToFileAtomic(path, full.substr(0, full.size() / 2)).ok());
    ColmapModel m;
    const Status s = ReadColmapModel(dir, &m);
    ASSERT_FALSE(s.ok()) << f;
    EXPECT_NE(s.message().find(path), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("truncated"), std::string::npos) << s.message();
    ASSERT_TRUE(WriteStringToFileAtomic(path, full).ok());
  }
}

TEST(ColmapModelTest, CorruptCountDoesNotAllocate) {
  const std::string dir = testing::ScratchDir();
  std::string data(8, '\0');
  const uint64_t huge = 1ull << 60;
  std::memcpy(data.data(), &huge, 8);
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/points3D.bin", data).ok());
  std::vector<ColmapPoint3D> points;
  const Status s = ReadPoints3DBinary(dir + "/points3D.bin", &points);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("corrupt"), std::string::npos) << s.message();
}

TEST(ColmapModelTest, UnknownCameraModelIdIsRefused) {
  const std::string dir = testing::ScratchDir();
  ColmapModel m = RandomModel(2);
  ASSERT_TRUE(WriteColmapModel(dir, m, ColmapFormat::kBinary).ok());
  std::string data = Slurp(dir + "/cameras.bin");
  const int32_t bad = 42;
  std::memcpy(data.data() + 8 + 4, &bad, 4);  // first camera's model id
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/cameras.bin", data).ok());
  const Status s = ReadColmapModel(dir, &m);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("unknown camera model id 42"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("cameras.bin"), std::string::npos) << s.message();

  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/cameras.txt", "1 FANCY_LENS 10 10 1 2 3\n").ok());
  std::vector<ColmapCamera> cams;
  const Status t = ReadCamerasText(dir + "/cameras.txt", &cams);
  ASSERT_FALSE(t.ok());
  EXPECT_NE(t.message().find("cameras.txt:1: unknown camera model 'FANCY_LENS'"), std::string::npos)
      << t.message();
}

TEST(ColmapModelTest, AllCameraModelsParseButOnlyPinholeTrains) {
  for (int id = 0; id <= 10; ++id) {
    const CameraModelInfo* info = FindCameraModel(id);
    ASSERT_NE(info, nullptr);
    EXPECT_EQ(FindCameraModel(info->name), info);
    ColmapCamera cam;
    cam.camera_id = 1;
    cam.model_id = id;
    cam.width = 100;
    cam.height = 100;
    cam.params.assign(info->num_params, 0.0);
    cam.params[0] = 90;
    for (int k = 1; k < info->num_params; ++k) cam.params[k] = 50;
    ColmapImage im;
    im.name = "a.png";
    Camera out;
    const Status s = MakePinholeCamera(cam, im, &out);
    if (id <= 1) {
      EXPECT_TRUE(s.ok()) << s.message();
    } else {
      ASSERT_FALSE(s.ok()) << info->name;
      EXPECT_NE(s.message().find("colmap image_undistorter"), std::string::npos) << s.message();
      EXPECT_NE(s.message().find(info->name), std::string::npos) << s.message();
    }
  }
  EXPECT_EQ(FindCameraModel(11), nullptr);
}

TEST(ColmapModelTest, ValidationCatchesNanPosesAndDanglingReferences) {
  ColmapModel m = RandomModel(4);
  EXPECT_TRUE(ValidateColmapModel(m, "model").ok());
  ColmapModel nan = m;
  nan.images[1].tvec.y() = std::nan("");
  Status s = ValidateColmapModel(nan, "model");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("img_1.jpg has a NaN/inf pose"), std::string::npos) << s.message();
  ColmapModel dangling = m;
  dangling.images[0].camera_id = 999;
  s = ValidateColmapModel(dangling, "model");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("missing camera 999"), std::string::npos) << s.message();
}

TEST(ColmapModelTest, MissingFolderAndFiles) {
  ColmapModel m;
  Status s = ReadColmapModel("/nonexistent/sparse/0", &m);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("/nonexistent/sparse/0"), std::string::npos);
  const std::string dir = testing::ScratchDir();
  ASSERT_TRUE(WriteColmapModel(dir, RandomModel(1), ColmapFormat::kBinary).ok());
  std::filesystem::remove(dir + "/images.bin");
  std::filesystem::remove(dir + "/points3D.bin");
  s = ReadColmapModel(dir, &m);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("images.bin: cannot open"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace mgsr
