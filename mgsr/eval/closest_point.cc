#include "mgsr/eval/closest_point.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <nanoflann.hpp>

namespace mgsr {

Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                       const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  // Voronoi regions of the vertices, then the edges, then the face.
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double denom = d1 - d3;
    return denom > 0 ? Eigen::Vector3d(a + (d1 / denom) * ab) : a;
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double denom = d2 - d6;
    return denom > 0 ? Eigen::Vector3d(a + (d2 / denom) * ac) : a;
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double denom = (d4 - d3) + (d5 - d6);
    return denom > 0 ? Eigen::Vector3d(b + ((d4 - d3) / denom) * (c - b)) : b;
  }
  const double sum = va + vb + vc;
  if (!(sum > 0)) return a;  // degenerate (not reached for triangles with area)
  const double v = vb / sum, w = vc / sum;
  return a + ab * v + ac * w;
}

namespace {

struct SampleCloud {
  std::vector<Eigen::Vector3d> points;
  std::vector<int> triangle;
  size_t kdtree_get_point_count() const { return points.size(); }
  double kdtree_get_pt(size_t i, size_t dim) const { return points[i][dim]; }
  template <class BBox>
  bool kdtree_get_bbox(BBox&) const {
    return false;
  }
};

using SampleTree =
    nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, SampleCloud>,
                                        SampleCloud, 3, size_t>;

// Branch and bound over the kd-tree: every sample in the (shrinking) ball names a triangle whose
// exact closest point is computed once. A triangle at distance d has a sample within d + R (R: the
// covering radius of the samples), so the ball of radius best + R never misses the closest one.
class ClosestTriangleSet {
 public:
  ClosestTriangleSet(const TriangleMesh& mesh, const SampleCloud& cloud, const Eigen::Vector3d& p,
                     double covering_radius, ClosestPoint* best)
      : mesh_(mesh), cloud_(cloud), p_(p), cover_(covering_radius), best_(best) {
    UpdateRadius();
  }
  size_t size() const { return 0; }
  bool full() const { return true; }
  double worstDist() const { return radius2_; }
  bool addPoint(double dist2, size_t index) {
    if (dist2 >= radius2_) return true;
    const int t = cloud_.triangle[index];
    if (std::find(visited_.begin(), visited_.end(), t) != visited_.end()) return true;
    visited_.push_back(t);
    const auto& f = mesh_.triangles[t];
    const Eigen::Vector3d q = ClosestPointOnTriangle(p_, mesh_.vertices[f[0]], mesh_.vertices[f[1]],
                                                     mesh_.vertices[f[2]]);
    const double d = (q - p_).norm();
    if (d < best_->distance) {
      best_->distance = d;
      best_->point = q;
      best_->triangle = t;
      UpdateRadius();
    }
    return true;
  }

 private:
  void UpdateRadius() {
    // A little slack for rounding in the tree's squared distances.
    const double r = (best_->distance + cover_) * (1 + 1e-9) + 1e-12;
    radius2_ = r * r;
  }
  const TriangleMesh& mesh_;
  const SampleCloud& cloud_;
  Eigen::Vector3d p_;
  double cover_;
  ClosestPoint* best_;
  double radius2_ = 0;
  std::vector<int> visited_;
};

}  // namespace

// A triangle whose longest edge exceeds this many median longest edges is tested directly.
constexpr double kOversized = 64;

struct TriangleClosestPoint::Index {
  SampleCloud cloud;
  std::unique_ptr<SampleTree> tree;
  double covering_radius = 0;
  // Triangles far larger than the mesh's typical one (a stray vertex far away makes a few): not
  // sampled, but tested one by one in every query. Sampled, their covering radius would widen
  // every query's search ball to the whole mesh (a query then visits every sample).
  std::vector<int> oversized;
};

