#include "mgsr/io/scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>

#include "mgsr/io/colmap_model.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"
#include "test_util.h"

namespace mgsr {
namespace {

namespace fs = std::filesystem;

class SceneTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing::ScratchDir();
    ASSERT_TRUE(WriteSyntheticScene(testing::SmallSynthOptions(), dir_).ok());
  }
  Status Load(Scene* scene, SceneOptions options = {}) { return LoadScene(dir_, options, scene); }
  void ExpectLoadFails(const std::string& expected) {
    Scene scene;
    const Status s = Load(&scene);
    ASSERT_FALSE(s.ok()) << "expected: " << expected;
    EXPECT_NE(s.message().find(expected), std::string::npos) << s.message();
    EXPECT_EQ(s.message().find('\n'), std::string::npos) << "one line: " << s.message();
  }
  void EditModel(const std::function<void(ColmapModel*)>& edit) {
    ColmapModel m;
    ASSERT_TRUE(ReadColmapModel(dir_ + "/sparse/0", &m).ok());
    edit(&m);
    ASSERT_TRUE(WriteColmapModel(dir_ + "/sparse/0", m, ColmapFormat::kBinary).ok());
  }
  std::string dir_;
};

TEST_F(SceneTest, ColmapWorkspaceLoads) {
  Scene scene;
  ASSERT_TRUE(Load(&scene).ok());
  EXPECT_EQ(scene.source, "colmap");
  ASSERT_EQ(scene.views.size(), 12u);
  EXPECT_EQ(scene.TestIndices().size(), 3u);  // split.txt: views 0, 4, 8
  EXPECT_TRUE(scene.views[0].is_test);
  EXPECT_TRUE(scene.views[4].is_test);
  EXPECT_TRUE(scene.has_masks());
  for (const View& v : scene.views) {
    EXPECT_EQ(v.image.channels(), 3);
    EXPECT_EQ(v.alpha.channels(), 1);
    EXPECT_EQ(v.image.width(), 32);
    EXPECT_EQ(v.mask.width(), 32);
  }
  EXPECT_FALSE(scene.random_points);
  EXPECT_GT(scene.points.size(), 50u);
  // Cameras at distance ~3.5 around the origin: extent = 1.1 x max distance from their centroid.
  EXPECT_GT(scene.extent, 3.0);
  EXPECT_LT(scene.extent, 5.0);
}

TEST_F(SceneTest, BlenderLayoutAgreesWithColmapLayout) {
  Scene colmap, blender;
  ASSERT_TRUE(LoadColmapScene(dir_, SceneOptions(), &colmap).ok());
  ASSERT_TRUE(LoadBlenderScene(dir_, SceneOptions(), &blender).ok());
  ASSERT_EQ(colmap.views.size(), blender.views.size());
  std::map<std::string, const View*> by_stem;
  for (const View& v : blender.views) by_stem[FileStem(v.name)] = &v;
  for (const View& v : colmap.views) {
    const View& b = *by_stem.at(FileStem(v.name));
    EXPECT_EQ(v.is_test, b.is_test) << v.name;
    EXPECT_NEAR((v.camera.R - b.camera.R).norm(), 0, 1e-9) << v.name;
    EXPECT_NEAR((v.camera.t - b.camera.t).norm(), 0, 1e-9) << v.name;
    EXPECT_NEAR(v.camera.fx, b.camera.fx, 1e-9);
    EXPECT_NEAR(v.camera.cx, b.camera.cx, 1e-12);
    ASSERT_TRUE(v.image.SameShape(b.image));
    for (size_t i = 0; i < v.image.size(); ++i) ASSERT_EQ(v.image.data()[i], b.image.data()[i]);
    for (size_t i = 0; i < v.mask.size(); ++i) ASSERT_EQ(v.mask.data()[i], b.mask.data()[i]);
  }
  EXPECT_NEAR(colmap.extent, blender.extent, 1e-9);
  EXPECT_EQ(colmap.points.size(), blender.points.size());
}

TEST_F(SceneTest, SplitFallsBackToEveryNth) {
  fs::remove(dir_ + "/split.txt");
  SceneOptions o;
  o.test_every = 5;
  Scene scene;
  ASSERT_TRUE(Load(&scene, o).ok());
  std::vector<int> expected = {0, 5, 10};
  EXPECT_EQ(scene.TestIndices(), expected);
  o.test_every = 0;
  ASSERT_TRUE(Load(&scene, o).ok());
  EXPECT_TRUE(scene.TestIndices().empty());
}

