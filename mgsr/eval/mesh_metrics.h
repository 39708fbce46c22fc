// Mesh quality against ground truth (DESIGN.md section 5, reference 6.2): area-uniform samples on
// both surfaces, nearest neighbours both ways through a kd-tree (nanoflann).
//   accuracy     = mean distance from predicted samples to the nearest ground-truth sample
//   completeness = mean distance from ground-truth samples to the nearest predicted sample
//   CD           = (accuracy + completeness) / 2
//   NC           = (mean |n_p . n_nn(p)| + mean |n_g . n_nn(g)|) / 2   (absolute: orientation-free)
//   F-score      = harmonic mean of precision and recall at a distance threshold
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "mgsr/core/triangle_mesh.h"

namespace mgsr {

struct SurfaceSamples {
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector3d> normals;  // unit; empty when unknown (point clouds without normals)
};

// `count` points uniformly by area with their face normals (seeded). A mesh without triangles is
// treated as a point cloud: a seeded subset of its vertices (all of them if fewer), with vertex
// normals when it has them. Degenerate (zero-area) triangles are never sampled.
SurfaceSamples SampleSurface(const TriangleMesh& mesh, int count, uint64_t seed);

struct MeshMetricsOptions {
  int num_samples = 10000;
  uint64_t seed = 0;
  double fscore_threshold = 0.01;  // scene units
};

struct MeshMetrics {
  bool ok = false;
  std::string failure;  // why !ok (empty or degenerate mesh)
  double accuracy = std::numeric_limits<double>::infinity();
  double completeness = std::numeric_limits<double>::infinity();
  double chamfer = std::numeric_limits<double>::infinity();
  double normal_consistency = 0;  // NaN-free; 0 when normals are unknown on a side
  double precision = 0, recall = 0, fscore = 0;
};

MeshMetrics EvaluateMesh(const TriangleMesh& predicted, const TriangleMesh& ground_truth,
                         const MeshMetricsOptions& options);

}  // namespace mgsr
