// RayCaster: exact ray-triangle queries on a TriangleMesh through a bounding volume hierarchy.
// Used to render synthetic scenes and to test visibility; double precision throughout because its
// depths are ground truth.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "mgsr/core/triangle_mesh.h"

namespace mgsr {

struct RayHit {
  double t = 0;         // distance along the (unit or not) direction
  int triangle = -1;    // -1: no hit
  double u = 0, v = 0;  // barycentrics of vertices 1 and 2
};

class RayCaster {
 public:
  explicit RayCaster(const TriangleMesh& mesh);

  // Nearest hit with t in (t_min, t_max).
  bool Intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double t_min,
                 double t_max, RayHit* hit) const;
  // Any hit in (t_min, t_max): for shadow and visibility rays.
  bool Occluded(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double t_min,
                double t_max) const;

  // Geometric (face) normal of a hit, unit length, outward for outward-wound meshes.
  Eigen::Vector3d FaceNormal(int triangle) const;
  // Shading normal interpolated from vertex normals (face normal when the mesh has none).
  Eigen::Vector3d ShadingNormal(const RayHit& hit) const;

 private:
  struct Node {
    Eigen::Vector3d lo, hi;
    int left = -1, right = -1;  // children; -1 for leaves
    int first = 0, count = 0;   // leaf range in order_
  };
  int Build(int first, int count, int depth);
  template <bool kAnyHit>
  bool Traverse(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_min, double t_max,
                RayHit* hit) const;

  const TriangleMesh& mesh_;
  std::vector<Node> nodes_;
  std::vector<int> order_;
  std::vector<Eigen::Vector3d> centroids_;
};

}  // namespace mgsr