TEST_F(SceneTest, ImageIdsNeedNotFollowFileOrder) {
  EditModel([](ColmapModel* m) {
    std::reverse(m->images.begin(), m->images.end());
    for (auto& im : m->images) im.image_id += 1000;
    for (auto& p : m->points) {
      for (auto& id : p.track_image_ids) id += 1000;
    }
  });
  Scene scene;
  ASSERT_TRUE(Load(&scene).ok());
  EXPECT_EQ(scene.views[0].name, "v000.png");
  EXPECT_EQ(scene.views[11].name, "v011.png");
}

TEST_F(SceneTest, DownscaleAndMaxWidthResizeImagesAndIntrinsics) {
  Scene full, half;
  ASSERT_TRUE(Load(&full).ok());
  SceneOptions o;
  o.downscale = 2;
  ASSERT_TRUE(Load(&half, o).ok());
  EXPECT_EQ(half.views[1].image.width(), 16);
  EXPECT_EQ(half.views[1].mask.height(), 16);
  EXPECT_NEAR(half.views[1].camera.fx, full.views[1].camera.fx / 2, 1e-12);
  EXPECT_NEAR(half.views[1].camera.cx, full.views[1].camera.cx / 2, 1e-12);
  SceneOptions w;
  w.max_width = 8;
  ASSERT_TRUE(Load(&half, w).ok());
  EXPECT_EQ(half.views[1].image.width(), 8);
  EXPECT_EQ(half.views[1].camera.width, 8);
  EXPECT_EQ(half.views[1].photo_width, 32);
  // The long side is capped, the aspect kept, and the log says so.
  ASSERT_TRUE(Load(&full).ok());
  EXPECT_TRUE(full.notes.empty());
  SceneOptions l;
  l.max_size = 16;
  ASSERT_TRUE(Load(&half, l).ok());
  EXPECT_EQ(half.views[1].camera.width, 16);
  EXPECT_EQ(half.views[1].camera.height, 16);
  ASSERT_EQ(half.notes.size(), 1u);
  EXPECT_NE(half.notes[0].find("resized from 32x32 to 16x16: the long side is capped at 16 px"),
            std::string::npos)
      << half.notes[0];
}

TEST_F(SceneTest, AlphaBecomesTheMaskWithoutAMasksFolder) {
  Scene with;
  ASSERT_TRUE(Load(&with).ok());
  fs::remove_all(dir_ + "/masks");
  Scene without;
  ASSERT_TRUE(Load(&without).ok());
  ASSERT_TRUE(without.has_masks());
  const Image& alpha = without.views[3].alpha;
  for (size_t i = 0; i < alpha.size(); ++i)
    ASSERT_EQ(without.views[3].mask.data()[i], alpha.data()[i]);
  // The thresholded mask file and the alpha agree where alpha is decisive.
  for (size_t i = 0; i < alpha.size(); ++i) {
    if (alpha.data()[i] > 0.9f) {
      ASSERT_EQ(with.views[3].mask.data()[i], 1.0f);
    }
    if (alpha.data()[i] < 0.1f) {
      ASSERT_EQ(with.views[3].mask.data()[i], 0.0f);
    }
  }
}

TEST_F(SceneTest, EmptyPoints3DInitialisesRandomlyInsideTheCommonView) {
  EditModel([](ColmapModel* m) {
    m->points.clear();
    for (auto& im : m->images) {
      im.xys.clear();
      im.point3D_ids.clear();
    }
  });
  SceneOptions o;
  o.random_points = 500;
  Scene scene;
  ASSERT_TRUE(Load(&scene, o).ok());
  EXPECT_TRUE(scene.random_points);
  ASSERT_EQ(scene.points.size(), 500u);
  ASSERT_EQ(scene.warnings.size(), 1u);
  EXPECT_NE(scene.warnings[0].find("points3D is empty"), std::string::npos);
  for (const auto& p : scene.points) {
    for (int i : scene.TrainIndices()) {
      const Camera& c = scene.views[i].camera;
      const Eigen::Vector3d Xc = c.WorldToCamera(p.cast<double>());
      ASSERT_GT(Xc.z(), 0.2);
      const Eigen::Vector2d uv = c.CameraToPixel(Xc);
      ASSERT_TRUE(uv.x() >= 0 && uv.x() <= c.width && uv.y() >= 0 && uv.y() <= c.height);
    }
  }
}