TriangleClosestPoint::TriangleClosestPoint(const TriangleMesh& mesh)
    : mesh_(mesh), index_(std::make_unique<Index>()) {
  const size_t n = mesh.triangles.size();
  face_normals_.assign(n, Eigen::Vector3d::Zero());
  const bool vertex_normals = mesh.vertex_normals.size() == mesh.vertices.size();
  // Target spacing: the median longest edge, so a typical triangle gets one to four samples.
  std::vector<double> longest(n, 0.0);
  for (size_t i = 0; i < n; ++i) {
    const auto& f = mesh.triangles[i];
    const Eigen::Vector3d &a = mesh.vertices[f[0]], &b = mesh.vertices[f[1]],
                          &c = mesh.vertices[f[2]];
    const Eigen::Vector3d cross = (b - a).cross(c - a);
    if (!(cross.norm() > 0) || !cross.allFinite()) continue;
    Eigen::Vector3d normal = cross.normalized();
    if (vertex_normals) {
      const Eigen::Vector3d sum =
          mesh.vertex_normals[f[0]] + mesh.vertex_normals[f[1]] + mesh.vertex_normals[f[2]];
      if (sum.dot(normal) < 0) normal = -normal;
    }
    face_normals_[i] = normal;
    longest[i] = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
  }
  std::vector<double> sorted;
  for (double l : longest)
    if (l > 0) sorted.push_back(l);
  if (sorted.empty()) return;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double spacing = sorted[sorted.size() / 2];
  SampleCloud& cloud = index_->cloud;
  for (size_t i = 0; i < n; ++i) {
    if (!(longest[i] > 0)) continue;
    const auto& f = mesh.triangles[i];
    const Eigen::Vector3d &a = mesh.vertices[f[0]], &b = mesh.vertices[f[1]],
                          &c = mesh.vertices[f[2]];
    if (longest[i] > kOversized * spacing) {
      index_->oversized.push_back(static_cast<int>(i));
      continue;
    }
    // n x n similar sub-triangles, one sample at each centroid: every point of the triangle is
    // within (the largest centroid-to-vertex distance) / k of a sample.
    const int k = static_cast<int>(std::clamp(std::ceil(longest[i] / spacing), 1.0, kOversized));
    const Eigen::Vector3d centroid = (a + b + c) / 3.0;
    const double reach =
        std::max({(a - centroid).norm(), (b - centroid).norm(), (c - centroid).norm()}) / k;
    index_->covering_radius = std::max(index_->covering_radius, reach);
    const Eigen::Vector3d u = (b - a) / k, v = (c - a) / k;
    for (int x = 0; x < k; ++x) {
      for (int y = 0; x + y < k; ++y) {
        cloud.points.push_back(a + (x + 1.0 / 3) * u + (y + 1.0 / 3) * v);
        cloud.triangle.push_back(static_cast<int>(i));
        if (x + y + 1 < k) {
          cloud.points.push_back(a + (x + 2.0 / 3) * u + (y + 2.0 / 3) * v);
          cloud.triangle.push_back(static_cast<int>(i));
        }
      }
    }
  }
  index_->tree =
      std::make_unique<SampleTree>(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  index_->tree->buildIndex();
}

TriangleClosestPoint::~TriangleClosestPoint() = default;

double TriangleClosestPoint::search_slack() const { return index_->covering_radius; }

bool TriangleClosestPoint::empty() const {
  return index_->cloud.points.empty() && index_->oversized.empty();
}

ClosestPoint TriangleClosestPoint::Query(const Eigen::Vector3d& p) const {
  ClosestPoint best;
  if (empty()) return best;
  best.distance = std::numeric_limits<double>::infinity();
  for (int t : index_->oversized) {
    const auto& f = mesh_.triangles[t];
    const Eigen::Vector3d q =
        ClosestPointOnTriangle(p, mesh_.vertices[f[0]], mesh_.vertices[f[1]], mesh_.vertices[f[2]]);
    const double d = (q - p).norm();
    if (d < best.distance) best = {q, d, t};
  }
  if (index_->cloud.points.empty()) return best;
  // Seed the bound with the nearest sample's triangle, then search the ball around it.
  size_t nearest = 0;
  double d2 = 0;
  index_->tree->knnSearch(p.data(), 1, &nearest, &d2);
  const int t = index_->cloud.triangle[nearest];
  const auto& f = mesh_.triangles[t];
  const Eigen::Vector3d q =
      ClosestPointOnTriangle(p, mesh_.vertices[f[0]], mesh_.vertices[f[1]], mesh_.vertices[f[2]]);
  if ((q - p).norm() < best.distance) best = {q, (q - p).norm(), t};
  ClosestTriangleSet set(mesh_, index_->cloud, p, index_->covering_radius, &best);
  index_->tree->findNeighbors(set, p.data(), nanoflann::SearchParams());
  return best;
}

}  // namespace mgsr
