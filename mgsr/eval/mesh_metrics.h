// Mesh quality against ground truth (docs/design.md, method.md 6.2), measured exactly:
// area-uniform samples on each surface, and for each sample the exact closest point on the *other*
// surface's triangles (TriangleClosestPoint), so a mesh against itself scores ~0 and errors far
// below the sample spacing still show.
//   accuracy      = mean distance from predicted samples to the ground-truth triangles
//   completeness  = mean distance from ground-truth samples to the predicted triangles
//   CD            = (accuracy + completeness) / 2
//   NC            = (mean |n_p . n_closest(p)| + mean |n_g . n_closest(g)|) / 2 (orientation-free)
//   signed offset = distance of a predicted sample to the ground truth, negative when it lies
//                   inside (behind the ground truth's outward face normal at the closest point):
//                   a systematic shrink or swell shows as a median away from 0
//   F-score       = harmonic mean of precision and recall at a distance threshold
// A ground truth without triangles (a point cloud such as gt_points_visible.ply) is matched point
// to point (nearest sample), as before; its vertex normals, when present, give the sign.
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
  double fscore_threshold = 0.01;  // scene units: the headline F-score (precision, recall)
  // Further F-scores: thresholds in scene units, and in pixel footprints when `pixel_footprint`
  // (scene units covered by one training pixel at the object) is known.
  std::vector<double> fscore_thresholds = {0.005, 0.01, 0.02};
  double pixel_footprint = 0;
  std::vector<double> fscore_footprints = {0.5, 1, 2};
  // Optional ground-truth samples to measure completeness from instead of samples of the
  // ground-truth mesh (e.g. only its visible part, suzanne's gt_points_visible.ply). Not owned.
  const TriangleMesh* completeness_points = nullptr;
};

struct FScore {
  double threshold = 0;   // scene units
  double footprints = 0;  // the same in pixel footprints (0: given in scene units)
  double precision = 0, recall = 0, fscore = 0;
};

struct MeshMetrics {
  bool ok = false;
  std::string failure;  // why !ok (empty or degenerate mesh)
  double accuracy = std::numeric_limits<double>::infinity();
  double completeness = std::numeric_limits<double>::infinity();
  double chamfer = std::numeric_limits<double>::infinity();
  double normal_consistency = 0;                 // NaN-free; 0 when normals are unknown on a side
  double precision = 0, recall = 0, fscore = 0;  // at options.fscore_threshold
  // Signed distance of the predicted surface to the ground truth along its outward normal
  // (negative: inside), over the predicted samples; 0 with fraction_inside 0 when the ground truth
  // has no normals to tell inside from outside.
  double signed_offset_median = 0, signed_offset_mean = 0, fraction_inside = 0;
  // The same seen from the ground truth: the offset of the closest predicted point from each
  // ground-truth sample (floaters away from the surface do not enter it).
  double signed_offset_median_gt = 0;
  double pixel_footprint = 0;  // as given in the options
  std::vector<FScore> fscores;
  // The F-score at `footprints` pixel footprints (0 when it was not measured).
  double FScoreAtFootprints(double footprints) const {
    for (const FScore& f : fscores)
      if (f.footprints == footprints) return f.fscore;
    return 0.0;
  }
};

MeshMetrics EvaluateMesh(const TriangleMesh& predicted, const TriangleMesh& ground_truth,
                         const MeshMetricsOptions& options);

}  // namespace mgsr