TEST_F(SceneTest, FarPointsLieOnTheFarSphereAfterTheModelsPoints) {
  Scene plain, far;
  ASSERT_TRUE(Load(&plain, SceneOptions()).ok());
  SceneOptions o;
  o.far_points = 2000;
  o.far_radius = 8;
  ASSERT_TRUE(Load(&far, o).ok());
  const size_t n = plain.points.size();
  ASSERT_EQ(far.points.size(), n + 2000);
  ASSERT_EQ(far.point_colors.size(), far.points.size());
  for (size_t i = 0; i < n; ++i) ASSERT_EQ(far.points[i], plain.points[i]);
  // On the sphere, and spread over it: every octant holds about an eighth.
  int octant[8] = {};
  for (size_t i = n; i < far.points.size(); ++i) {
    const Eigen::Vector3d d = far.points[i].cast<double>() - far.center;
    ASSERT_NEAR(d.norm(), 8 * far.extent, 1e-5 * far.extent);
    ++octant[(d.x() > 0) + 2 * (d.y() > 0) + 4 * (d.z() > 0)];
  }
  for (int k = 0; k < 8; ++k) EXPECT_NEAR(octant[k], 250, 60) << "octant " << k;
  o.far_radius = 0.5;
  EXPECT_NE(Load(&far, o).message().find("--far_radius"), std::string::npos);
}

TEST_F(SceneTest, UndistorterLayoutFromTheWorkspaceOrTheDenseFolder) {
  // dense/images + dense/sparse/ (no 0/), as `colmap image_undistorter` writes them.
  fs::create_directories(dir_ + "/ws/dense/sparse");
  fs::copy(dir_ + "/images", dir_ + "/ws/dense/images", fs::copy_options::recursive);
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"}) {
    fs::copy(dir_ + "/sparse/0/" + f, dir_ + "/ws/dense/sparse/" + f);
  }
  Scene a, b, ref;
  ASSERT_TRUE(Load(&ref).ok());
  ASSERT_TRUE(LoadScene(dir_ + "/ws", SceneOptions(), &a).ok());
  ASSERT_TRUE(LoadScene(dir_ + "/ws/dense", SceneOptions(), &b).ok());
  ASSERT_EQ(a.views.size(), ref.views.size());
  ASSERT_EQ(b.views.size(), ref.views.size());
  EXPECT_EQ(a.views[3].camera.t, ref.views[3].camera.t);
  EXPECT_EQ(b.views[3].name, ref.views[3].name);
}

TEST_F(SceneTest, MissingFolderAndUnknownLayout) {
  Scene scene;
  Status s = LoadScene(dir_ + "/nope", SceneOptions(), &scene);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message(), dir_ + "/nope: scene folder does not exist");
  s = LoadScene(dir_ + "/images", SceneOptions(), &scene);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("not a scene"), std::string::npos);
}

TEST_F(SceneTest, ImageListedButMissing) {
  fs::remove(dir_ + "/images/v003.png");
  ExpectLoadFails(dir_ + "/images/v003.png: image file is missing");
}

TEST_F(SceneTest, ImageSizeNotMatchingItsCamera) {
  ASSERT_TRUE(WriteImage(dir_ + "/images/v005.png", Image(16, 20, 3, 0.5f)).ok());
  ExpectLoadFails(dir_ + "/images/v005.png: image is 16x20 but its camera says 32x32");
}

TEST_F(SceneTest, MaskSizeNotMatchingItsImage) {
  ASSERT_TRUE(WriteImage(dir_ + "/masks/v002.png", Image(8, 8, 1, 1.0f)).ok());
  ExpectLoadFails(dir_ + "/masks/v002.png: mask is 8x8 but its image is 32x32");
}

TEST_F(SceneTest, MissingMaskWhenTheFolderExists) {
  fs::remove(dir_ + "/masks/v007.png");
  ExpectLoadFails("no mask for image v007.png");
}

