#include "mgsr/io/undistort.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "mgsr/core/lens.h"
#include "mgsr/eval/image_metrics.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"
#include "mgsr/io/scene.h"
#include "mgsr/synth/synthetic_scene.h"
#include "test_util.h"

namespace mgsr {
namespace {

Lens OpenCvLens() {
  Lens l;
  l.kind = Lens::Kind::kRadial;
  l.model = "FULL_OPENCV";
  l.width = 120;
  l.height = 90;
  l.fx = 100;
  l.fy = 104;
  l.cx = 61.5;
  l.cy = 44;
  l.k = {-0.25, 0.08, -0.01, 0.02, -0.005, 0.001};
  l.p1 = 0.003;
  l.p2 = -0.002;
  return l;
}

Lens FisheyeLens() {
  Lens l = OpenCvLens();
  l.kind = Lens::Kind::kFisheye;
  l.model = "OPENCV_FISHEYE";
  l.k = {0.1, -0.03, 0.01, -0.002, 0, 0};
  l.p1 = l.p2 = 0;
  return l;
}

// OpenCV's documented formulas, written out here independently of Lens::Distort.
TEST(LensTest, DistortFollowsOpenCvFormulas) {
  const Lens l = OpenCvLens();
  const double x = 0.3, y = -0.2, r2 = x * x + y * y;
  const double radial = (1 + l.k[0] * r2 + l.k[1] * r2 * r2 + l.k[2] * r2 * r2 * r2) /
                        (1 + l.k[3] * r2 + l.k[4] * r2 * r2 + l.k[5] * r2 * r2 * r2);
  const Eigen::Vector2d d = l.Distort({x, y});
  EXPECT_NEAR(d.x(), x * radial + 2 * l.p1 * x * y + l.p2 * (r2 + 2 * x * x), 1e-15);
  EXPECT_NEAR(d.y(), y * radial + l.p1 * (r2 + 2 * y * y) + 2 * l.p2 * x * y, 1e-15);
  const Lens f = FisheyeLens();
  const double theta = std::atan(std::sqrt(r2));
  const double td = theta * (1 + f.k[0] * std::pow(theta, 2) + f.k[1] * std::pow(theta, 4) +
                             f.k[2] * std::pow(theta, 6) + f.k[3] * std::pow(theta, 8));
  const Eigen::Vector2d e = f.Distort({x, y});
  EXPECT_NEAR(e.x(), x * td / std::sqrt(r2), 1e-15);
  EXPECT_NEAR(e.y(), y * td / std::sqrt(r2), 1e-15);
}

TEST(LensTest, UndistortInvertsDistortAcrossTheImage) {
  for (const Lens& l : {OpenCvLens(), FisheyeLens()}) {
    for (double u = 0; u <= l.width; u += 7.5) {
      for (double v = 0; v <= l.height; v += 7.5) {
        const Eigen::Vector2d d((u - l.cx) / l.fx, (v - l.cy) / l.fy);
        Eigen::Vector2d xy;
        ASSERT_TRUE(l.Undistort(d, &xy)) << l.model << " " << u << "," << v;
        EXPECT_LT((l.Distort(xy) - d).norm(), 1e-10) << l.model;
      }
    }
  }
}

TEST(LensTest, EveryColmapModelMapsItsParameters) {
  Lens l;
  const double radial[] = {200, 60, 40, -0.1};
  ASSERT_TRUE(LensFromColmap("SIMPLE_RADIAL", radial, 4, 120, 80, &l).ok());
  EXPECT_EQ(l.kind, Lens::Kind::kRadial);
  EXPECT_EQ(l.fx, 200);
  EXPECT_EQ(l.fy, 200);
  EXPECT_EQ(l.k[0], -0.1);
  const double radial2[] = {200, 60, 40, -0.1, 0.02};
  ASSERT_TRUE(LensFromColmap("RADIAL", radial2, 5, 120, 80, &l).ok());
  EXPECT_EQ(l.k[1], 0.02);
  const double opencv[] = {200, 210, 60, 40, -0.1, 0.02, 0.001, -0.002};
  ASSERT_TRUE(LensFromColmap("OPENCV", opencv, 8, 120, 80, &l).ok());
  EXPECT_EQ(l.fy, 210);
  EXPECT_EQ(l.p1, 0.001);
  EXPECT_EQ(l.p2, -0.002);
  const double full[] = {200, 210, 60, 40, -0.1, 0.02, 0.001, -0.002, 0.003, 0.1, 0.01, 0.001};
  ASSERT_TRUE(LensFromColmap("FULL_OPENCV", full, 12, 120, 80, &l).ok());
  EXPECT_EQ(l.k[2], 0.003);
  EXPECT_EQ(l.k[3], 0.1);
  EXPECT_EQ(l.k[5], 0.001);
  const double fish[] = {200, 210, 60, 40, 0.1, 0.02, 0.003, 0.004};
  ASSERT_TRUE(LensFromColmap("OPENCV_FISHEYE", fish, 8, 120, 80, &l).ok());
  EXPECT_EQ(l.kind, Lens::Kind::kFisheye);
  EXPECT_EQ(l.k[3], 0.004);
  ASSERT_TRUE(LensFromColmap("SIMPLE_RADIAL_FISHEYE", radial, 4, 120, 80, &l).ok());
  EXPECT_EQ(l.kind, Lens::Kind::kFisheye);
  ASSERT_TRUE(LensFromColmap("RADIAL_FISHEYE", radial2, 5, 120, 80, &l).ok());
  EXPECT_EQ(l.k[1], 0.02);
  const double pinhole[] = {200, 210, 60, 40};
  ASSERT_TRUE(LensFromColmap("PINHOLE", pinhole, 4, 120, 80, &l).ok());
  EXPECT_TRUE(l.IsPinhole());
  for (const char* model : {"FOV", "THIN_PRISM_FISHEYE", "WEIRD"}) {
    const Status s = LensFromColmap(model, full, 12, 120, 80, &l);
    ASSERT_FALSE(s.ok()) << model;
    EXPECT_NE(s.message().find(std::string("camera model ") + model + " is not supported"),
              std::string::npos)
        << s.message();
  }
  EXPECT_FALSE(LensFromColmap("OPENCV", opencv, 7, 120, 80, &l).ok());
}

// Each pinhole pixel samples the photo where the lens images that pixel's ray, and every sample
// lies inside the photo (no blank border).
TEST(UndistortionTest, MapsSendEachPinholeRayThroughTheLens) {
  for (const Lens& l : {OpenCvLens(), FisheyeLens()}) {
    Undistortion u;
    ASSERT_TRUE(MakeUndistortion(l, true, "test", &u).ok());
    EXPECT_NE(u.Describe().find(l.model + " lens"), std::string::npos);
    EXPECT_NE(u.Describe().find("undistorted"), std::string::npos);
    for (int y = 0; y < l.height; ++y) {
      for (int x = 0; x < l.width; ++x) {
        const size_t i = static_cast<size_t>(y) * l.width + x;
        const double px = u.map_x[i] + 0.5, py = u.map_y[i] + 0.5;  // to pixel-edge origin
        EXPECT_GE(px, -1e-3);
        EXPECT_LE(px, l.width + 1e-3);
        EXPECT_GE(py, -1e-3);
        EXPECT_LE(py, l.height + 1e-3);
        Eigen::Vector2d xy;
        ASSERT_TRUE(l.Undistort({(px - l.cx) / l.fx, (py - l.cy) / l.fy}, &xy));
        EXPECT_NEAR(xy.x(), (x + 0.5 - u.cx) / u.fx, 1e-5);
        EXPECT_NEAR(xy.y(), (y + 0.5 - u.cy) / u.fy, 1e-5);
      }
    }
    // The pinhole image is not smaller than it must be: its border touches the photo's.
    float min_x = 1e9f, max_x = -1e9f;
    for (float m : u.map_x) {
      min_x = std::min(min_x, m);
      max_x = std::max(max_x, m);
    }
    EXPECT_LT(min_x + 0.5, 2.0) << l.model;
    EXPECT_GT(max_x + 0.5, l.width - 2.0) << l.model;
  }
  Lens folded = OpenCvLens();
  folded.k = {-3, 0, 0, 0, 0, 0};  // folds over inside the photo
  Undistortion u;
  const Status s = MakeUndistortion(folded, false, "cam.json", &u);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("cam.json: the FULL_OPENCV lens"), std::string::npos) << s.message();
}

// A distorted synthetic capture, loaded: each photo comes out as the pinhole image that a pinhole
// camera with the loaded intrinsics sees (rendered exactly), in the COLMAP layout and in the
// nerfstudio transforms.json alike.
TEST(UndistortionTest, DistortedPhotosLoadAsTheirPinholeImages) {
  for (const char* lens : {"opencv", "fisheye"}) {
    SynthOptions o = testing::SmallSynthOptions();
    o.width = o.height = 64;
    o.varying_light = false;
    o.supersampling = 3;
    o.lens = lens;
    o.per_frame_focal = std::string(lens) == "opencv";
    const std::string dir = testing::ScratchDir() + "/" + lens;
    ASSERT_TRUE(WriteSyntheticScene(o, dir).ok());
    SyntheticScene truth;
    ASSERT_TRUE(MakeSyntheticScene(o, &truth).ok());
    const SyntheticRenderer renderer(truth, o);
    for (const bool json : {false, true}) {
      if (json) std::filesystem::remove_all(dir + "/sparse");
      Scene scene;
      ASSERT_TRUE(LoadScene(dir, SceneOptions(), &scene).ok());
      EXPECT_EQ(scene.source, json ? "nerfstudio" : "colmap");
      ASSERT_FALSE(scene.notes.empty());
      EXPECT_NE(scene.notes[0].find("undistorted"), std::string::npos) << scene.notes[0];
      EXPECT_EQ(scene.TestIndices().size(), 3u);
      for (size_t i = 0; i < scene.views.size(); i += 5) {
        const View& v = scene.views[i];
        Image rgba, depth, normal;
        renderer.Render(v.camera, truth.lights[i], &rgba, &depth, &normal);
        View rendered = v;
        rendered.image = ExtractChannels(rgba, 0, 3);
        rendered.alpha = ExtractChannels(rgba, 3, 1);
        const Image exact = CompositeOnBackground(rendered, 0.0f);
        const double loaded = Psnr(CompositeOnBackground(v, 0.0f), exact);
        // The photo as it was, read as if pinhole: what was trained on before.
        Image photo;
        ASSERT_TRUE(ReadImage(dir + "/images/" + truth.names[i], &photo).ok());
        View raw = v;
        raw.image = ExtractChannels(photo, 0, 3);
        raw.alpha = ExtractChannels(photo, 3, 1);
        const double unrectified = Psnr(CompositeOnBackground(raw, 0.0f), exact);
        EXPECT_GT(loaded, 28.0) << lens << " view " << i;
        EXPECT_GT(loaded, unrectified + 3.0) << lens << " view " << i;
      }
    }
  }
}

}  // namespace
}  // namespace mgsr
