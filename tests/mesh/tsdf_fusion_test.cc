#include "mgsr/mesh/tsdf_fusion.h"

#include <gtest/gtest.h>

#include <utility>

#include "mgsr/core/timer.h"
#include "mgsr/eval/mesh_metrics.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"
#include "mgsr/io/ply.h"
#include "mgsr/io/scene.h"
#include "mgsr/synth/shapes.h"
#include "test_util.h"

namespace mgsr {
namespace {

// Fusing the exact depth maps of a synthetic scene must give back its ground-truth mesh.
class TsdfOfExactDepthTest : public ::testing::TestWithParam<std::string> {};

TEST_P(TsdfOfExactDepthTest, ReconstructsTheGroundTruth) {
  const std::string dir = testing::ScratchDir("_" + GetParam());
  SynthOptions o;
  o.shape = GetParam();
  o.num_views = 48;
  o.width = o.height = 128;
  o.supersampling = 1;
  o.num_points = 100;
  ASSERT_TRUE(WriteSyntheticScene(o, dir).ok());
  Scene scene;
  ASSERT_TRUE(LoadScene(dir, SceneOptions(), &scene).ok());
  std::vector<DepthFrame> frames;
  for (int i : scene.TrainIndices()) {
    DepthFrame f;
    f.camera = scene.views[i].camera;
    ASSERT_TRUE(
        ReadPfm(dir + "/gt/depth/" + FileStem(scene.views[i].name) + ".pfm", &f.depth).ok());
    f.color = scene.views[i].image;
    f.weight = scene.views[i].mask;
    frames.push_back(std::move(f));
  }
  TsdfOptions options;
  const double voxel = AutoVoxelSize(frames, Eigen::Vector3d::Zero());
  Timer timer;
  TriangleMesh mesh;
  ASSERT_TRUE(FuseDepthMaps(frames, options, &mesh).ok());
  const double seconds = timer.ElapsedSeconds();
  TriangleMesh gt;
  ASSERT_TRUE(ReadTriangleMesh(dir + "/gt/mesh.ply", &gt).ok());
  const MeshMetrics m = EvaluateMesh(mesh, gt, MeshMetricsOptions());
  ASSERT_TRUE(m.ok) << m.failure;
  std::printf(
      "[ tsdf     ] %s: voxel %.4f, %zu triangles, CD %.5f (%.2f voxels), NC %.4f, %.2f s\n",
      GetParam().c_str(), voxel, mesh.triangles.size(), m.chamfer, m.chamfer / voxel,
      m.normal_consistency, seconds);
  EXPECT_LT(m.chamfer, 1.5 * voxel);
  // Fusion at the voxel's size rounds a 90-degree edge over a voxel or two: sharp-edged shapes
  // (measured 0.94 to 0.97) are held to less than smooth ones.
  EXPECT_GT(m.normal_consistency, ShapeHasSharpEdges(GetParam()) ? 0.93 : 0.97);
  EXPECT_EQ(mesh.vertex_colors.size(), mesh.vertices.size());
}

INSTANTIATE_TEST_SUITE_P(AllShapes, TsdfOfExactDepthTest, ::testing::ValuesIn(ShapeNames()));

TEST(TsdfFusionTest, EmptyInputIsAnErrorNotACrash) {
  TriangleMesh mesh;
  EXPECT_FALSE(FuseDepthMaps({}, TsdfOptions(), &mesh).ok());
  DepthFrame f;
  f.camera = LookAtCamera({0, -3, 0}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 16, 16, 20, 20);
  f.depth = Image(16, 16, 1, 0.0f);
  const Status s = FuseDepthMaps({f}, TsdfOptions(), &mesh);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("every depth map is empty"), std::string::npos);
}

// One view of two flat patches at the same depth, a large and a small one with empty pixels
// between them: without the clean-up both are meshed; with keep_largest_component only the large
// one is, and all of it.
TEST(TsdfFusionTest, KeepsOnlyTheLargestConnectedPiece) {
  DepthFrame f;
  f.camera = LookAtCamera({0, -3, 0}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 64, 64, 64, 64);
  f.depth = Image(64, 64, 1, 0.0f);
  auto in_large = [](double x, double y) { return x > 4 && x < 44 && y > 10 && y < 50; };
  auto in_small = [](double x, double y) { return x > 52 && x < 60 && y > 52 && y < 60; };
  for (int y = 0; y < 64; ++y) {
    for (int x = 0; x < 64; ++x) {
      if (in_large(x + 0.5, y + 0.5) || in_small(x + 0.5, y + 0.5)) f.depth.at(0, y, x) = 3.0f;
    }
  }
  TsdfOptions options;
  options.voxel_size = 0.02;
  // Triangles by where their first vertex lands in the view: large patch, small patch.
  auto count = [&](const TriangleMesh& mesh) {
    std::pair<int, int> n{0, 0};
    for (const auto& t : mesh.triangles) {
      const Eigen::Vector2d p = f.camera.WorldToPixel(mesh.vertices[t[0]].cast<double>());
      n.first += in_large(p.x(), p.y());
      n.second += in_small(p.x(), p.y());
    }
    return n;
  };
  TriangleMesh all, largest;
  ASSERT_TRUE(FuseDepthMaps({f}, options, &all).ok());
  options.keep_largest_component = true;
  ASSERT_TRUE(FuseDepthMaps({f}, options, &largest).ok());
  const auto [all_large, all_small] = count(all);
  const auto [kept_large, kept_small] = count(largest);
  EXPECT_GT(all_large, 100);
  EXPECT_GT(all_small, 4);
  EXPECT_EQ(kept_large, all_large);
  EXPECT_EQ(kept_small, 0);
  EXPECT_EQ(largest.triangles.size(), static_cast<size_t>(kept_large));
  EXPECT_EQ(largest.vertices.size(), largest.vertex_colors.size());
  // Small-cluster clean-up instead: pieces of at least a share of the largest stay (the small
  // patch has about 4% of the large one's triangles).
  TriangleMesh both, one;
  options.min_component_share = 0.01;
  ASSERT_TRUE(FuseDepthMaps({f}, options, &both).ok());
  options.min_component_share = 0.1;
  ASSERT_TRUE(FuseDepthMaps({f}, options, &one).ok());
  EXPECT_EQ(count(both), count(all));
  EXPECT_EQ(count(one), count(largest));
}

}  // namespace
}  // namespace mgsr