TEST_F(SceneTest, NanInPose) {
  EditModel([](ColmapModel* m) { m->images[2].qvec[1] = std::nan(""); });
  ExpectLoadFails("image v002.png has a NaN/inf pose");
}

TEST_F(SceneTest, ZeroImages) {
  EditModel([](ColmapModel* m) {
    m->images.clear();
    m->points.clear();
  });
  ExpectLoadFails("the model has no images");
}

// Every COLMAP camera model trains: a distorted one through undistortion (the log's note names
// the model), the two without an OpenCV equivalent are refused with the fix.
TEST_F(SceneTest, EveryColmapCameraModelLoadsOrIsRefusedWithAFix) {
  Scene original;
  ASSERT_TRUE(LoadScene(dir_, SceneOptions(), &original).ok());
  const double f = original.views[0].camera.fx;
  for (int id = 0; id <= 10; ++id) {
    const CameraModelInfo* info = FindCameraModel(id);
    ASSERT_NE(info, nullptr);
    static int model_id;
    static double focal;
    model_id = id;
    focal = f;
    EditModel([](ColmapModel* m) {
      const CameraModelInfo* info = FindCameraModel(model_id);
      ColmapCamera& c = m->cameras[0];
      c.model_id = model_id;
      // Focal lengths, the principal point, then small coefficients of alternating sign.
      const bool one_focal = std::string(info->name).rfind("SIMPLE", 0) == 0 ||
                             std::string(info->name) == "RADIAL" ||
                             std::string(info->name) == "RADIAL_FISHEYE";
      c.params = one_focal ? std::vector<double>{focal, 16, 16}
                           : std::vector<double>{focal, focal, 16, 16};
      for (int k = static_cast<int>(c.params.size()); k < info->num_params; ++k)
        c.params.push_back((k % 2 ? -0.01 : 0.004) / k);
    });
    Scene scene;
    const Status s = LoadScene(dir_, SceneOptions(), &scene);
    const std::string name = info->name;
    if (name == "FOV" || name == "THIN_PRISM_FISHEYE") {
      ASSERT_FALSE(s.ok()) << name;
      EXPECT_NE(s.message().find("camera model " + name + " is not supported"), std::string::npos)
          << s.message();
      EXPECT_NE(s.message().find("colmap image_undistorter"), std::string::npos) << s.message();
      continue;
    }
    ASSERT_TRUE(s.ok()) << name << ": " << s.message();
    EXPECT_NEAR(scene.views[0].camera.fx, f, 0.05 * f) << name;
    if (info->has_distortion) {
      ASSERT_EQ(scene.notes.size(), 1u) << name;
      EXPECT_NE(scene.notes[0].find(name + " lens"), std::string::npos) << scene.notes[0];
      EXPECT_NE(scene.notes[0].find("undistorted"), std::string::npos) << scene.notes[0];
    } else {
      EXPECT_TRUE(scene.notes.empty()) << name;
    }
  }
}

TEST_F(SceneTest, TruncatedModelFile) {
  std::string data;
  ASSERT_TRUE(ReadFileToString(dir_ + "/sparse/0/images.bin", &data).ok());
  ASSERT_TRUE(WriteStringToFileAtomic(dir_ + "/sparse/0/images.bin", data.substr(0, 100)).ok());
  ExpectLoadFails(dir_ + "/sparse/0/images.bin: truncated");
}

TEST_F(SceneTest, SplitFileNamingAnUnknownImage) {
  ASSERT_TRUE(WriteStringToFileAtomic(dir_ + "/split.txt", "v001.png\nghost.png\n").ok());
  ExpectLoadFails("split.txt: lists 'ghost.png', which is not in the model");
}

// #18: inputs that used to validate and then trained on wrong data.
TEST_F(SceneTest, DuplicateImageNameIsRefused) {
  EditModel([](ColmapModel* m) { m->images[3].name = m->images[2].name; });
  ExpectLoadFails("image name v002.png appears twice (two poses for one photo)");
}

TEST_F(SceneTest, ImageSizeBeyondAnySensorIsRefused) {
  EditModel([](ColmapModel* m) { m->cameras[0].width = (uint64_t{1} << 32) + 32; });
  ExpectLoadFails("has size 4294967328 x 32 (expected 1 to 65536 pixels a side)");
}

