#include "mgsr/eval/mesh_metrics.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <memory>
#include <nanoflann.hpp>
#include <numeric>

#include "mgsr/core/rng.h"
#include "mgsr/eval/closest_point.h"

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

// For every `from` sample: the distance to the target surface, |n . n_target|, and the vector
// from the sample to its closest target point with the target's normal there (for the sign).
struct Matches {
  std::vector<double> distance, dot;
  std::vector<Eigen::Vector3d> offset;         // closest target point - sample
  std::vector<Eigen::Vector3d> target_normal;  // zero when unknown
  bool normals = false;                        // |n . n_target| is meaningful
};

// The target is a mesh's triangles (exact closest point) or, when it has none, its points.
Matches Match(const SurfaceSamples& from, const TriangleMesh& target) {
  const int n = static_cast<int>(from.points.size());
  Matches m;
  m.distance.resize(n);
  m.dot.assign(n, 0.0);
  m.offset.resize(n);
  m.target_normal.assign(n, Eigen::Vector3d::Zero());
  if (!target.triangles.empty()) {
    const TriangleClosestPoint index(target);
    m.normals = !from.normals.empty();
#pragma omp parallel for schedule(dynamic, 64)
    for (int i = 0; i < n; ++i) {
      const ClosestPoint c = index.Query(from.points[i]);
      m.distance[i] = c.distance;
      m.offset[i] = c.point - from.points[i];
      m.target_normal[i] = index.FaceNormal(c.triangle);
      if (m.normals) m.dot[i] = std::abs(from.normals[i].dot(m.target_normal[i]));
    }
    return m;
  }
  const std::vector<Eigen::Vector3d>& pts = target.vertices;
  const bool target_normals = target.vertex_normals.size() == pts.size();
  PointCloudAdaptor adaptor{pts};
  KdTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tree.buildIndex();
  m.normals = !from.normals.empty() && target_normals;
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    size_t index = 0;
    double d2 = 0;
    tree.knnSearch(from.points[i].data(), 1, &index, &d2);
    m.distance[i] = std::sqrt(d2);
    m.offset[i] = pts[index] - from.points[i];
    if (target_normals) m.target_normal[i] = target.vertex_normals[index].normalized();
    if (m.normals) m.dot[i] = std::abs(from.normals[i].dot(m.target_normal[i]));
  }
  return m;
}

double Mean(const std::vector<double>& v) {
  double sum = 0;
  for (double x : v) sum += x;
  return v.empty() ? 0.0 : sum / v.size();
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  const size_t half = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + half, v.end());
  if (v.size() % 2 == 1) return v[half];
  return 0.5 * (v[half] + *std::max_element(v.begin(), v.begin() + half));
}

double ShareBelow(const std::vector<double>& v, double threshold) {
  size_t count = 0;
  for (double x : v) count += x < threshold;
  return v.empty() ? 0.0 : static_cast<double>(count) / v.size();
}

FScore ScoreAt(const Matches& to_gt, const Matches& to_pred, double threshold, double footprints) {
  FScore f;
  f.threshold = threshold;
  f.footprints = footprints;
  f.precision = ShareBelow(to_gt.distance, threshold);
  f.recall = ShareBelow(to_pred.distance, threshold);
  f.fscore =
      f.precision + f.recall > 0 ? 2 * f.precision * f.recall / (f.precision + f.recall) : 0.0;
  return f;
}

// |d| signed by the side of the ground truth's surface the predicted point is on. `outward` is
// the vector from the ground-truth point to the predicted point.
double Signed(double distance, const Eigen::Vector3d& outward, const Eigen::Vector3d& normal) {
  return outward.dot(normal) < 0 ? -distance : distance;
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
  m.pixel_footprint = options.pixel_footprint;
  const SurfaceSamples pred = SampleSurface(predicted, options.num_samples, options.seed);
  const TriangleMesh& gt_source =
      options.completeness_points != nullptr ? *options.completeness_points : ground_truth;
  const SurfaceSamples gt = SampleSurface(gt_source, options.num_samples, options.seed + 1);
  if (pred.points.empty()) {
    m.failure =
        predicted.vertices.empty() ? "predicted mesh is empty" : "predicted mesh has no area";
    return m;
  }
  if (gt.points.empty() || SampleSurface(ground_truth, 1, options.seed).points.empty()) {
    m.failure = "ground-truth mesh is empty or has no area";
    return m;
  }
  const Matches to_gt = Match(pred, ground_truth);
  const Matches to_pred = Match(gt, predicted);
  m.ok = true;
  m.accuracy = Mean(to_gt.distance);
  m.completeness = Mean(to_pred.distance);
  m.chamfer = 0.5 * (m.accuracy + m.completeness);
  m.normal_consistency =
      0.5 * ((to_gt.normals ? Mean(to_gt.dot) : 0.0) + (to_pred.normals ? Mean(to_pred.dot) : 0.0));
  const FScore headline = ScoreAt(to_gt, to_pred, options.fscore_threshold, 0);
  m.precision = headline.precision;
  m.recall = headline.recall;
  m.fscore = headline.fscore;
  for (double t : options.fscore_thresholds) m.fscores.push_back(ScoreAt(to_gt, to_pred, t, 0));
  if (options.pixel_footprint > 0) {
    for (double k : options.fscore_footprints)
      m.fscores.push_back(ScoreAt(to_gt, to_pred, k * options.pixel_footprint, k));
  }
  // Signed offsets: from the predicted samples (the ground truth's normal at the closest point)
  // and from the ground-truth samples (their own normal).
  std::vector<double> signed_pred, signed_gt;
  for (size_t i = 0; i < pred.points.size(); ++i) {
    if (to_gt.target_normal[i].squaredNorm() == 0) continue;
    signed_pred.push_back(Signed(to_gt.distance[i], -to_gt.offset[i], to_gt.target_normal[i]));
  }
  if (!gt.normals.empty()) {
    for (size_t i = 0; i < gt.points.size(); ++i)
      signed_gt.push_back(Signed(to_pred.distance[i], to_pred.offset[i], gt.normals[i]));
  }
  m.signed_offset_median = Median(signed_pred);
  m.signed_offset_mean = Mean(signed_pred);
  m.fraction_inside = ShareBelow(signed_pred, 0.0);
  m.signed_offset_median_gt = Median(signed_gt);
  return m;
}

}  // namespace mgsr
