#include "mgsr/eval/mesh_metrics.h"

#include <gtest/gtest.h>

#include <cmath>

#include "mgsr/synth/shapes.h"

namespace mgsr {
namespace {

TEST(MeshMetricsTest, SamplingIsAreaUniformAndOnTheSurface) {
  const TriangleMesh sphere = MakeIcoSphere(1.0, 4);
  const SurfaceSamples s = SampleSurface(sphere, 20000, 3);
  ASSERT_EQ(s.points.size(), 20000u);
  ASSERT_EQ(s.normals.size(), 20000u);
  int upper = 0;
  for (size_t i = 0; i < s.points.size(); ++i) {
    EXPECT_NEAR(s.points[i].norm(), 1.0, 2e-3);
    EXPECT_GT(s.normals[i].dot(s.points[i]), 0.99);  // outward face normals
    upper += s.points[i].z() > 0.5;
  }
  // The cap z > 0.5 holds a quarter of a sphere's area (Archimedes).
  EXPECT_NEAR(upper / 20000.0, 0.25, 0.015);
  // Same seed, same samples.
  EXPECT_EQ(SampleSurface(sphere, 100, 3).points, SampleSurface(sphere, 100, 3).points);
}

TEST(MeshMetricsTest, IdenticalMeshesScoreNearPerfect) {
  const TriangleMesh m = MakeTorus(0.65, 0.3, 96, 48);
  MeshMetricsOptions o;
  const MeshMetrics r = EvaluateMesh(m, m, o);
  ASSERT_TRUE(r.ok);
  // Independent samples of one surface: distances are a fraction of the sample spacing.
  const double spacing = std::sqrt(m.SurfaceArea() / o.num_samples);
  EXPECT_LT(r.chamfer, 0.5 * spacing);
  EXPECT_GT(r.normal_consistency, 0.99);
  o.fscore_threshold = 2 * spacing;
  EXPECT_GT(EvaluateMesh(m, m, o).fscore, 0.99);
}

TEST(MeshMetricsTest, ConcentricSpheresGiveTheirGap) {
  const double r = 0.8, d = 0.1;
  const TriangleMesh inner = MakeIcoSphere(r, 5), outer = MakeIcoSphere(r + d, 5);
  MeshMetricsOptions o;
  o.fscore_threshold = 0.05;
  const MeshMetrics m = EvaluateMesh(outer, inner, o);
  ASSERT_TRUE(m.ok);
  EXPECT_NEAR(m.chamfer, d, 0.1 * d);
  EXPECT_NEAR(m.accuracy, d, 0.1 * d);
  EXPECT_NEAR(m.completeness, d, 0.1 * d);
  EXPECT_GT(m.normal_consistency, 0.98);
  EXPECT_EQ(m.fscore, 0.0);  // every distance exceeds the threshold
}

TEST(MeshMetricsTest, FlippedNormalsStillScoreOne) {
  const TriangleMesh m = MakeIcoSphere(1.0, 4);
  TriangleMesh flipped = m;
  for (auto& f : flipped.triangles) std::swap(f[1], f[2]);
  const MeshMetrics r = EvaluateMesh(flipped, m, MeshMetricsOptions());
  ASSERT_TRUE(r.ok);
  EXPECT_GT(r.normal_consistency, 0.99);
}

TEST(MeshMetricsTest, EmptyAndDegenerateMeshesFailWithoutCrashing) {
  const TriangleMesh gt = MakeIcoSphere(1.0, 2);
  MeshMetrics r = EvaluateMesh(TriangleMesh(), gt, MeshMetricsOptions());
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.failure, "predicted mesh is empty");
  EXPECT_TRUE(std::isinf(r.chamfer));
  EXPECT_EQ(r.normal_consistency, 0.0);
  TriangleMesh flat;
  flat.vertices = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}};  // collinear: zero area
  flat.triangles = {{0, 1, 2}};
  r = EvaluateMesh(flat, gt, MeshMetricsOptions());
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.failure, "predicted mesh has no area");
  r = EvaluateMesh(gt, TriangleMesh(), MeshMetricsOptions());
  EXPECT_FALSE(r.ok);
  EXPECT_TRUE(std::isinf(r.chamfer));
}

TEST(MeshMetricsTest, PointCloudGroundTruthUsesItsPoints) {
  const TriangleMesh m = MakeIcoSphere(1.0, 5);
  TriangleMesh cloud;
  cloud.vertices = m.vertices;
  cloud.vertex_normals = m.vertex_normals;
  const MeshMetrics r = EvaluateMesh(m, cloud, MeshMetricsOptions());
  ASSERT_TRUE(r.ok);
  EXPECT_LT(r.chamfer, 0.6 * std::sqrt(m.SurfaceArea() / 10000));  // about half the spacing
  EXPECT_GT(r.normal_consistency, 0.98);
}

}  // namespace
}  // namespace mgsr