TEST_F(SceneTest, OverflowingQuaternionIsRefused) {
  EditModel([](ColmapModel* m) { m->images[4].qvec = Eigen::Vector4d(1e200, 1e200, 0, 0); });
  ExpectLoadFails("image v004.png has a quaternion of norm inf (zero or overflowing");
}

TEST_F(SceneTest, SplitFileWithoutNamesIsRefused) {
  ASSERT_TRUE(WriteStringToFileAtomic(dir_ + "/split.txt", "# test views\n\n").ok());
  ExpectLoadFails(dir_ + "/split.txt: lists no test views");
  std::string all;
  Scene scene;
  ASSERT_TRUE(fs::remove(dir_ + "/split.txt"));
  ASSERT_TRUE(Load(&scene).ok());
  for (const View& v : scene.views) all += v.name + "\n";
  ASSERT_TRUE(WriteStringToFileAtomic(dir_ + "/split.txt", all).ok());
  ExpectLoadFails(dir_ + "/split.txt: lists every image as a test view");
}

TEST_F(SceneTest, BlenderWithoutTrainingFramesNamesTheFile) {
  fs::remove_all(dir_ + "/sparse");
  std::string json;
  ASSERT_TRUE(ReadFileToString(dir_ + "/transforms_train.json", &json).ok());
  nlohmann::json j = nlohmann::json::parse(json);
  j["frames"] = nlohmann::json::array();
  ASSERT_TRUE(WriteStringToFileAtomic(dir_ + "/transforms_train.json", j.dump()).ok());
  ExpectLoadFails(dir_ + "/transforms_train.json: no training frames");
}

// Cameras no capture has, which trained to an empty mesh with exit 0 before.
TEST_F(SceneTest, DegenerateCamerasAreRefused) {
  const auto params = [this](std::vector<double> p) {
    EditModel([&p](ColmapModel* m) { m->cameras[0].params = p; });
  };
  ColmapModel original;
  ASSERT_TRUE(ReadColmapModel(dir_ + "/sparse/0", &original).ok());
  const std::vector<double> good = original.cameras[0].params;
  ASSERT_EQ(good.size(), 4u);  // PINHOLE fx fy cx cy
  params({1e-12, 1e-12, good[2], good[3]});
  ExpectLoadFails("focal length 1e-12 px gives a horizontal field of view of 180 degrees");
  params({1e12, 1e12, good[2], good[3]});
  ExpectLoadFails("field of view of 1.833e-09 degrees (expected 0.1 to 179)");
  params({good[0], good[1], 1e6, good[3]});
  ExpectLoadFails("principal point (1e+06, 16) lies far outside its 32 x 32 image");
  params(good);
  EditModel([](ColmapModel* m) { m->images[5].tvec = Eigen::Vector3d(1e308, 0, 0); });
  ExpectLoadFails("view v005.png: camera lies");
}

TEST_F(SceneTest, AllEmptyMasksAreRefused) {
  for (const auto& e : fs::directory_iterator(dir_ + "/masks"))
    ASSERT_TRUE(WriteImage(e.path().string(), Image(32, 32, 1, 0.0f)).ok());
  ExpectLoadFails("every mask is empty (all background): nothing to reconstruct");
}

TEST_F(SceneTest, BlenderFieldOfViewOfPiIsRefused) {
  fs::remove_all(dir_ + "/sparse");
  std::string json;
  ASSERT_TRUE(ReadFileToString(dir_ + "/transforms_train.json", &json).ok());
  nlohmann::json j = nlohmann::json::parse(json);
  j["camera_angle_x"] = 3.141592653589793;
  j.erase("fl_x");  // the focal length then comes from the angle
  j.erase("fl_y");
  ASSERT_TRUE(WriteStringToFileAtomic(dir_ + "/transforms_train.json", j.dump()).ok());
  ExpectLoadFails("field of view of 180 degrees");
}

