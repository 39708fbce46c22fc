// Scene-level synthetic captures (mgsr_synth --scene_type outdoor|indoor): the layout's ground
// truth is exactly the region's object and ground, the photos are unmasked RGB with a sky where
// nothing is hit outdoors (none indoors), depth back-projects onto the scene, and the cameras stand
// on a wide orbit at standing height.
#include "mgsr/synth/scene_layout.h"

#include <gtest/gtest.h>

#include <cmath>

#include "mgsr/eval/closest_point.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"
#include "mgsr/io/ply.h"
#include "mgsr/io/scene.h"
#include "mgsr/synth/ray_caster.h"
#include "mgsr/synth/shapes.h"
#include "mgsr/synth/synthetic_scene.h"
#include "test_util.h"

namespace mgsr {
namespace {

TEST(SceneLayoutTest, GroundTruthIsTheObjectAndTheGroundInsideTheRegion) {
  const TriangleMesh object = MakeIcoSphere(1.0, 2);
  for (SceneType type : {SceneType::kOutdoor, SceneType::kIndoor}) {
    const SceneLayout l = MakeSceneLayout(object, type, 2.0);
    ASSERT_EQ(l.materials.size(), l.mesh.triangles.size());
    EXPECT_EQ(l.object_triangles, static_cast<int>(object.triangles.size()));
    EXPECT_NEAR(l.ground_z, -1.0, 1e-9);  // the sphere rests on the ground
    // The ground truth's area: the object's plus a 4 x 4 square of ground, exactly.
    EXPECT_NEAR(l.ground_truth.SurfaceArea(), object.SurfaceArea() + 16.0, 1e-9);
    for (const auto& v : l.ground_truth.vertices) {
      EXPECT_TRUE(l.region.contains(v)) << v.transpose();
    }
    // Walls only indoors, and all of the scene far beyond the region.
    int walls = 0;
    double reach = 0;
    for (size_t t = 0; t < l.mesh.triangles.size(); ++t) {
      walls += l.materials[t] == SurfaceMaterial::kWall;
      for (int k = 0; k < 3; ++k)
        reach = std::max(reach, l.mesh.vertices[l.mesh.triangles[t][k]].head<2>().norm());
    }
    EXPECT_EQ(walls > 0, type == SceneType::kIndoor);
    EXPECT_GT(reach, type == SceneType::kOutdoor ? 14.0 : 4.9);
  }
  // An object capture: the ground truth is the object itself.
  EXPECT_EQ(MakeSceneLayout(object, SceneType::kObject, 2.0).ground_truth.triangles.size(),
            object.triangles.size());
}

class SceneLevelCaptureTest : public ::testing::TestWithParam<std::string> {};

TEST_P(SceneLevelCaptureTest, UnmaskedPhotosExactDepthAndAStandingOrbit) {
  const std::string dir = testing::ScratchDir("_" + GetParam());
  SynthOptions o = testing::SmallSynthOptions();
  o.scene_type = GetParam();
  o.width = 48;
  o.height = 36;
  o.num_points = 300;
  ASSERT_TRUE(WriteSyntheticScene(o, dir).ok());
  EXPECT_FALSE(DirectoryExists(dir + "/masks"));
  ASSERT_TRUE(FileExists(dir + "/gt/region.json"));
  Scene scene;
  ASSERT_TRUE(LoadScene(dir, SceneOptions(), &scene).ok());
  SyntheticScene truth;
  ASSERT_TRUE(MakeSyntheticScene(o, &truth).ok());
  const RayCaster caster(truth.layout.mesh);
  int sky = 0, pixels = 0;
  for (size_t i = 0; i < scene.views.size(); ++i) {
    const View& v = scene.views[i];
    EXPECT_TRUE(v.mask.empty());
    EXPECT_EQ(v.image.channels(), 3);
    // Standing height over the ground, outside the region, facing its centre.
    const Eigen::Vector3d c = v.camera.Center();
    EXPECT_GE(c.z() - truth.layout.ground_z, 1.3 - 1e-9);
    EXPECT_LE(c.z() - truth.layout.ground_z, 1.9 + 1e-9);
    EXPECT_GT(c.head<2>().norm(), 0.9 * o.distance);
    EXPECT_GT(v.camera.R.row(2).dot(-c.normalized()), 0.95);
    Image depth;
    ASSERT_TRUE(ReadPfm(dir + "/gt/depth/" + FileStem(v.name) + ".pfm", &depth).ok());
    for (int y = 0; y < depth.height(); y += 3) {
      for (int x = 0; x < depth.width(); x += 3) {
        ++pixels;
        const float z = depth.at(0, y, x);
        if (z <= 0) {
          ++sky;
          continue;
        }
        const Eigen::Vector3d X = v.camera.CameraToWorld(v.camera.PixelToRay(x + 0.5, y + 0.5) * z);
        RayHit hit;
        ASSERT_TRUE(caster.Intersect(c, X - c, 1e-9, 2.0, &hit));
        EXPECT_NEAR(hit.t, 1.0, 1e-4) << v.name << " pixel " << x << "," << y;
      }
    }
  }
  // Outdoors a sky above the horizon; a room is closed.
  if (GetParam() == "outdoor") {
    EXPECT_GT(sky, pixels / 20);
  } else {
    EXPECT_EQ(sky, 0);
  }
  // SfM points on the object and on the ground.
  int on_ground = 0, on_object = 0;
  for (const Eigen::Vector3f& p : scene.points) {
    if (std::abs(p.z() - truth.layout.ground_z) < 1e-5) {
      ++on_ground;
    } else if (p.norm() < 1.0 + 1e-5) {
      ++on_object;
    }
  }
  EXPECT_GT(on_ground, 30);
  EXPECT_GT(on_object, 30);
}

INSTANTIATE_TEST_SUITE_P(Types, SceneLevelCaptureTest, ::testing::Values("outdoor", "indoor"));

TEST(SceneLevelCaptureTest, RefusesAnUnknownTypeAndARoomTooSmallForTheOrbit) {
  SynthOptions o = testing::SmallSynthOptions();
  o.scene_type = "forest";
  EXPECT_NE(o.Validate().message().find("scene_type"), std::string::npos);
  o.scene_type = "indoor";
  o.distance = 6;
  EXPECT_NE(o.Validate().message().find("indoors"), std::string::npos);
}

}  // namespace
}  // namespace mgsr
