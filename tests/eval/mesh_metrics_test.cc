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

TEST(MeshMetricsTest, IdenticalMeshesScoreZero) {
  const TriangleMesh m = MakeTorus(0.65, 0.3, 96, 48);
  MeshMetricsOptions o;
  o.pixel_footprint = 0.01;
  const MeshMetrics r = EvaluateMesh(m, m, o);
  ASSERT_TRUE(r.ok);
  // Point to triangle: every sample lies on the other mesh, whatever the sample spacing.
  EXPECT_LT(r.chamfer, 1e-12);
  EXPECT_LT(std::abs(r.signed_offset_median), 1e-12);
  EXPECT_GT(r.normal_consistency, 0.9999);
  EXPECT_EQ(r.fscore, 1.0);
  ASSERT_EQ(r.fscores.size(), o.fscore_thresholds.size() + o.fscore_footprints.size());
  for (const FScore& f : r.fscores) EXPECT_EQ(f.fscore, 1.0);
  EXPECT_EQ(r.fscores.back().footprints, 2.0);
  EXPECT_DOUBLE_EQ(r.fscores.back().threshold, 0.02);
}

// A copy moved along its vertex normals by a known delta: the signed offset and CD give delta, the
// sign tells inside from outside, and the F-score switches at delta.
TEST(MeshMetricsTest, MeshMovedAlongItsNormalsReportsTheOffset) {
  for (const char* shape : {"torus", "dented"}) {
    TriangleMesh gt;
    ASSERT_TRUE(MakeShape(shape, 2, &gt));
    for (const double delta : {-0.004, 0.004, -0.02}) {
      TriangleMesh moved = gt;
      for (size_t i = 0; i < moved.vertices.size(); ++i)
        moved.vertices[i] += delta * gt.vertex_normals[i].normalized();
      MeshMetricsOptions o;
      o.fscore_thresholds = {0.5 * std::abs(delta), 2 * std::abs(delta)};
      const MeshMetrics r = EvaluateMesh(moved, gt, o);
      ASSERT_TRUE(r.ok);
      SCOPED_TRACE(std::string(shape) + " delta " + std::to_string(delta));
      EXPECT_NEAR(r.signed_offset_median, delta, 0.05 * std::abs(delta));
      EXPECT_NEAR(r.signed_offset_median_gt, delta, 0.05 * std::abs(delta));
      EXPECT_NEAR(r.chamfer, std::abs(delta), 0.1 * std::abs(delta));
      EXPECT_NEAR(r.fraction_inside, delta < 0 ? 1.0 : 0.0, 0.05);
      EXPECT_LT(r.fscores[0].fscore, 0.1);
      EXPECT_GT(r.fscores[1].fscore, 0.9);
    }
  }
}

// Completeness from a subset of the ground truth (its visible part) ignores the rest.
TEST(MeshMetricsTest, CompletenessFromGivenPoints) {
  const TriangleMesh sphere = MakeIcoSphere(1.0, 4);
  TriangleMesh cap;  // predicted: only the upper half of the sphere
  cap.vertices = sphere.vertices;
  for (const auto& f : sphere.triangles) {
    if (sphere.vertices[f[0]].z() > 0 && sphere.vertices[f[1]].z() > 0 &&
        sphere.vertices[f[2]].z() > 0)
      cap.triangles.push_back(f);
  }
  MeshMetricsOptions o;
  const MeshMetrics whole = EvaluateMesh(cap, sphere, o);
  EXPECT_GT(whole.completeness, 0.2);
  TriangleMesh visible;  // ground-truth points of the upper half only
  for (const auto& v : sphere.vertices)
    if (v.z() > 0.1) visible.vertices.push_back(v);
  o.completeness_points = &visible;
  const MeshMetrics part = EvaluateMesh(cap, sphere, o);
  EXPECT_LT(part.completeness, 1e-12);
  EXPECT_LT(part.accuracy, 1e-12);
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
