#include "mgsr/eval/closest_point.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "mgsr/core/rng.h"
#include "mgsr/synth/shapes.h"

namespace mgsr {
namespace {

Eigen::Vector3d RandomPoint(Rng* rng, double scale) {
  return Eigen::Vector3d(rng->Uniform() - 0.5, rng->Uniform() - 0.5, rng->Uniform() - 0.5) *
         (2 * scale);
}

// The closest point minimises the distance over the triangle: no point of a fine barycentric grid
// is closer, and it lies on the triangle (its barycentrics are in [0, 1]).
TEST(ClosestPointTest, TriangleClosestPointBeatsEveryGridPoint) {
  Rng rng(7);
  for (int trial = 0; trial < 300; ++trial) {
    const Eigen::Vector3d a = RandomPoint(&rng, 1), b = RandomPoint(&rng, 1),
                          c = RandomPoint(&rng, 1), p = RandomPoint(&rng, 2);
    const Eigen::Vector3d q = ClosestPointOnTriangle(p, a, b, c);
    const double d = (q - p).norm();
    double grid_best = 1e30;
    const int n = 60;
    for (int i = 0; i <= n; ++i) {
      for (int j = 0; i + j <= n; ++j) {
        const Eigen::Vector3d g = a + (b - a) * (double(i) / n) + (c - a) * (double(j) / n);
        grid_best = std::min(grid_best, (g - p).norm());
      }
    }
    EXPECT_LE(d, grid_best + 1e-12) << "trial " << trial;
    EXPECT_GT(d, grid_best - 0.05) << "trial " << trial;  // the grid is a 1/60 net
    // q on the plane of the triangle and inside it.
    const Eigen::Vector3d nrm = (b - a).cross(c - a);
    EXPECT_NEAR((q - a).dot(nrm.normalized()), 0.0, 1e-9);
    const double area = nrm.norm();
    const double u = (q - a).cross(c - a).norm() / area, v = (b - a).cross(q - a).norm() / area;
    EXPECT_LE(u + v, 1 + 1e-9);
  }
}

// The indexed query equals brute force over every triangle, including for points far off the
// surface and exactly on it.
TEST(ClosestPointTest, IndexAgreesWithBruteForce) {
  const TriangleMesh mesh = MakeDentedSphereWithRod(2);
  const TriangleClosestPoint index(mesh);
  ASSERT_FALSE(index.empty());
  Rng rng(3);
  for (int trial = 0; trial < 400; ++trial) {
    const double scale = trial % 4 == 0 ? 3.0 : 1.2;
    const Eigen::Vector3d p = RandomPoint(&rng, scale);
    double best = 1e30;
    for (const auto& f : mesh.triangles) {
      best = std::min(best, (ClosestPointOnTriangle(p, mesh.vertices[f[0]], mesh.vertices[f[1]],
                                                    mesh.vertices[f[2]]) -
                             p)
                                .norm());
    }
    const ClosestPoint c = index.Query(p);
    ASSERT_GE(c.triangle, 0);
    EXPECT_NEAR(c.distance, best, 1e-12) << "trial " << trial;
    EXPECT_NEAR((c.point - p).norm(), c.distance, 1e-12);
  }
  // A vertex of the mesh is at distance 0.
  EXPECT_NEAR(index.Query(mesh.vertices[17]).distance, 0.0, 1e-12);
}

// One stray vertex far away (a mesh an audit fed mgsr_eval): its few huge triangles are tested
// directly instead of being sampled, so the search ball stays small, and the answer stays exact.
TEST(ClosestPointTest, AFarAwayVertexKeepsTheAnswerExact) {
  TriangleMesh mesh = MakeDentedSphereWithRod(2);
  const int far = static_cast<int>(mesh.vertices.size());
  mesh.vertices.emplace_back(1e6, 2e5, -3e5);
  mesh.triangles.emplace_back(0, 1, far);
  mesh.triangles.emplace_back(5, far, 9);
  const TriangleClosestPoint index(mesh);
  // The search stays local: the sphere's own sampling sets the slack, not the far triangles
  // (sampled, they set it to thousands of units and every query visited every sample).
  EXPECT_LT(index.search_slack(), 0.1);
  Rng rng(4);
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Vector3d p = RandomPoint(&rng, trial % 5 == 0 ? 5e5 : 1.5);
    double best = 1e300;
    for (const auto& f : mesh.triangles) {
      best = std::min(best, (ClosestPointOnTriangle(p, mesh.vertices[f[0]], mesh.vertices[f[1]],
                                                    mesh.vertices[f[2]]) -
                             p)
                                .norm());
    }
    const ClosestPoint c = index.Query(p);
    EXPECT_NEAR(c.distance, best, 1e-9 * std::max(1.0, best)) << "trial " << trial;
  }
}

TEST(ClosestPointTest, FaceNormalsPointOutOfAClosedShape) {
  const TriangleMesh sphere = MakeIcoSphere(1.0, 3);
  const TriangleClosestPoint index(sphere);
  const ClosestPoint c = index.Query(Eigen::Vector3d(0.3, 0.2, 1.5));
  EXPECT_GT(index.FaceNormal(c.triangle).dot(c.point), 0.9);
  // Wound the other way but with outward vertex normals: the normals still point out.
  TriangleMesh flipped = sphere;
  for (auto& f : flipped.triangles) std::swap(f[1], f[2]);
  flipped.vertex_normals = sphere.vertex_normals;
  ASSERT_EQ(flipped.vertex_normals.size(), flipped.vertices.size());
  const TriangleClosestPoint flipped_index(flipped);
  const ClosestPoint f = flipped_index.Query(Eigen::Vector3d(0.3, 0.2, 1.5));
  EXPECT_GT(flipped_index.FaceNormal(f.triangle).dot(f.point), 0.9);
}

TEST(ClosestPointTest, MeshWithoutTrianglesIsEmpty) {
  TriangleMesh cloud;
  cloud.vertices = {{0, 0, 0}, {1, 0, 0}};
  const TriangleClosestPoint index(cloud);
  EXPECT_TRUE(index.empty());
  EXPECT_EQ(index.Query(Eigen::Vector3d::Zero()).triangle, -1);
}

}  // namespace
}  // namespace mgsr
