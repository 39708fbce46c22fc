#include "mgsr/mesh/exact_depth_ceiling.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "mgsr/eval/mesh_metrics.h"
#include "mgsr/synth/ray_caster.h"
#include "mgsr/synth/shapes.h"

namespace mgsr {
namespace {

// Cameras on a Fibonacci sphere of radius 3.5 looking at the origin.
std::vector<Camera> RingOfCameras(int count, int size) {
  std::vector<Camera> cameras;
  const double golden = M_PI * (3 - std::sqrt(5.0));
  for (int i = 0; i < count; ++i) {
    const double z = 0.9 - 1.6 * (i + 0.5) / count, r = std::sqrt(1 - z * z);
    const Eigen::Vector3d center(3.5 * r * std::cos(golden * i), 3.5 * r * std::sin(golden * i),
                                 3.5 * z);
    cameras.push_back(LookAtCamera(center, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ(), size,
                                   size, size * 1.39, size * 1.39));
  }
  return cameras;
}

TEST(ExactDepthCeilingTest, ExactDepthIsTheRayCastZ) {
  const TriangleMesh sphere = MakeIcoSphere(1.0, 5);
  const RayCaster caster(sphere);
  const Camera camera = RingOfCameras(1, 64).front();
  const Image depth = RenderExactDepth(caster, camera);
  // The centre pixel looks straight at the sphere: z = distance - radius (up to tessellation).
  const float z = depth.at(0, 32, 32);
  EXPECT_NEAR(z, (camera.Center().norm() - 1.0), 2e-3);
  EXPECT_EQ(depth.at(0, 0, 0), 0.0f);  // the corner misses
}

// Kept or cast again, every read is the camera's own exact depth; the budget bounds what is kept.
TEST(ExactDepthCeilingTest, ExactDepthViewsKeepWithinTheirBudget) {
  const TriangleMesh sphere = MakeIcoSphere(1.0, 4);
  const RayCaster caster(sphere);
  const std::vector<Camera> cameras = RingOfCameras(3, 48);
  const size_t one_image = 48 * 48 * sizeof(float);
  for (const size_t budget : {size_t{0}, one_image, 3 * one_image}) {
    ExactDepthViews views(caster, cameras, budget);
    ASSERT_EQ(views.size(), 3u);
    for (const size_t k : {0, 1, 2, 0, 2, 1, 1}) {
      const Image expected = RenderExactDepth(caster, cameras[k]);
      const Image got = views.Depth(k);
      ASSERT_TRUE(got.SameShape(expected));
      for (size_t p = 0; p < got.size(); ++p) ASSERT_EQ(got.data()[p], expected.data()[p]) << k;
    }
    EXPECT_EQ(views.kept_bytes(), std::min(budget, 3 * one_image)) << budget;
  }
}

// The ceiling of a sphere is a sphere: fused exact depth lies within 0.2 voxels of the surface.
TEST(ExactDepthCeilingTest, ExactDepthOfASphereFusesToTheSphere) {
  const TriangleMesh sphere = MakeIcoSphere(0.8, 6);
  const std::vector<Camera> cameras = RingOfCameras(32, 128);
  TsdfOptions o;
  o.voxel_size = AutoVoxelSize(cameras, LookAtCenter(cameras));
  EXPECT_NEAR(LookAtCenter(cameras).norm(), 0.0, 1e-9);
  TriangleMesh fused;
  ASSERT_TRUE(FuseExactDepth(sphere, cameras, o, &fused).ok());
  ASSERT_FALSE(fused.empty());
  MeshMetricsOptions mo;
  mo.pixel_footprint = o.voxel_size;
  const MeshMetrics m = EvaluateMesh(fused, sphere, mo);
  ASSERT_TRUE(m.ok);
  EXPECT_LT(std::abs(m.signed_offset_median), 0.2 * o.voxel_size);
  EXPECT_LT(m.chamfer, 0.2 * o.voxel_size);
  EXPECT_GT(m.normal_consistency, 0.98);
  // Vertex by vertex: the mesh's vertices are on the sphere within 0.2 voxels (median).
  std::vector<double> off;
  for (const auto& v : fused.vertices) off.push_back(std::abs(v.norm() - 0.8));
  std::nth_element(off.begin(), off.begin() + off.size() / 2, off.end());
  EXPECT_LT(off[off.size() / 2], 0.2 * o.voxel_size);
  // No voxel size: an error, not a guess.
  EXPECT_FALSE(FuseExactDepth(sphere, cameras, TsdfOptions(), &fused).ok());
}

}  // namespace
}  // namespace mgsr