TEST_F(SceneTest, BlenderBadJsonAndNanMatrix) {
  fs::remove_all(dir_ + "/sparse");
  Scene scene;
  ASSERT_TRUE(Load(&scene).ok());
  EXPECT_EQ(scene.source, "blender");
  std::string json;
  ASSERT_TRUE(ReadFileToString(dir_ + "/transforms_train.json", &json).ok());
  ASSERT_TRUE(
      WriteStringToFileAtomic(dir_ + "/transforms_train.json", json.substr(0, json.size() / 2))
          .ok());
  ExpectLoadFails(dir_ + "/transforms_train.json: invalid JSON");
  // NaN is not JSON; writers that emit it produce null.
  const size_t pos = json.find("\"transform_matrix\"");
  const size_t num = json.find_first_of("-0123456789", json.find('[', json.find('[', pos) + 1));
  const size_t end = json.find_first_of(",\n]", num);
  ASSERT_TRUE(WriteStringToFileAtomic(dir_ + "/transforms_train.json",
                                      json.substr(0, num) + "null" + json.substr(end))
                  .ok());
  ExpectLoadFails("has a non-number (NaN?)");
}

TEST(SharedSceneTest, SuzanneLoadsInBothLayouts) {
  if (!testing::HaveSharedData()) GTEST_SKIP() << "../shared/data not present";
  const std::string root = testing::SharedDataDir() + "/suzanne";
  Scene colmap, blender;
  ASSERT_TRUE(LoadColmapScene(root, SceneOptions(), &colmap).ok());
  ASSERT_TRUE(LoadBlenderScene(root, SceneOptions(), &blender).ok());
  EXPECT_EQ(colmap.TrainIndices().size(), 48u);
  EXPECT_EQ(colmap.TestIndices().size(), 12u);
  EXPECT_EQ(blender.TestIndices().size(), 12u);
  EXPECT_TRUE(colmap.has_masks());
  std::map<std::string, const View*> by_stem;
  for (const View& v : blender.views) by_stem[FileStem(v.name)] = &v;
  for (const View& v : colmap.views) {
    const View& b = *by_stem.at(FileStem(v.name));
    EXPECT_EQ(v.is_test, b.is_test);
    EXPECT_NEAR((v.camera.Center() - b.camera.Center()).norm(), 0, 1e-5) << v.name;
    EXPECT_NEAR((v.camera.R - b.camera.R).norm(), 0, 1e-5) << v.name;
  }
}

}  // namespace
}  // namespace mgsr

namespace mgsr {
namespace {

TEST(SceneTextModelTest, TextAndBinaryWorkspacesLoadTheSame) {
  const std::string dir = testing::ScratchDir();
  SynthOptions o = testing::SmallSynthOptions();
  ASSERT_TRUE(WriteSyntheticScene(o, dir + "/bin").ok());
  o.write_text_model = true;
  ASSERT_TRUE(WriteSyntheticScene(o, dir + "/txt").ok());
  ASSERT_TRUE(FileExists(dir + "/txt/sparse/0/images.txt"));
  ASSERT_FALSE(FileExists(dir + "/txt/sparse/0/images.bin"));
  // sparse/ without 0/ is accepted too.
  std::filesystem::rename(dir + "/txt/sparse/0", dir + "/txt/model");
  std::filesystem::remove_all(dir + "/txt/sparse");
  std::filesystem::rename(dir + "/txt/model", dir + "/txt/sparse");
  Scene a, b;
  ASSERT_TRUE(LoadScene(dir + "/bin", SceneOptions(), &a).ok());
  ASSERT_TRUE(LoadScene(dir + "/txt", SceneOptions(), &b).ok());
  ASSERT_EQ(a.views.size(), b.views.size());
  for (size_t i = 0; i < a.views.size(); ++i) {
    EXPECT_EQ(a.views[i].camera.R, b.views[i].camera.R);
    EXPECT_EQ(a.views[i].camera.t, b.views[i].camera.t);
  }
  EXPECT_EQ(a.points, b.points);
}

}  // namespace
}  // namespace mgsr

