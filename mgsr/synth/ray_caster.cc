#include "mgsr/synth/ray_caster.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <limits>

namespace mgsr {
namespace {

constexpr int kLeafSize = 4;

bool HitBox(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, const Eigen::Vector3d& o,
            const Eigen::Vector3d& inv_d, double t_min, double t_max) {
  for (int k = 0; k < 3; ++k) {
    double t0 = (lo[k] - o[k]) * inv_d[k];
    double t1 = (hi[k] - o[k]) * inv_d[k];
    if (t0 > t1) std::swap(t0, t1);
    t_min = std::max(t_min, t0);
    t_max = std::min(t_max, t1);
    if (t_max < t_min) return false;
  }
  return true;
}

}  // namespace

RayCaster::RayCaster(const TriangleMesh& mesh) : mesh_(mesh) {
  const int n = static_cast<int>(mesh.triangles.size());
  order_.resize(n);
  centroids_.resize(n);
  for (int i = 0; i < n; ++i) {
    order_[i] = i;
    const auto& f = mesh.triangles[i];
    centroids_[i] = (mesh.vertices[f[0]] + mesh.vertices[f[1]] + mesh.vertices[f[2]]) / 3.0;
  }
  nodes_.reserve(2 * n / kLeafSize + 2);
  if (n > 0) Build(0, n, 0);
}

int RayCaster::Build(int first, int count, int depth) {
  Node node;
  node.lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  node.hi = -node.lo;
  for (int i = first; i < first + count; ++i) {
    const auto& f = mesh_.triangles[order_[i]];
    for (int k = 0; k < 3; ++k) {
      node.lo = node.lo.cwiseMin(mesh_.vertices[f[k]]);
      node.hi = node.hi.cwiseMax(mesh_.vertices[f[k]]);
    }
  }
  const int id = static_cast<int>(nodes_.size());
  nodes_.push_back(node);
  if (count <= kLeafSize || depth > 60) {
    nodes_[id].first = first;
    nodes_[id].count = count;
    return id;
  }
  // Median split along the longest axis of the centroid bounds.
  Eigen::Vector3d clo = centroids_[order_[first]], chi = clo;
  for (int i = first; i < first + count; ++i) {
    clo = clo.cwiseMin(centroids_[order_[i]]);
    chi = chi.cwiseMax(centroids_[order_[i]]);
  }
  int axis = 0;
  (chi - clo).maxCoeff(&axis);
  const int half = count / 2;
  std::nth_element(order_.begin() + first, order_.begin() + first + half,
                   order_.begin() + first + count,
                   [&](int a, int b) { return centroids_[a][axis] < centroids_[b][axis]; });
  const int left = Build(first, half, depth + 1);
  const int right = Build(first + half, count - half, depth + 1);
  nodes_[id].left = left;
  nodes_[id].right = right;
  return id;
}

template <bool kAnyHit>
bool RayCaster::Traverse(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_min,
                         double t_max, RayHit* hit) const {
  if (nodes_.empty()) return false;
  const Eigen::Vector3d inv_d(1.0 / d.x(), 1.0 / d.y(), 1.0 / d.z());
  int stack[128];
  int top = 0;
  stack[top++] = 0;
  bool found = false;
  double best = t_max;
  while (top > 0) {
    const Node& node = nodes_[stack[--top]];
    if (!HitBox(node.lo, node.hi, o, inv_d, t_min, best)) continue;
    if (node.left >= 0) {
      stack[top++] = node.left;
      stack[top++] = node.right;
      continue;
    }
    for (int i = node.first; i < node.first + node.count; ++i) {
      // Moller-Trumbore.
      const int tri = order_[i];
      const auto& f = mesh_.triangles[tri];
      const Eigen::Vector3d& a = mesh_.vertices[f[0]];
      const Eigen::Vector3d e1 = mesh_.vertices[f[1]] - a, e2 = mesh_.vertices[f[2]] - a;
      const Eigen::Vector3d p = d.cross(e2);
      const double det = e1.dot(p);
      if (std::abs(det) < 1e-300) continue;
      const double inv = 1.0 / det;
      const Eigen::Vector3d s = o - a;
      const double u = s.dot(p) * inv;
      if (u < 0 || u > 1) continue;
      const Eigen::Vector3d q = s.cross(e1);
      const double v = d.dot(q) * inv;
      if (v < 0 || u + v > 1) continue;
      const double t = e2.dot(q) * inv;
      if (t <= t_min || t >= best) continue;
      if (kAnyHit) return true;
      found = true;
      best = t;
      hit->t = t;
      hit->triangle = tri;
      hit->u = u;
      hit->v = v;
    }
  }
  return found;
}

bool RayCaster::Intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                          double t_min, double t_max, RayHit* hit) const {
  *hit = RayHit();
  return Traverse<false>(origin, direction, t_min, t_max, hit);
}

bool RayCaster::Occluded(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                         double t_min, double t_max) const {
  RayHit unused;
  return Traverse<true>(origin, direction, t_min, t_max, &unused);
}

Eigen::Vector3d RayCaster::FaceNormal(int triangle) const {
  const auto& f = mesh_.triangles[triangle];
  return (mesh_.vertices[f[1]] - mesh_.vertices[f[0]])
      .cross(mesh_.vertices[f[2]] - mesh_.vertices[f[0]])
      .normalized();
}

Eigen::Vector3d RayCaster::ShadingNormal(const RayHit& hit) const {
  if (mesh_.vertex_normals.size() != mesh_.vertices.size()) return FaceNormal(hit.triangle);
  const auto& f = mesh_.triangles[hit.triangle];
  const Eigen::Vector3d n = (1 - hit.u - hit.v) * mesh_.vertex_normals[f[0]] +
                            hit.u * mesh_.vertex_normals[f[1]] + hit.v * mesh_.vertex_normals[f[2]];
  return n.norm() > 0 ? Eigen::Vector3d(n.normalized()) : FaceNormal(hit.triangle);
}

}  // namespace mgsr
