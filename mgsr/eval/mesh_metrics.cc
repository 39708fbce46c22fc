#include "mgsr/eval/mesh_metrics.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <memory>
#include <nanoflann.hpp>
#include <numeric>

#include "mgsr/core/rng.h"

namespace mgsr {
namespace {

struct PointCloudAdaptor {
  const std::vector<Eigen::Vector3d>& pts;
  size_t kdtree_get_point_count() const { return pts.size(); }
  double kdtree_get_pt(size_t i, size_t dim) const { return pts[i][dim]; }
  template <class BBox>
  bool kdtree_get_bbox(BBox&) const {
    return false;
  }
};

using KdTree =
    nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, PointCloudAdaptor>,
                                        PointCloudAdaptor, 3, size_t>;

struct OneWay {
  double mean_distance = 0;
  double normal_dot = 0;  // mean |n . n_nn|
  double within = 0;      // share of points closer than the threshold
};

// From every `from` sample to its nearest `to` sample.
OneWay Directed(const SurfaceSamples& from, const SurfaceSamples& to, double threshold) {
  PointCloudAdaptor adaptor{to.points};
  KdTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tree.buildIndex();
  const bool normals = !from.normals.empty() && !to.normals.empty();
  const int n = static_cast<int>(from.points.size());
  double dist_sum = 0, dot_sum = 0, within = 0;
#pragma omp parallel for reduction(+ : dist_sum, dot_sum, within) schedule(static)
  for (int i = 0; i < n; ++i) {
    size_t index = 0;
    double d2 = 0;
    tree.knnSearch(from.points[i].data(), 1, &index, &d2);
    const double d = std::sqrt(d2);
    dist_sum += d;
    within += d < threshold ? 1.0 : 0.0;
    if (normals) dot_sum += std::abs(from.normals[i].dot(to.normals[index]));
  }
  OneWay r;
  r.mean_distance = dist_sum / n;
  r.normal_dot = normals ? dot_sum / n : 0.0;
  r.within = within / n;
  return r;
}

}  // namespace

SurfaceSamples SampleSurface(const TriangleMesh& mesh, int count, uint64_t seed) {
  SurfaceSamples s;
  Rng rng(seed);
  if (mesh.triangles.empty()) {
    std::vector<size_t> order(mesh.vertices.size());
    std::iota(order.begin(), order.end(), 0);
    // Partial Fisher-Yates: a seeded subset of the vertices.
    const size_t take = std::min(order.size(), static_cast<size_t>(std::max(count, 0)));
    for (size_t i = 0; i < take; ++i)
      std::swap(order[i], order[i + rng.UniformInt(order.size() - i)]);
    const bool normals = mesh.vertex_normals.size() == mesh.vertices.size();
    for (size_t i = 0; i < take; ++i) {
      s.points.push_back(mesh.vertices[order[i]]);
      if (normals) s.normals.push_back(mesh.vertex_normals[order[i]].normalized());
    }
    return s;
  }
  std::vector<double> cumulative(mesh.triangles.size());
  double total = 0;
  for (size_t i = 0; i < mesh.triangles.size(); ++i) {
    const auto& f = mesh.triangles[i];
    const double area = 0.5 * (mesh.vertices[f[1]] - mesh.vertices[f[0]])
                                  .cross(mesh.vertices[f[2]] - mesh.vertices[f[0]])
                                  .norm();
    total += std::isfinite(area) ? area : 0.0;
    cumulative[i] = total;
  }
  if (!(total > 0)) return s;
  s.points.reserve(count);
  s.normals.reserve(count);
  for (int k = 0; k < count; ++k) {
    const double target = rng.Uniform() * total;
    size_t i = std::upper_bound(cumulative.begin(), cumulative.end(), target) - cumulative.begin();
    i = std::min(i, cumulative.size() - 1);
    const auto& f = mesh.triangles[i];
    const Eigen::Vector3d &a = mesh.vertices[f[0]], &b = mesh.vertices[f[1]],
                          &c = mesh.vertices[f[2]];
    double u = rng.Uniform(), v = rng.Uniform();
    if (u + v > 1) {
      u = 1 - u;
      v = 1 - v;
    }
    s.points.push_back(a + u * (b - a) + v * (c - a));
    s.normals.push_back((b - a).cross(c - a).normalized());
  }
  return s;
}

MeshMetrics EvaluateMesh(const TriangleMesh& predicted, const TriangleMesh& ground_truth,
                         const MeshMetricsOptions& options) {
  MeshMetrics m;
  const SurfaceSamples pred = SampleSurface(predicted, options.num_samples, options.seed);
  const SurfaceSamples gt = SampleSurface(ground_truth, options.num_samples, options.seed + 1);
  if (pred.points.empty()) {
    m.failure =
        predicted.vertices.empty() ? "predicted mesh is empty" : "predicted mesh has no area";
    return m;
  }
  if (gt.points.empty()) {
    m.failure = "ground-truth mesh is empty or has no area";
    return m;
  }
  const OneWay to_gt = Directed(pred, gt, options.fscore_threshold);
  const OneWay to_pred = Directed(gt, pred, options.fscore_threshold);
  m.ok = true;
  m.accuracy = to_gt.mean_distance;
  m.completeness = to_pred.mean_distance;
  m.chamfer = 0.5 * (m.accuracy + m.completeness);
  m.normal_consistency = 0.5 * (to_gt.normal_dot + to_pred.normal_dot);
  m.precision = to_gt.within;
  m.recall = to_pred.within;
  m.fscore =
      m.precision + m.recall > 0 ? 2 * m.precision * m.recall / (m.precision + m.recall) : 0.0;
  return m;
}

}  // namespace mgsr