namespace mgsr {
namespace {

// The Blender/nerfstudio json: what it cannot honour is refused naming the field, what it can is
// honoured (a frame's own focal length wins over the file's).
class BlenderFieldsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing::ScratchDir();
    ASSERT_TRUE(WriteSyntheticScene(testing::SmallSynthOptions(), dir_).ok());
    std::filesystem::remove_all(dir_ + "/sparse");
    std::string text;
    ASSERT_TRUE(ReadFileToString(dir_ + "/transforms_train.json", &text).ok());
    json_ = nlohmann::json::parse(text);
  }
  Status Load(Scene* scene) {
    EXPECT_TRUE(WriteStringToFileAtomic(dir_ + "/transforms_train.json", json_.dump()).ok());
    return LoadScene(dir_, SceneOptions(), scene);
  }
  void ExpectRefused(const std::string& expected) {
    Scene scene;
    const Status s = Load(&scene);
    ASSERT_FALSE(s.ok()) << expected;
    EXPECT_NE(s.message().find(expected), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("transforms_train.json"), std::string::npos) << s.message();
  }
  std::string dir_;
  nlohmann::json json_;
};

TEST_F(BlenderFieldsTest, PerFrameFocalLengthWins) {
  Scene scene;
  ASSERT_TRUE(Load(&scene).ok());
  const double fx = scene.views[0].camera.fx;
  json_["frames"][1]["fl_x"] = 2 * fx;
  json_["frames"][1]["fl_y"] = 2 * fx;
  ASSERT_TRUE(Load(&scene).ok());
  const std::string name = json_["frames"][1]["file_path"].get<std::string>();
  for (const View& v : scene.views) {
    if (v.name == name) {
      EXPECT_DOUBLE_EQ(v.camera.fx, 2 * fx);
      EXPECT_DOUBLE_EQ(v.camera.fy, 2 * fx);
    } else {
      EXPECT_DOUBLE_EQ(v.camera.fx, fx) << v.name;
    }
  }
}

TEST_F(BlenderFieldsTest, FieldsItCannotHonourAreRefused) {
  const nlohmann::json original = json_;
  json_["w"] = 1e12;
  ExpectRefused("'w' must be a whole number of pixels in [1, 65536]");
  json_ = original;
  json_["k4"] = 0.1;  // nerfstudio: coefficients without a model are OPENCV's, which has no k4
  ExpectRefused("'k4' is not a coefficient of camera_model OPENCV");
  json_ = original;
  json_["frames"][2]["p2"] = -0.01;
  json_["frames"][2]["camera_model"] = "OPENCV_FISHEYE";
  ExpectRefused("'p2' is not a coefficient of camera_model OPENCV_FISHEYE");
  json_ = original;
  json_["camera_model"] = "PINHOLE";
  json_["k1"] = 0.1;
  ExpectRefused("'k1' is not a coefficient of camera_model PINHOLE");
  json_ = original;
  json_["camera_model"] = "EQUIRECTANGULAR";
  ExpectRefused("camera_model EQUIRECTANGULAR is not supported");
  json_ = original;
  json_["frames"].push_back(json_["frames"][0]);
  ExpectRefused("is listed twice");
  json_ = original;
  json_["k1"] = 0.0;  // zero distortion is a pinhole camera
  json_["camera_model"] = "PINHOLE";
  Scene scene;
  EXPECT_TRUE(Load(&scene).ok());
}

}  // namespace
}  // namespace mgsr

namespace mgsr {
namespace {

// Scenes that load but cannot train are refused before training, saying what is wrong.
TEST(TrainableTest, DegenerateScenesAreRefusedBeforeTraining) {
  const std::string dir = testing::ScratchDir();
  ASSERT_TRUE(WriteSyntheticScene(testing::SmallSynthOptions(), dir).ok());
  Scene scene;
  ASSERT_TRUE(LoadScene(dir, SceneOptions(), &scene).ok());
  EXPECT_TRUE(CheckTrainable(scene).ok());
  Scene one = scene;
  for (size_t v = 0; v < one.views.size(); ++v) one.views[v].is_test = v != 1;
  Status s = CheckTrainable(one);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("1 training view(s); at least 2 are needed"), std::string::npos)
      << s.message();
  Scene away = scene;
  for (auto& p : away.points) p = Eigen::Vector3f(0, 0, 1000);  // above every camera's view
  s = CheckTrainable(away);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("only 0 of the 200 scene points lie in front of two training"),
            std::string::npos)
      << s.message();
  SceneOptions tiny;
  tiny.downscale = 1000;
  Scene small;
  s = LoadScene(dir, tiny, &small);
  if (s.ok()) s = CheckTrainable(small);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find(dir), std::string::npos) << s.message();
}

}  // namespace
}  // namespace mgsr
