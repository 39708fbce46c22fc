// The fusion region: found from the cameras where most of their frusta meet, parsed from a box or
// a file, and fusion that ignores depth beyond it (a scene-level capture's ground and walls).
#include "mgsr/mesh/fusion_region.h"

#include <gtest/gtest.h>

#include <cmath>

#include "mgsr/eval/mesh_metrics.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"
#include "mgsr/io/ply.h"
#include "mgsr/io/scene.h"
#include "mgsr/mesh/tsdf_fusion.h"
#include "mgsr/synth/synthetic_scene.h"
#include "test_util.h"

namespace mgsr {
namespace {

// 24 cameras once around `centre` at radius 4 and 1.5 above it, 60 degrees wide, looking at it.
std::vector<Camera> Ring(const Eigen::Vector3d& centre) {
  std::vector<Camera> cameras;
  const double fx = 64 / (2 * std::tan(M_PI / 6));
  for (int i = 0; i < 24; ++i) {
    const double a = 2 * M_PI * i / 24;
    const Eigen::Vector3d eye = centre + Eigen::Vector3d(4 * std::cos(a), 4 * std::sin(a), 1.5);
    cameras.push_back(LookAtCamera(eye, centre, Eigen::Vector3d::UnitZ(), 64, 64, fx, fx));
  }
  return cameras;
}

TEST(FusionRegionTest, FromCamerasIsWhereMostFrustaMeet) {
  const Eigen::Vector3d centre(5, -2, 1);
  const std::vector<Camera> cameras = Ring(centre);
  const Eigen::AlignedBox3d region = RegionFromCameras(cameras);
  ASSERT_FALSE(region.isEmpty());
  // Around the centre: a ball of radius 1 is inside; the ring itself and what lies beyond it, or
  // above the cameras, is not. (A 60 degree ring shares a wide volume: about +-3.6 across.)
  for (const Eigen::Vector3d& d :
       {Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0, -1, 0), Eigen::Vector3d(0, 0, 1),
        Eigen::Vector3d(0, 0, -1), Eigen::Vector3d(-0.7, 0.7, 0)}) {
    EXPECT_TRUE(region.contains(centre + d)) << d.transpose();
  }
  EXPECT_FALSE(region.contains(centre + Eigen::Vector3d(4, 0, 0)));
  EXPECT_FALSE(region.contains(centre + Eigen::Vector3d(0, -4, 0)));
  EXPECT_FALSE(region.contains(centre + Eigen::Vector3d(0, 0, 3)));
  EXPECT_LT((region.center() - centre).head<2>().norm(), 0.3);
  // Asking more cameras to agree gives a smaller region inside the first.
  const Eigen::AlignedBox3d strict = RegionFromCameras(cameras, 0.9);
  ASSERT_FALSE(strict.isEmpty());
  EXPECT_TRUE(region.contains(strict));
  EXPECT_LT(strict.volume(), region.volume());
  // Cameras that share nothing: two looking away from each other.
  std::vector<Camera> apart = {cameras[0], cameras[12]};
  for (Camera& c : apart) {
    const Eigen::Vector3d eye = c.Center();
    c = LookAtCamera(eye, eye + (eye - centre), Eigen::Vector3d::UnitZ(), 64, 64, c.fx, c.fy);
  }
  EXPECT_TRUE(RegionFromCameras(apart, 1.0).isEmpty());
}

TEST(FusionRegionTest, ParsesABoxOrAFileAndNamesWhatIsWrong) {
  Eigen::AlignedBox3d r;
  ASSERT_TRUE(ParseRegion("-1,-2,-3,1,2,3.5", &r).ok());
  EXPECT_EQ(r.min(), Eigen::Vector3d(-1, -2, -3));
  EXPECT_EQ(r.max(), Eigen::Vector3d(1, 2, 3.5));
  const std::string dir = testing::ScratchDir();
  ASSERT_TRUE(
      WriteStringToFileAtomic(dir + "/region.json", R"({"min": [0, 0, 0], "max": [1, 2, 3]})")
          .ok());
  ASSERT_TRUE(ParseRegion(dir + "/region.json", &r).ok());
  EXPECT_EQ(r.max(), Eigen::Vector3d(1, 2, 3));
  ASSERT_TRUE(
      WriteStringToFileAtomic(dir + "/bad.json", R"({"min": [0, 0], "max": [1, 2, 3]})").ok());
  const Status bad_file = ParseRegion(dir + "/bad.json", &r);
  EXPECT_NE(bad_file.message().find("bad.json"), std::string::npos) << bad_file.message();
  const Status flipped = ParseRegion("1,0,0,0,1,1", &r);
  EXPECT_NE(flipped.message().find("max"), std::string::npos) << flipped.message();
  const Status junk = ParseRegion("1,2,x", &r);
  EXPECT_NE(junk.message().find("'1,2,x'"), std::string::npos) << junk.message();
}

TEST(FusionRegionTest, FusionIgnoresDepthBeyondTheRegion) {
  // An outdoor capture: exact depth of the object, the ground out to 15 units and the sky.
  const std::string dir = testing::ScratchDir();
  SynthOptions o = testing::SmallSynthOptions();
  o.scene_type = "outdoor";
  o.width = 96;
  o.height = 72;
  o.num_views = 24;
  ASSERT_TRUE(WriteSyntheticScene(o, dir).ok());
  Scene scene;
  const Status loaded = LoadScene(dir, SceneOptions(), &scene);
  ASSERT_TRUE(loaded.ok()) << loaded.message();
  std::vector<DepthFrame> frames;
  for (const View& v : scene.views) {
    DepthFrame f;
    f.camera = v.camera;
    ASSERT_TRUE(ReadPfm(dir + "/gt/depth/" + FileStem(v.name) + ".pfm", &f.depth).ok());
    frames.push_back(std::move(f));
  }
  Eigen::AlignedBox3d region;
  ASSERT_TRUE(ParseRegion(dir + "/gt/region.json", &region).ok());
  TsdfOptions options;
  options.voxel_size = 0.05;
  TriangleMesh everything, inside;
  ASSERT_TRUE(FuseDepthMaps(frames, options, &everything).ok());
  options.region = region;
  options.keep_largest_component = true;
  options.min_component_share = 0.02;
  ASSERT_TRUE(FuseDepthMaps(frames, options, &inside).ok());
  // Without the region the ground is meshed far out; with it nothing lies outside.
  double reach = 0;
  for (const auto& v : everything.vertices) reach = std::max(reach, v.head<2>().norm());
  EXPECT_GT(reach, 5.0);
  ASSERT_GT(inside.triangles.size(), 1000u);
  for (const auto& v : inside.vertices) ASSERT_TRUE(region.contains(v)) << v.transpose();
  // And what is inside is the ground truth of the region (object and ground).
  TriangleMesh gt;
  ASSERT_TRUE(ReadTriangleMesh(dir + "/gt/mesh.ply", &gt).ok());
  const MeshMetrics m = EvaluateMesh(inside, gt, MeshMetricsOptions());
  ASSERT_TRUE(m.ok) << m.failure;
  EXPECT_LT(m.chamfer, 2 * options.voxel_size);
  EXPECT_GT(m.normal_consistency, 0.97);
  // The largest component alone would be the ground without the object (they need not touch).
  options.min_component_share = 1.0;
  TriangleMesh largest;
  ASSERT_TRUE(FuseDepthMaps(frames, options, &largest).ok());
  EXPECT_GT(EvaluateMesh(largest, gt, MeshMetricsOptions()).completeness, 10 * m.completeness);
  // Cropping a mesh keeps exactly its triangles inside.
  TriangleMesh cropped = everything;
  CropMeshToRegion(region, &cropped);
  EXPECT_LT(cropped.triangles.size(), everything.triangles.size());
  for (const auto& v : cropped.vertices) ASSERT_TRUE(region.contains(v));
}

}  // namespace
}  // namespace mgsr
